#include "scenarios/runner/common/closed_loop/outputs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "render/residual_figures.h"
#include "scenarios/runner/common/closed_loop/truth.h"
#include "scenarios/runner/output.h"
#include "sim/dynamic_effects.h"
#include "sim/export_model.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;
using identify::DataSet;

// A metric that does not apply here (no cross-validation, no position rows) is null: NaN in a
// summary is an error the runner reports.
Json FiniteOrNull(double v) { return std::isfinite(v) ? Json(v) : Json(); }

struct Stats {
  double mean = 0, std = 0, max = 0;
};
Stats Summarise(const std::vector<double>& e) {
  Stats s;
  if (e.empty()) return s;
  for (double v : e) s.mean += v, s.max = std::max(s.max, v);
  s.mean /= e.size();
  for (double v : e) s.std += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(s.std / e.size());
  return s;
}

std::string JoinNames(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

void WriteRowErrorStats(const std::string& prefix, const std::string& unit,
                        const std::vector<double>& errors, Json* m) {
  if (errors.empty()) return;
  const Stats s = Summarise(errors);
  (*m)[prefix + "_mean" + unit] = s.mean;
  (*m)[prefix + "_std" + unit] = s.std;
  (*m)[prefix + "_max" + unit] = s.max;
}

void WriteErrorMetrics(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m) {
  const DataSet& cal = rep.cal;
  const DataSet& val = rep.val;
  if (cl.camera.present) {
    (*m)["val_err_before_px"] =
        identify::MeanRowError(val, rep.val_before, identify::RowUnit::kPixels);
    (*m)["val_err_after_px"] =
        identify::MeanRowError(val, rep.val_after, identify::RowUnit::kPixels);
    (*m)["cal_err_before_px"] =
        identify::MeanRowError(cal, rep.cal_before, identify::RowUnit::kPixels);
    (*m)["cal_err_after_px"] =
        identify::MeanRowError(cal, rep.cal_after, identify::RowUnit::kPixels);
  }
  if (identify::HasUnit(cal, identify::RowUnit::kRadians) ||
      identify::HasUnit(val, identify::RowUnit::kRadians)) {
    const auto deg = [](const DataSet& d, const std::vector<double>& e) {
      return identify::MeanRowError(d, e, identify::RowUnit::kRadians) / kDeg;
    };
    (*m)["val_err_before_gravity_deg"] = deg(val, rep.val_before);
    (*m)["val_err_after_gravity_deg"] = deg(val, rep.val_after);
    (*m)["cal_err_before_gravity_deg"] = deg(cal, rep.cal_before);
    (*m)["cal_err_after_gravity_deg"] = deg(cal, rep.cal_after);
  }
  (*m)["val_err_before_m"] = identify::ConsistencyError(val, rep.val_before);
  (*m)["val_err_after_m"] = identify::ConsistencyError(val, rep.val_after);
  if (const auto e = TruthRowErrors(cl, val)) {
    (*m)["val_err_truth_m"] = identify::ConsistencyError(val, *e);
  }
  (*m)["cal_err_before_m"] = identify::ConsistencyError(cal, rep.cal_before);
  (*m)["cal_err_after_m"] = identify::ConsistencyError(cal, rep.cal_after);
  for (const auto& [name, e] :
       {std::pair{"cal_before", &rep.cal_before}, std::pair{"cal_after", &rep.cal_after},
        std::pair{"val_before", &rep.val_before}, std::pair{"val_after", &rep.val_after}}) {
    const DataSet& d = std::string(name).rfind("cal", 0) == 0 ? cal : val;
    std::vector<double> metres, pixels, degrees;
    for (size_t r = 0; r < d.rows.size(); ++r) {
      switch (identify::UnitOf(d.rows[r].type)) {
        case identify::RowUnit::kMetres:
          metres.push_back((*e)[r]);
          break;
        case identify::RowUnit::kPixels:
          pixels.push_back((*e)[r]);
          break;
        case identify::RowUnit::kRadians:
          degrees.push_back((*e)[r] / kDeg);
          break;
      }
    }
    WriteRowErrorStats(std::string(name) + "_row_err", "_m", metres, m);
    WriteRowErrorStats(std::string(name) + "_row_err", "_px", pixels, m);
    WriteRowErrorStats(std::string(name) + "_row_err", "_gravity_deg", degrees, m);
  }
  (*m)["calibration_rows"] = cal.rows.size();
  (*m)["validation_rows"] = val.rows.size();
}

// Each marker's fitted offset on its link (m, in its frame's coordinates) and its std.
Json OffsetsJson(const ClosedLoopSetup& cl, const identify::IdentifyResult& res) {
  Json out = Json::array();
  for (size_t k = 0; k < cl.points.size(); ++k) {
    if (!cl.offset_unknown[k]) continue;
    const Vec3& d = res.after.marker_offsets[k];
    const Mat3& C = res.marker_offset_cov[k];
    out.push_back({{"marker", cl.points[k]},
                   {"offset_m", {d.x(), d.y(), d.z()}},
                   {"std_m", {std::sqrt(C(0, 0)), std::sqrt(C(1, 1)), std::sqrt(C(2, 2))}}});
  }
  return out;
}

// Each frame's fitted pose, its reference and prior, and the covariance of xi
// (T_base_frame = T_ref Exp(xi), [rho; theta] in m and rad).
Json FramesJson(const ClosedLoopSetup& cl, const identify::IdentifyResult& res) {
  Json out = Json::array();
  for (size_t f = 0; f < cl.frames.size(); ++f) {
    const lie::SE3& T = res.after.T_base_frames[f];
    const Eigen::Quaterniond q(T.rotation());
    const Mat6& C = res.frame_cov[f];
    std::vector<std::vector<double>> cov(6, std::vector<double>(6));
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) cov[i][j] = C(i, j);
    }
    out.push_back(
        {{"name", cl.frames[f].name},
         {"T_base_frame",
          {T.translation().x(), T.translation().y(), T.translation().z(), q.w(), q.x(), q.y(),
           q.z()}},
         {"std_m", {std::sqrt(C(0, 0)), std::sqrt(C(1, 1)), std::sqrt(C(2, 2))}},
         {"std_deg",
          {std::sqrt(C(3, 3)) / kDeg, std::sqrt(C(4, 4)) / kDeg, std::sqrt(C(5, 5)) / kDeg}},
         {"xi_covariance", cov},
         {"prior", cl.frames[f].has_prior}});
  }
  return out;
}

