// Contact fusion (PPOE paper sec. V-B, Fig. 5): a fingertip touches a table whose pose is known
// with the covariance Sigma_v; the 1-D distance along the table's normal corrects the
// end-effector pose iteratively during contact. With the PPOE prior the correlations of the
// chain let the 1-D measurement correct the directions it does not observe; with the
// correlations dropped (naive) it cannot.
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>

#include "estimators/estimator.h"
#include "render/plot.h"
#include "scenarios/runner/common/error_stats.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/log_export.h"
#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/common/pose.h"
#include "scenarios/runner/common/sim_readings.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/common/truth_rig.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/declared_chain.h"
#include "sim/recorded_log.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {
namespace {

class ContactFusionKind : public ScenarioKind {
 public:
  bool ExportsLog() const final { return true; }

  void Configure(const ConfigNode& root) override {
    sim::DeclaredModel declared = ReadModelAndDeclared(root, &model_path_);
    effects_ = sim::ParseEffects(root.Child("effects"));
    const ConfigNode cfg = root.Child("configuration_deg");
    for (const std::string& j : cfg.Keys()) configuration_.emplace_back(j, cfg.GetDouble(j));
    iterations_ = root.GetInt("iterations", 30);
    if (iterations_ < 1) root.Child("iterations").Fail("must be >= 1");
    const ConfigNode sv = root.Child("table_std");  // std of the table pose, [rho; theta]
    const std::vector<double> sd = sv.AsDoubleList();
    if (sd.size() != 6) sv.Fail("expected 6 standard deviations [m m m rad rad rad]");
    for (int i = 0; i < 6; ++i) {
      if (!(sd[i] >= 0.0)) sv.Fail("standard deviations must be >= 0");
      table_std_[i] = sd[i];
      sigma_table_(i, i) = sd[i] * sd[i];
    }
    sensor_std_ = root.GetDouble("distance_std_m", 1e-3);
    if (!(sensor_std_ > 0.0)) root.Child("distance_std_m").Fail("must be > 0");
    estimators_ = ParseEstimators(root.Child("estimators"));

    rig_ = LoadTruthRig(model_path_, effects_, std::move(declared));
    for (const auto& [j, v] : configuration_) rig_.sim->SetCommand(j, 0.0);
    // estimate_in: an observed frame, e.g. the head camera whose depth image shows the table
    // (the paper's set-up): the table's pose is known in that frame, the chain from it to the
    // fingertip (neck, torso, arm) is what the contact corrects, and the scores are in it.
    if (root.Has("estimate_in")) {
      estimate_in_ = root.GetString("estimate_in");
      rig_.setup.reference_frame = rig_.chain->ObservedFrame(estimate_in_);
    }
    for (const EstimatorSpec& spec : estimators_) instances_.push_back(rig_.MakeEstimator(spec));
  }

  // collect (settle, place the table, draw the contact readings) -> estimate -> score, per
  // estimator; then the figure.
  void Run(RunContext& ctx) override {
    const Contact contact = Collect(ctx);
    FittedRangeCheck range(rig_.declared, rig_.chain->q_joints, rig_.sim->nominal_model(),
                           rig_.chain.get());
    range.Observe(contact.joints.q.data(), static_cast<int>(contact.joints.q.size()));
    range.Report(ctx);
    if (!ctx.export_log.empty()) {
      WriteLogWithDeclared(ContactLog(contact), rig_.declared, ctx.export_log);
      ctx.log("the contact's readings written to " + ctx.export_log);
    }
    std::ofstream csv(ctx.out->File("iterations.csv"));
    csv << "iteration,estimator,err_x_m,err_y_m,err_z_m,pos_err_m,rot_err_deg,"
           "eig1,eig2,eig3,eig4,eig5,eig6\n";
    render::Figure fig(1500, 500, 1, 3);
    fig.title = "Fingertip on the table: PPOE (solid) vs naive (dashed)";
    TrajectoryRecorder trajectories;
    for (size_t e = 0; e < instances_.size(); ++e) {
      const Trace trace = Estimate(*instances_[e], contact);
      const Curves curves = Score(e, trace, contact, &csv, &trajectories, ctx);
      Plot(e, curves, &fig);
    }
    trajectories.Write(*ctx.out, estimate_in_.empty() ? "base" : estimate_in_);
    SaveFigure(&fig, ctx);
    (*ctx.summary)["metrics"]["iterations"] = iterations_;
    (*ctx.summary)["metrics"]["estimated_in"] = estimate_in_.empty() ? "base" : estimate_in_;
  }