Json FindingJson(const identify::ResidualFinding& f) {
  return {{"significant", f.significant},
          {"kind", f.kind},
          {"variable", f.variable},
          {"cycles", f.cycles},
          {"size", f.size},
          {"unit", f.unit},
          {"noise", f.noise},
          {"below_noise", f.below_noise},
          {"p_value", f.p_value},
          {"message", f.message}};
}

Json EquivalenceJson(const ClosedLoopSetup& cl, const identify::IdentifyResult& res) {
  Json sets = Json::array();
  for (const identify::EquivalenceSet& s : res.equivalence) {
    Json members = Json::array();
    for (const identify::EquivalentMember& mb : s.members) {
      members.push_back({{"effect", mb.name},
                         {"observable_value", mb.value},
                         {"unit", cl.em->candidates()[mb.candidate].unit},
                         {"unobservable_directions", mb.unobservable}});
    }
    sets.push_back({{"name", s.name}, {"members", members}});
  }
  return sets;
}

// The projected residual of the finding's joint against its variable, with the fitted curve.
void PlotFinding(RunContext& ctx, const identify::ResidualFinding& f) {
  if (f.x.empty()) return;  // (a per-set finding has no curve to draw)
  const bool angle = f.kind == "periodic";
  const double xs = angle ? 1.0 / kDeg : 1.0;
  const double zs = f.kind == "drift" ? 1e3 : 1.0 / kDeg;
  std::vector<double> x(f.x.size()), z(f.z.size());
  for (size_t i = 0; i < x.size(); ++i) x[i] = f.x[i] * xs, z[i] = f.z[i] * zs;
  std::vector<double> cx, cz;
  const auto [lo, hi] = std::minmax_element(f.x.begin(), f.x.end());
  for (int i = 0; i <= 200; ++i) {
    const double v = *lo + (*hi - *lo) * i / 200.0;
    double y = f.coefficients.empty() ? 0.0 : f.coefficients[0];
    if (angle) {
      for (int c = 1; c <= 3 && 2 * c < static_cast<int>(f.coefficients.size()); ++c) {
        y += f.coefficients[2 * c - 1] * std::cos(c * v) + f.coefficients[2 * c] * std::sin(c * v);
      }
    } else if (f.kind == "load" && f.coefficients.size() == 3) {
      const double scale = std::max(std::abs(*lo), std::abs(*hi));
      y += f.coefficients[1] * v + f.coefficients[2] * std::pow(v / scale, 3) * scale;
    } else if (f.coefficients.size() == 2) {
      y += f.coefficients[1] * v;
    }
    cx.push_back(v * xs);
    cz.push_back(y * zs);
  }
  char title[160];
  std::snprintf(title, sizeof(title), "Residual left: %s in %s, p = %.2g%s", f.kind.c_str(),
                f.variable.c_str(), f.p_value,
                f.significant   ? ""
                : f.below_noise ? " (below the stated noise)"
                                : " (not significant)");
  const std::string x_label = angle              ? f.variable + " [deg]"
                              : f.kind == "load" ? "gravity torque at " + f.variable + " [N m]"
                                                 : "row order (0 first, 1 last)";
  const std::string y_label = f.kind == "drift"
                                  ? "residual [mm]"
                                  : "residual as an angle error of " + f.variable + " [deg]";
  render::SaveRowsAndCurve(ctx.out->File("residual_structure.png").string(),
                           {title, x_label, y_label}, x, z, cx, cz);
}

// The source directions by their sorting, and the scale on the constrained ones.
Json SourceScalingJson(const identify::Report& rep) {
  Json constrained = Json::array(), kept = Json::array();
  for (size_t i = 0; i < rep.directions.size(); ++i) {
    (rep.constrained[i] ? constrained : kept).push_back(rep.directions[i].name);
  }
  return {{"constrained", constrained}, {"kept_declared", kept}, {"scale", rep.source_scale}};
}

void WriteAugmented(const ClosedLoopSetup& cl, RunContext& ctx, const identify::Job& job,
                    const identify::Report& rep) {
  sim::DeclaredModel out = identify::AugmentedModel(job, rep);
  out.fitted_under = identify::FittedUnder(job, rep, out);
  const std::string kept = out.fitted_under.kept_declared_sources.empty()
                               ? "none"
                               : JoinNames(out.fitted_under.kept_declared_sources);
  std::ostringstream header;
  header << "Declared model augmented by flexbench closed_loop: the identified effects with "
            "their\nfitted parameters, and the PPOE source directions the validation rows "
            "constrain\nscaled by "
         << ShortNum(rep.source_scale) << " (what the remaining validation residual supports; mean "
         << "NEES there " << ShortNum(rep.nees_after_scaled)
         << ",\n3 is consistent). Kept as declared (the "
         << "rows do not see them): " << kept << ".\nVerdict: " << rep.verdict
         << (rep.verdict == "ambiguous" ? " (the correction holds; other effect sets explain the "
                                          "data about as well, so no cause is singled out)"
                                        : "")
         << ".\nfitted_under: the joint ranges, gravity torques and end-effector box of those "
            "rows; a run "
            "outside them is warned of.";
  // Relative to the result folder, so the file loads from where it is written.
  out.model_path = fs::absolute(cl.declared.model_path)
                       .lexically_normal()
                       .lexically_relative(fs::absolute(ctx.out->final_dir()).lexically_normal())
                       .generic_string();
  WriteFileAtomic(ctx.out->File("declared_augmented.yaml"),
                  sim::EmitDeclaredModel(out, header.str()));
}