 private:
  // The contact as every estimator sees it.
  struct Contact {
    lie::SE3 T_w_tip;          // the true fingertip, in the estimators' frame
    lie::SE3 T_w_table_known;  // the table as known to the estimators
    Quat q_w_table;            // its orientation, from which T_w_table_known is made
    estimators::JointReading joints;
    std::vector<double> distances;  // the contact sensor's noise, one draw per iteration
  };

  // The contact as a recorded log of static postures (--export-log): a joint row per iteration
  // (the same posture, estimated afresh each time, as Estimate does), the table (its pose
  // known within table_std, in the estimators' frame: estimate_in), and per iteration from the
  // first the contact sensor's reading as Estimate fuses it: the mean of the contacts so far,
  // with its standard error.
  sim::RecordedLog ContactLog(const Contact& c) const {
    sim::RecordedLog log = LogOfChain(rig_.declared, *rig_.chain);
    log.static_postures = true;
    log.estimate_in = estimate_in_;
    log.planes.push_back({"table", c.q_w_table, c.T_w_table_known, table_std_, sigma_table_});
    log.contact_points.push_back({"fingertip", rig_.declared.end_effector, Vec3::Zero()});
    double distance_sum = 0.0;
    for (int it = 0; it <= iterations_; ++it) {
      estimators::JointReading joints = c.joints;
      joints.t = it;
      AddStepToLog(joints, c.T_w_tip, &log);
      if (it == 0) continue;
      distance_sum += c.distances[it - 1];
      log.contacts.push_back({static_cast<double>(it), 0, 0, distance_sum / it,
                              sensor_std_ / std::sqrt(static_cast<double>(it))});
    }
    return log;
  }

  // One estimator's beliefs, iteration 0 (the prior) to iterations_, and its update statuses.
  struct Trace {
    std::vector<estimators::Belief> beliefs;
    std::map<std::string, int> counts;
  };

  // What Fig. 5 plots per iteration: position error per axis [cm], rotation error [deg],
  // log10 of the covariance's largest and smallest (on its range) eigenvalues.
  struct Curves {
    std::vector<double> it, ex, ey, ez, rot, eig_max, eig_min;
  };

  Contact Collect(RunContext& ctx) {
    for (const auto& [j, deg] : configuration_) rig_.sim->SetCommand(j, deg * M_PI / 180.0);
    rig_.sim->Settle();
    // The fingertip and the table in the estimators' frame ("w" below): the world, or the true
    // pose of the reference frame (where the depth camera that sees the table really is).
    const lie::SE3 T_w_ref =
        estimate_in_.empty() ? lie::SE3() : ToSE3(rig_.sim->Pose(estimate_in_));
    const lie::SE3 T_world_tip = ToSE3(rig_.sim->Pose(rig_.declared.end_effector));
    Contact c;
    c.T_w_tip = T_w_ref.Inverse() * T_world_tip;
    // The table passes through the true fingertip (the finger touches it), normal up. As in
    // the paper, its pose is known with the zero-mean uncertainty Sigma_v. The table's pose
    // error is one error shared by every iteration (the same table, seen once), not a fresh
    // draw per contact: only the contact sensor's noise is independent between iterations.
    // (Not drawn here: the in-plane and tilt parts are invisible at a table frame centred on
    // the contact point, and its 1 mm normal part would be a floor common to both estimators.)
    std::mt19937_64 rng(ctx.seed * 6151ULL + 3);
    // Through a quaternion, as a recorded log states a plane (--export-log replays to the bit).
    const lie::SE3 T_w_table =
        T_w_ref.Inverse() * lie::SE3(Mat3::Identity(), T_world_tip.translation());
    c.q_w_table = Quat(T_w_table.rotation());
    c.T_w_table_known = sim::PlanePose(c.q_w_table, T_w_table.translation());
    std::normal_distribution<double> distance_noise(0.0, sensor_std_);
    c.joints = EncoderReading(*rig_.sim, *rig_.chain, 0.0);
    c.distances.resize(iterations_);
    for (double& d : c.distances) d = distance_noise(rng);
    return c;
  }