// The augmented model as files MuJoCo and URDF tools load (what `flexbench export` writes),
// beside declared_augmented.yaml; summary.json's identification.calibrated_model names them
// and what the formats cannot hold. A model export cannot read (a URDF) is said so instead.
void WriteCalibratedModel(RunContext& ctx, const identify::Job& job, const identify::Report& rep) {
  Json& cm = (*ctx.summary)["identification"]["calibrated_model"];
  sim::ExportedModel mjcf, urdf;
  // Only the export may refuse the model; a write that fails (a full disk) fails the run.
  try {
    const sim::DeclaredModel model = identify::AugmentedModel(job, rep);
    mjcf = sim::ExportMjcf(model);
    urdf = sim::ExportUrdf(model);
  } catch (const InputError& e) {
    cm = {{"not_written", e.what()}};
    ctx.log(std::string("calibrated model not exported: ") + e.what());
    return;
  }
  WriteFileAtomic(ctx.out->File("calibrated_model.xml"), mjcf.text);
  WriteFileAtomic(ctx.out->File("calibrated_model.urdf"), urdf.text);
  cm = {{"mjcf", "calibrated_model.xml"},
        {"urdf", "calibrated_model.urdf"},
        {"not_in_mjcf", mjcf.skipped},
        {"not_in_urdf", urdf.skipped}};
  if (!mjcf.skipped.empty()) {
    ctx.log("calibrated_model.xml cannot hold (MJCF has no form for them): " +
            JoinNames(mjcf.skipped));
  }
}

void WriteResiduals(const ClosedLoopSetup& cl, RunContext& ctx, const DataSet& d,
                    const std::vector<double>& before, const std::vector<double>& after,
                    const identify::RowLoads& loads, const std::vector<Vec3>& p,
                    const std::string& name) {
  std::ostringstream c;
  c << "row,set,group,where,err_before_m,err_after_m,reach_m,max_abs_tau_Nm,x_m,y_m,z_m\n";
  kinematics::PpoeData pd(cl.chain->model);
  identify::EffectModel::Workspace ws = cl.em->MakeWorkspace();
  for (size_t r = 0; r < d.rows.size(); ++r) {
    kinematics::ForwardKinematics(cl.chain->model, pd, d.rows[r].q);
    const double reach = pd.T_base_frame[cl.chain->end_effector].translation().norm();
    const identify::ConfigLoads& L = loads.At(r, d.rows[r], ws);
    c << r << "," << d.sets[d.rows[r].set] << ","
      << (d.rows[r].type == identify::ObservationType::kGroup ? d.groups[d.rows[r].group] : "")
      << "," << d.rows[r].where << "," << ShortNum(before[r]) << "," << ShortNum(after[r]) << ","
      << ShortNum(reach) << "," << ShortNum(L.tau.size() ? L.tau.cwiseAbs().maxCoeff() : 0.0) << ","
      << ShortNum(p[r].x()) << "," << ShortNum(p[r].y()) << "," << ShortNum(p[r].z()) << "\n";
  }
  WriteFileAtomic(ctx.out->File(name + "_residuals.csv"), c.str());
}

// Residual before and after against the quantity that exposed the first chosen effect.
void Plot(const ClosedLoopSetup& cl, RunContext& ctx, const identify::IdentifyResult& res,
          const DataSet& d, const std::vector<double>& before, const std::vector<double>& after,
          const identify::RowLoads& loads) {
  std::string xl = "row";
  std::vector<double> x(d.rows.size());
  for (size_t r = 0; r < x.size(); ++r) x[r] = r;
  if (!res.effects.empty()) {
    size_t main = 0;
    for (size_t e = 1; e < res.effects.size(); ++e) {
      if (res.effects[e].share > res.effects[main].share) main = e;
    }
    const identify::Candidate& c = cl.em->candidates()[res.effects[main].candidate];
    // Geometry at a fixed frame (a tool offset) shows against the nearest joint above it.
    int q_index = c.q_index;
    for (kinematics::FrameId f = c.frame; q_index < 0 && f > 0;
         f = cl.chain->model.frame(f).parent) {
      if (c.type == identify::EffectType::kLinkOffset ||
          c.type == identify::EffectType::kLinkLength) {
        q_index = cl.chain->model.frame(f).q_index;
      } else {
        break;
      }
    }
    if (c.q_index >= 0 && (c.type == identify::EffectType::kJointCompliance ||
                           c.type == identify::EffectType::kBacklash)) {
      xl = "gravity torque at " + c.location + " [N m]";
      identify::EffectModel::Workspace ws = cl.em->MakeWorkspace();
      for (size_t r = 0; r < x.size(); ++r) x[r] = loads.At(r, d.rows[r], ws).tau[c.q_index];
    } else if (q_index >= 0) {
      xl = cl.chain->q_joints[q_index] + " [deg] (main effect: " + res.effects[main].name + ")";
      for (size_t r = 0; r < x.size(); ++r) x[r] = d.rows[r].q[q_index] / kDeg;
    } else if (c.type == identify::EffectType::kBaseCompliance) {
      xl = "moment at the mount, |M_xy| [N m]";
      identify::EffectModel::Workspace ws = cl.em->MakeWorkspace();
      for (size_t r = 0; r < x.size(); ++r) {
        x[r] = loads.At(r, d.rows[r], ws).M_mount.head<2>().norm();
      }
    } else {
      xl = "reach [m]";
      kinematics::PpoeData pd(cl.chain->model);
      for (size_t r = 0; r < x.size(); ++r) {
        kinematics::ForwardKinematics(cl.chain->model, pd, d.rows[r].q);
        x[r] = pd.T_base_frame[cl.chain->end_effector].translation().norm();
      }
    }
  }
  // The rows of the data's main unit (MainUnit), in mm, px or deg.
  const identify::RowUnit unit = identify::MainUnit(d);
  const double scale = unit == identify::RowUnit::kMetres    ? 1e3
                       : unit == identify::RowUnit::kRadians ? 1.0 / kDeg
                                                             : 1.0;
  std::vector<double> xs, b_shown, a_shown;
  for (size_t r = 0; r < before.size(); ++r) {
    if (identify::UnitOf(d.rows[r].type) != unit) continue;
    xs.push_back(x[r]);
    b_shown.push_back(scale * before[r]);
    a_shown.push_back(scale * after[r]);
  }
  x = xs;
  const bool sockets = std::any_of(d.rows.begin(), d.rows.end(), [](const auto& o) {
    return o.type == identify::ObservationType::kGroup;
  });
  const std::string y_label = unit == identify::RowUnit::kPixels ? "pixel error of the tags [px]"
                              : unit == identify::RowUnit::kRadians
                                  ? "angle to the measured up [deg]"
                              : sockets ? "distance from the socket's mean [mm]"
                                        : "distance from the measured point [mm]";
  render::SaveBeforeAfter(ctx.out->File("residual_before_after.png").string(),
                          {"Validation residual before and after identification", xl, y_label}, x,
                          b_shown, a_shown);
}