  Trace Estimate(estimators::Estimator& est, const Contact& c) const {
    Trace trace;
    est.Reset();
    ++trace.counts[estimators::ToString(est.Update(c.joints))];
    double distance_sum = 0.0;
    for (int it = 0; it <= iterations_; ++it) {
      if (it > 0) {
        // The pose is static and the table error is shared, so `it` contacts are one contact
        // at their mean distance: table uncertainty Sigma_v once, the sensor's std / sqrt(it).
        // Feeding Sigma_v again with every contact would count the table's information `it`
        // times: the normal variance then falls far below Sigma_v's 1 mm^2, and the iterated
        // update, re-linearised 30 times against that over-confident normal, walks along the
        // unobserved directions (rotations about the neck mix in through the SE(3) curvature)
        // by millimetres to centimetres with the noise. Each iteration is therefore the prior
        // plus that one contact: to first order what a filter carrying the table error gives.
        distance_sum += c.distances[it - 1];
        est.Reset();
        est.Update(c.joints);  // the prior again (counted once, above)
        estimators::PlaneContact m;
        m.t = it;
        m.frame = rig_.chain->end_effector;
        m.T_base_plane = c.T_w_table_known;
        m.plane_cov = sigma_table_;
        m.distance = distance_sum / it;
        m.std = sensor_std_ / std::sqrt(static_cast<double>(it));
        ++trace.counts[estimators::ToString(est.Update(m))];
      }
      trace.beliefs.push_back(est.Estimate());
    }
    return trace;
  }

  // Every iteration into the CSV, the curves and the trajectories; the last into the metrics.
  Curves Score(size_t e, const Trace& trace, const Contact& c, std::ofstream* csv,
               TrajectoryRecorder* trajectories, RunContext& ctx) const {
    Curves curves;
    ErrorStats stats;
    for (int it = 0; it <= iterations_; ++it) {
      const estimators::Belief& b = trace.beliefs[it];
      const Vec3 err = b.T_base_ee.translation() - c.T_w_tip.translation();
      const double rot_deg = b.T_base_ee.Between(c.T_w_tip).Log().tail<3>().norm() * 180.0 / M_PI;
      Eigen::SelfAdjointEigenSolver<Mat6> eig(0.5 * (b.cov + b.cov.transpose()));
      WriteRow(it, estimators_[e].name, err, rot_deg, eig.eigenvalues(), csv);
      curves.it.push_back(it);
      curves.ex.push_back(err.x() * 100);
      curves.ey.push_back(err.y() * 100);
      curves.ez.push_back(err.z() * 100);
      curves.rot.push_back(rot_deg);
      curves.eig_max.push_back(std::log10(std::max(eig.eigenvalues()[5], 1e-30)));
      curves.eig_min.push_back(std::log10(std::max(SmallestOnRange(eig.eigenvalues()), 1e-300)));
      if (it == iterations_) stats.Add(b.T_base_ee, b.cov, c.T_w_tip);
      // Every iteration (timestamp: its index); the metrics score the last.
      if (e == 0) trajectories->AddTruth(it, c.T_w_tip);
      trajectories->Add(estimators_[e].name, it, b.T_base_ee, b.cov);
    }
    WriteMetrics(e, stats, curves, trace, ctx);
    return curves;
  }

  static void WriteRow(int it, const std::string& estimator, const Vec3& err, double rot_deg,
                       const Vec6& eigenvalues, std::ofstream* csv) {
    char line[512];
    std::snprintf(line, sizeof(line), "%d,%s,%.9g,%.9g,%.9g,%.9g,%.9g", it, estimator.c_str(),
                  err.x(), err.y(), err.z(), err.norm(), rot_deg);
    *csv << line;
    for (int k = 5; k >= 0; --k) {
      std::snprintf(line, sizeof(line), ",%.9g", eigenvalues[k]);
      *csv << line;
    }
    *csv << "\n";
  }

  // Smallest eigenvalue on the covariance's range: PPOE priors from rotational sources are
  // singular, and below 1e-12 of the largest is rounding (the rule Nees() uses).
  static double SmallestOnRange(const Vec6& eigenvalues) {
    for (int k = 0; k < 6; ++k) {
      if (eigenvalues[k] > 1e-12 * eigenvalues[5]) return eigenvalues[k];
    }
    return eigenvalues[5];
  }