// Conditioning, the fitted scale, what the data leave undetermined, and the verdict.
void WriteDiagnostics(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m) {
  const identify::IdentifyResult& res = rep.result;
  (*m)["condition_number"] = FiniteOrNull(res.condition_number);  // null: singular (near_singular)
  // The fitted distance of each constrained group pair (a check on the scale: the
  // consistency metric alone would reward shrinking the robot).
  std::vector<double> fitted_distances;
  for (const identify::GroupDistance& gd : rep.cal.distances) {
    fitted_distances.push_back(
        (res.after.group_points[gd.a] - res.after.group_points[gd.b]).norm());
  }
  (*m)["cal_group_distances_fitted_m"] = fitted_distances;
  (*m)["unidentifiable"] = res.unidentifiable;
  // Families a location cannot offer (only where there are some: earlier results stay as
  // they were).
  if (!cl.em->skipped().empty()) {
    Json skipped = Json::array();
    for (const identify::EffectModel::Skipped& sk : cl.em->skipped()) {
      skipped.push_back({{"candidate", sk.name}, {"reason", sk.reason}});
    }
    (*m)["skipped_candidates"] = skipped;
  }
  (*m)["indistinguishable"] = res.indistinguishable;
  (*m)["verdict"] = rep.verdict;
  (*m)["stopped_by"] = res.stopped_by;
  (*m)["cal_residual_noise_ratio"] = rep.noise_ratio;
  (*m)["near_singular"] = res.near_singular;
  (*m)["effect_overlap"] = res.overlap;
  (*m)["attribution_unique"] = res.attribution_unique;
  (*m)["cv_err_before"] = FiniteOrNull(res.cv_before);
  (*m)["cv_err_after"] = FiniteOrNull(res.cv_after);
  (*m)["residual_finding"] = FindingJson(res.finding);
}

// NEES of the declared PPOE covariance (plus the point noise) before and after, and the scale
// on the augmented model's sources.
void WriteNees(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m) {
  (*m)["nees_before"] = FiniteOrNull(rep.nees_before);
  (*m)["nees_after"] = FiniteOrNull(rep.nees_after);
  (*m)["nees_bound_low"] = rep.nees_bounds.lower;
  (*m)["nees_bound_high"] = rep.nees_bounds.upper;
  if (cl.reading_std_rad > 0.0) (*m)["nees_bound_high_shared"] = rep.nees_bound_high_shared;
  (*m)["source_covariance_scale"] = rep.source_scale;
  (*m)["source_scale_from"] = cl.reading_std_rad > 0.0 ? "readings' noise and fitted parameters"
                                                       : "point_std_m (floor 1e-6)";
  (*m)["source_scaling"] = SourceScalingJson(rep);
  (*m)["sources_cover_residual"] = rep.sources_cover_residual;
  (*m)["nees_after_scaled"] = FiniteOrNull(rep.nees_after_scaled);
}

}  // namespace

// The declared file's identified effects the identification applies, and those it cannot
// (they move none of the measured points), never silently.
void LogBaseEffects(const ClosedLoopSetup& cl, RunContext& ctx) {
  const size_t n = cl.em->base_effects().size();
  for (const sim::DeclaredMarkerOffset& mo : cl.declared.marker_offsets) {
    ctx.log("declared model: '" + mo.frame + "' moved by its fitted offset (marker_offsets)");
  }
  if (n > 0) {
    ctx.log("declared model: " + std::to_string(n) +
            " identified effect(s) applied; candidates act on top of them");
  }
  for (const std::string& name : cl.unused_frames) {
    ctx.log("declared model: frame '" + name +
            "' (frames:) is not a measurement frame of this run (--frame / frames): unused");
  }
  for (const std::string& name : cl.base_not_applied) {
    ctx.log("declared model: identified effect '" + name + "' " +
            (sim::IsDynamicEffect(name)
                 ? "is dynamic: the estimators and the export carry it, this fit does not"
                 : "moves none of the measured points here: not applied by the identification"));
  }
}

void WriteFitMetrics(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m) {
  (*m)["rejected_rows"] = rep.rejected.size();
  if (cl.reading_std_rad > 0.0 && std::isfinite(rep.rss_over_reading_noise)) {
    (*m)["theta_cov_from"] = "readings' noise (least-squares sandwich)";
    (*m)["cal_rss_over_reading_noise"] = rep.rss_over_reading_noise;
  }
}