  void WriteMetrics(size_t e, const ErrorStats& stats, const Curves& curves, const Trace& trace,
                    RunContext& ctx) const {
    Json& m = (*ctx.summary)["estimators"][estimators_[e].name]["metrics"];
    m["pos_err_initial_m"] = std::sqrt(curves.ex[0] * curves.ex[0] + curves.ey[0] * curves.ey[0] +
                                       curves.ez[0] * curves.ez[0]) /
                             100;
    m["pos_err_final_m"] = stats.last_pos();
    m["rot_err_final_deg"] = stats.last_rot_deg();
    m["nees_final"] = stats.last_nees();
    // The chi-square bounds a consistent estimator's final NEES falls in (95%, one sample).
    Json all;
    stats.WriteMetrics(&all);
    for (const char* key : {"nees_dof", "nees_bound_low", "nees_bound_high", "nees_consistent"}) {
      if (all.contains(key)) m[key] = all[key];
    }
    Json& updates = (*ctx.summary)["estimators"][estimators_[e].name]["updates"];
    for (const auto& [status, n] : trace.counts) updates[status] = n;
    updates["covariance_repairs"] = instances_[e]->covariance_repairs();
  }

  // Fig. 5 draws PPOE (solid) and naive (dashed); fk, which fuses no contact, stays at
  // iteration 0's error (CSV only).
  void Plot(size_t e, const Curves& curves, render::Figure* fig) const {
    if (!instances_[e]->FusesExternalMeasurements()) return;
    const bool naive = !instances_[e]->HasConfigurationPrior();
    const render::LineStyle style = naive ? render::LineStyle::kDashed : render::LineStyle::kSolid;
    const std::string tag = estimators_[e].name;
    const std::pair<const char*, const std::vector<double>*> axes[] = {
        {" x", &curves.ex}, {" y", &curves.ey}, {" z", &curves.ez}};
    int color = 0;
    for (const auto& [axis, values] : axes) {
      render::Series& s = fig->axes(0, 0).AddLine(tag + axis, curves.it, *values);
      s.line = style;
      s.color = render::PaletteColor(color++);
    }
    render::Series& r = fig->axes(0, 1).AddLine(tag, curves.it, curves.rot);
    r.line = style;
    render::Series& hi = fig->axes(0, 2).AddLine(tag + " largest", curves.it, curves.eig_max);
    hi.line = style;
    hi.color = render::PaletteColor(0);
    render::Series& lo =
        fig->axes(0, 2).AddLine(tag + " smallest on its range", curves.it, curves.eig_min);
    lo.line = style;
    lo.color = render::PaletteColor(3);
  }

  void SaveFigure(render::Figure* fig, RunContext& ctx) const {
    for (int k = 0; k < 3; ++k) {
      fig->axes(0, k).x_min = 0.0;
      fig->axes(0, k).x_max = iterations_;
    }
    fig->axes(0, 0).legend_position = render::LegendPosition::kBottomRight;
    fig->axes(0, 2).legend_position = render::LegendPosition::kBottomLeft;
    fig->axes(0, 0).title = "(a) position error per axis";
    fig->axes(0, 0).x_label = "iteration";
    fig->axes(0, 0).y_label = "error [cm]";
    fig->axes(0, 1).title = "(b) rotation error";
    fig->axes(0, 1).x_label = "iteration";
    fig->axes(0, 1).y_label = "error [deg]";
    fig->axes(0, 2).title = "(c) covariance eigenvalues";
    fig->axes(0, 2).x_label = "iteration";
    fig->axes(0, 2).y_label = "log10 eigenvalue";
    fig->SavePng((ctx.out->FramesDir() / "fig5_contact.png").string());
  }

  std::string model_path_;
  std::string estimate_in_;  // "" = the declared base
  sim::EffectList effects_;
  std::vector<std::pair<std::string, double>> configuration_;
  int iterations_ = 30;
  Vec6 table_std_ = Vec6::Zero();
  Mat6 sigma_table_ = Mat6::Zero();
  double sensor_std_ = 1e-3;
  std::vector<EstimatorSpec> estimators_;
  TruthRig rig_;
  std::vector<std::unique_ptr<estimators::Estimator>> instances_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeContactFusionKind() {
  return std::make_unique<ContactFusionKind>();
}

}  // namespace flexbench::scenarios