void WriteMetrics(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m) {
  WriteErrorMetrics(cl, rep, m);
  WriteDiagnostics(cl, rep, m);
  WriteNees(cl, rep, m);
}

void WriteIdentification(const ClosedLoopSetup& cl, const identify::Report& rep, Json* id) {
  const identify::IdentifyResult& res = rep.result;
  (*id)["rejected_rows"] = rep.rejected;
  (*id)["selection_rule"] = "forward stepwise, BIC = N ln(RSS/N) + k ln N, add while dBIC < -" +
                            ShortNum(cl.opt.bic_threshold);
  (*id)["steps"] = res.steps;
  Json effects = Json::array();
  for (const auto& e : res.effects) {
    const identify::Candidate& c = cl.em->candidates()[e.candidate];
    effects.push_back({{"effect", e.name},
                       {"value", e.value},
                       {"std", e.std},
                       {"unit", c.unit},
                       {"share", e.share}});
  }
  (*id)["effects"] = effects;
  Json corr = Json::array();
  for (int i = 0; i < res.theta_corr.rows(); ++i) {
    std::vector<double> row(res.theta_corr.cols());
    for (int j = 0; j < res.theta_corr.cols(); ++j) row[j] = res.theta_corr(i, j);
    corr.push_back(row);
  }
  (*id)["correlation"] = corr;
  (*id)["rss_before"] = res.before.rss;
  (*id)["rss_after"] = res.after.rss;
  (*id)["cross_validation"] = {{"folds_by", res.folds_by}, {"folds", res.num_folds}};
  (*id)["equivalence_sets"] = EquivalenceJson(cl, res);
  (*id)["undetermined"] = res.undetermined;
  (*id)["first_finding"] = FindingJson(res.first_finding);
  (*id)["unlocked"] = res.unlocked;
  Json alts = Json::array();
  for (const identify::Alternative& a : res.alternatives) {
    alts.push_back({{"banned", a.banned}, {"effects", a.effects}, {"cv_err", a.cv}});
  }
  (*id)["alternatives"] = alts;
  Json also = Json::array();
  for (const identify::Alternative& a : res.also_fits) {
    also.push_back({{"banned", a.banned},
                    {"effects", a.effects},
                    {"num_params", a.num_params},
                    {"chosen_num_params", a.chosen_params},
                    {"cv_err", a.cv}});
  }
  (*id)["also_fits"] = also;
  (*id)["simpler_equivalents"] = res.simpler;
  if (!cl.frames.empty()) (*id)["frames"] = FramesJson(cl, res);
  if (!cl.unknown_offset_nodes.empty()) (*id)["marker_offsets"] = OffsetsJson(cl, res);
}

void WriteIdentificationFiles(const ClosedLoopSetup& cl, RunContext& ctx, const identify::Job& job,
                              const identify::Report& rep) {
  const identify::IdentifyResult& res = rep.result;
  // A model that does not lower the validation error is no fix: it is not shipped.
  if (rep.verdict == "explained" || rep.verdict == "partly_explained" ||
      rep.verdict == "ambiguous") {
    WriteAugmented(cl, ctx, job, rep);
    WriteCalibratedModel(ctx, job, rep);
  } else {
    ctx.log(
        "declared_augmented.yaml not written: the identified model does not explain the "
        "validation data (verdict " +
        rep.verdict + ")");
  }
  PlotFinding(ctx, res.finding);  // the finding summary.json reports
  WriteResiduals(cl, ctx, rep.cal, rep.cal_before, rep.cal_after, rep.cal_loads, rep.cal_p0,
                 "calibration");
  WriteResiduals(cl, ctx, rep.val, rep.val_before, rep.val_after, rep.val_loads, rep.val_p0,
                 "validation");
  Plot(cl, ctx, res, rep.val, rep.val_before, rep.val_after, rep.val_loads);
}

}  // namespace flexbench::scenarios
