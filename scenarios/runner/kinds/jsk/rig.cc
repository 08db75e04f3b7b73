#include "scenarios/runner/kinds/jsk/rig.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"
#include "render/plot.h"
#include "scenarios/runner/common/pose.h"
#include "scenarios/runner/common/trajectories.h"
#include "sim/mujoco_model.h"
#include "sim/rng.h"

namespace flexbench::scenarios::jsk {

double Deg(double rad) { return rad * 180.0 / M_PI; }

void FailAt(const ConfigNode& node, const std::string& key, const std::string& message) {
  if (const auto child = node.Optional(key)) child->Fail(message);
  node.Fail("'" + key + "' (default) " + message);
}

double AngleError(double a, double b) { return std::remainder(a - b, 2.0 * M_PI); }

void FitAxes(render::Axes* ax, size_t skip, double headroom, bool from_zero) {
  double x0 = 1e300, x1 = -1e300, y0 = from_zero ? 0.0 : 1e300, y1 = -1e300;
  for (const render::Series& s : ax->series) {
    if (s.x.empty()) continue;
    x0 = std::min(x0, s.x.front());
    x1 = std::max(x1, s.x.back());
    for (size_t i = std::min(skip, s.y.size() / 10); i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i])) continue;
      y0 = std::min(y0, s.y[i]);
      y1 = std::max(y1, s.y[i]);
    }
  }
  if (x1 > x0) {
    ax->x_min = x0;
    ax->x_max = x1;
  }
  if (y1 > y0) {
    ax->y_min = from_zero && y0 >= 0.0 ? y0 : y0 - 0.05 * (y1 - y0);
    ax->y_max = y1 + headroom * (y1 - y0);
  }
}

void StyleComparison(render::Series* s) {
  if (s->label.find("bootstrap") != std::string::npos ||
      s->label.find("_n2048") != std::string::npos) {
    s->line = render::LineStyle::kDashed;
    s->line_width = 1;
  }
}

std::vector<LabelledEstimator> ParseLabelledEstimators(const ConfigNode& node) {
  std::vector<LabelledEstimator> out;
  for (const std::string& label : node.Keys()) {
    const ConfigNode entry = node.Child(label);
    LabelledEstimator e;
    e.label = label;
    e.name = label;
    std::map<std::string, std::vector<double>> values;
    if (entry.IsMap()) {
      for (const std::string& key : entry.Keys()) {
        const ConfigNode v = entry.Child(key);
        if (key == "estimator") {
          e.name = v.AsString();
          continue;
        }
        values[key] = v.IsSequence() ? v.AsDoubleList() : std::vector<double>{v.AsDouble()};
      }
    } else if (!(entry.IsScalar() && entry.AsString().empty())) {
      entry.Fail("expected a mapping of parameters ({} for none)");
    }
    bool known = false;
    std::string list;
    for (const auto& r : estimators::EstimatorRegistry()) {
      known = known || e.name == r.name;
      list += std::string(list.empty() ? "" : ", ") + r.name;
    }
    if (!known) entry.Fail("unknown estimator '" + e.name + "' (known: " + list + ")");
    e.params = estimators::Params(values, entry.WhereKey());
    e.where = entry.WhereKey();
    out.push_back(std::move(e));
  }
  if (out.empty()) node.Fail("no estimators");
  return out;
}

Rig LoadRig(const ConfigNode& root, bool with_effects) {
  Rig rig;
  const ConfigNode model = root.Child("model");
  const std::string model_path = model.ResolvePath(model.AsString());
  const ConfigNode declared = root.Child("declared");
  rig.declared = sim::LoadDeclaredModel(declared.ResolvePath(declared.AsString()));
  sim::EffectList effects;
  if (with_effects) {
    if (const auto e = root.Optional("effects")) effects = sim::ParseEffects(*e);
  }
  rig.sim = sim::Simulation::Load(model_path, effects);
  rig.chain = std::make_unique<sim::DeclaredChain>(
      sim::BuildDeclaredChain(rig.sim->nominal_model(), rig.declared));
  const ConfigNode imus = root.Child("imus");
  for (const ConfigNode& item : imus.Items()) {
    const std::string site = item.AsString();
    const auto& sites = rig.sim->catalog().imu_sites;
    if (std::find(sites.begin(), sites.end(), site) == sites.end()) {
      item.Fail("'" + site + "' is not an IMU site of " + model_path +
                " (a site with an MJCF gyro and accelerometer)");
    }
    rig.imu_sites.push_back(site);
    rig.imu_frames.push_back(rig.chain->ObservedFrame(site));
  }
  rig.setup.model = &rig.chain->model;
  rig.setup.effects = rig.chain->effects_or_null();
  rig.setup.end_effector = rig.chain->end_effector;
  for (kinematics::FrameId f : rig.imu_frames) rig.setup.imus.push_back(estimators::ImuSetup{f});
  const std::vector<std::string>& act = rig.sim->actuated_joints();
  for (const std::string& j : rig.chain->q_joints) {
    const auto it = std::find(act.begin(), act.end(), j);
    if (it == act.end()) {
      root.Child("declared").Fail("declared joint '" + j + "' has no actuator in " + model_path);
    }
    rig.act_of_q.push_back(static_cast<int>(it - act.begin()));
  }
  if (rig.nq() != rig.sim->num_actuated()) {
    root.Child("declared").Fail("the declared model must list every actuated joint");
  }
  return rig;
}

Eigen::VectorXd Rig::ToActuators(const Eigen::VectorXd& q) const {
  Eigen::VectorXd a(sim->num_actuated());
  for (int k = 0; k < nq(); ++k) a[act_of_q[k]] = q[k] + chain->q_qpos0[k];
  return a;
}

Eigen::VectorXd Rig::LinkAngles() const {
  Eigen::VectorXd q(nq());
  for (int k = 0; k < nq(); ++k) q[k] = sim->JointPosition(chain->q_joints[k]) - chain->q_qpos0[k];
  return q;
}

std::unique_ptr<estimators::Estimator> MakeLabelled(const Rig& rig, const LabelledEstimator& e,
                                                    std::uint64_t seed) {
  estimators::EstimatorSetup s = rig.setup;
  s.params = e.params;
  s.seed = seed;
  try {
    return estimators::MakeEstimator(e.name, s);
  } catch (const InputError& err) {
    const std::string what = err.what();
    if (e.where.empty() || what.rfind(e.where, 0) == 0) throw;
    throw InputError(e.where + ": " + what);
  }
}

Trajectory ParseTrajectory(const ConfigNode& node, int nq, bool dynamic) {
  Trajectory tr;
  const ConfigNode wps = node.Child("waypoints_deg");
  for (const ConfigNode& item : wps.Items()) {
    const std::vector<double> v = item.AsDoubleList();
    if (static_cast<int>(v.size()) != nq) {
      item.Fail("expected " + std::to_string(nq) + " angles (declared joint order), got " +
                std::to_string(v.size()));
    }
    Eigen::VectorXd q(nq);
    for (int k = 0; k < nq; ++k) {
      if (!std::isfinite(v[k])) item.Fail("angles must be finite");
      q[k] = v[k] * M_PI / 180.0;
    }
    tr.waypoints.push_back(q);
  }
  if (tr.waypoints.size() < 2) wps.Fail("need at least two waypoints");
  if (dynamic) {
    tr.segment_s = node.GetDouble("segment_s");
    tr.hold_s = node.GetDouble("hold_s", 0.0);
    if (!(tr.segment_s > 0.0)) node.Child("segment_s").Fail("must be > 0");
    if (!(tr.hold_s >= 0.0)) node.Child("hold_s").Fail("must be >= 0");
  } else {
    tr.segment_steps = node.GetInt("segment_steps");
    tr.hold_steps = node.GetInt("hold_steps", 0);
    if (tr.segment_steps < 1) node.Child("segment_steps").Fail("must be >= 1");
    if (tr.hold_steps < 0) node.Child("hold_steps").Fail("must be >= 0");
  }
  return tr;
}

int Trajectory::Steps() const {
  return hold_steps + static_cast<int>(waypoints.size() - 1) * (segment_steps + hold_steps);
}

Eigen::VectorXd Trajectory::AtStep(int k) const {
  if (k < hold_steps) return waypoints.front();
  const int period = segment_steps + hold_steps;
  const int kk = k - hold_steps;
  const int seg = std::min(kk / period, static_cast<int>(waypoints.size()) - 2);
  const int r = kk - seg * period;
  if (r >= segment_steps) return waypoints[seg + 1];
  const double a = static_cast<double>(r + 1) / segment_steps;
  return (1.0 - a) * waypoints[seg] + a * waypoints[seg + 1];
}

double Trajectory::Duration() const {
  return hold_s + static_cast<double>(waypoints.size() - 1) * (segment_s + hold_s);
}

Eigen::VectorXd Trajectory::AtTime(double t, int* segment) const {
  if (segment) *segment = 0;
  if (t <= hold_s) return waypoints.front();
  const double period = segment_s + hold_s;
  const double tt = t - hold_s;
  const int seg = std::min(static_cast<int>(tt / period), static_cast<int>(waypoints.size()) - 2);
  const double r = tt - seg * period;
  if (segment) *segment = seg + 1;
  if (r >= segment_s) return waypoints[seg + 1];
  const double x = r / segment_s;
  const double a = x * x * (3.0 - 2.0 * x);  // smooth start and stop
  return (1.0 - a) * waypoints[seg] + a * waypoints[seg + 1];
}

void Trace::Add(double time, const estimators::Belief& b, const pf::ParticleSummary* pf,
                const lie::SE3& T_true_step) {
  t.push_back(time);
  for (size_t j = 0; j < mean.size(); ++j) {
    const double m = b.q[j];
    mean[j].push_back(m);
    if (pf) {
      lower[j].push_back(pf->lower95[j]);
      upper[j].push_back(pf->upper95[j]);
    } else {
      lower[j].push_back(m - 1.96 * b.q_std[j]);
      upper[j].push_back(m + 1.96 * b.q_std[j]);
    }
  }
  const Vec3 e = b.T_base_ee.translation() - T_true_step.translation();
  T_est.push_back(b.T_base_ee);
  cov.push_back(b.cov);
  T_true.push_back(T_true_step);
  ee_err_m.push_back(e.norm());
  ee_err_z_m.push_back(e.z());
  ess.push_back(pf ? pf->ess : 0.0);
}

const pf::ParticleSummary* PfSummary(const estimators::Estimator& e) {
  const auto* p = dynamic_cast<const estimators::PfEstimator*>(&e);
  return p ? &p->filter().Summary() : nullptr;
}

ImuPipeline::ImuPipeline(const std::vector<std::string>& sites, double beta)
    : sites_(sites), last_t_(sites.size(), 0.0), started_(sites.size(), false) {
  for (size_t k = 0; k < sites.size(); ++k) filters_.emplace_back(beta);
}

void ImuPipeline::Feed(const sim::ImuReading& r, const Rig& rig, bool init_truth) {
  const auto it = std::find(sites_.begin(), sites_.end(), r.site);
  if (it == sites_.end()) return;
  const size_t k = it - sites_.begin();
  if (!started_[k]) {
    if (init_truth) {
      filters_[k].Reset(Quat(rig.sim->SitePose(r.site).linear()));
    } else {
      filters_[k].InitFromAccel(r.accel);
    }
    started_[k] = true;
    last_t_[k] = r.t;
    return;
  }
  filters_[k].Update(r.gyro, r.accel, r.t - last_t_[k]);
  last_t_[k] = r.t;
}

bool ImuPipeline::Ready() const {
  return std::all_of(started_.begin(), started_.end(), [](bool b) { return b; });
}

void PlotJointBands(const Rig& rig, const std::string& title, const std::vector<Trace>& traces,
                    const std::vector<std::vector<double>>* truth,
                    const std::vector<std::vector<double>>& reference, const std::string& path,
                    const std::string& x_label) {
  const int nq = rig.nq();
  const int cols = 3;
  const int rows = (nq + 1 + cols - 1) / cols;
  render::Figure fig(1500, 430 * rows, rows, cols);
  fig.title = title;
  const std::vector<double>& t = traces.front().t;
  const auto deg = [](const std::vector<double>& v) {
    std::vector<double> out(v.size());
    for (size_t i = 0; i < v.size(); ++i) out[i] = Deg(v[i]);
    return out;
  };
  const double t_min = t.empty() ? 0.0 : t.front();
  const double t_max = t.empty() ? 1.0 : t.back();
  for (int j = 0; j < nq; ++j) {
    render::Axes& ax = fig.axes(j / cols, j % cols);
    ax.x_min = t_min;
    ax.x_max = t_max;
    ax.title = rig.joint_names()[j];
    ax.x_label = x_label;
    ax.y_label = "angle [deg]";
    ax.legend_position = render::LegendPosition::kTopLeft;
    render::Series& ref = ax.AddLine("reference", t, deg(reference[j]));
    ref.color = render::Rgb{140, 140, 140};
    ref.line = render::LineStyle::kDashed;
    if (truth) {
      render::Series& tr = ax.AddLine("truth (effective)", t, deg((*truth)[j]));
      tr.color = render::Rgb{0, 0, 0};
    }
    // Head room above the data for the legend.
    // (The first steps, where the prior of [PF eq. 29] is still flat, do not set the range.)
    double lo = 1e300, hi = -1e300;
    const auto extend = [&](const std::vector<double>& v) {
      for (size_t i = std::min<size_t>(5, v.size() / 10); i < v.size(); ++i) {
        if (std::isfinite(v[i])) lo = std::min(lo, Deg(v[i])), hi = std::max(hi, Deg(v[i]));
      }
    };
    extend(reference[j]);
    if (truth) extend((*truth)[j]);
    for (const Trace& tr : traces) extend(tr.lower[j]), extend(tr.upper[j]);
    if (hi > lo) {
      ax.y_min = lo - 0.05 * (hi - lo);
      ax.y_max = hi + 0.6 * (hi - lo);
    }
    for (size_t e = 0; e < traces.size(); ++e) {
      const render::Rgb c = render::PaletteColor(static_cast<int>(e));
      render::Series& m =
          ax.AddLine(traces[e].label + " mean", traces[e].t, deg(traces[e].mean[j]));
      m.color = c;
      render::Series& lo = ax.AddLine(traces.size() == 1 ? "95% interval" : "", traces[e].t,
                                      deg(traces[e].lower[j]));
      lo.color = c;
      lo.line_width = 1;
      render::Series& hi = ax.AddLine("", traces[e].t, deg(traces[e].upper[j]));
      hi.color = c;
      hi.line_width = 1;
    }
  }
  render::Axes& ax = fig.axes(nq / cols, nq % cols);
  ax.x_min = t_min;
  ax.x_max = t_max;
  ax.title = "end-effector position error";
  ax.x_label = x_label;
  double ee_max = 1e-3;
  ax.y_label = "error [cm]";
  for (size_t e = 0; e < traces.size(); ++e) {
    std::vector<double> cm(traces[e].ee_err_m.size());
    for (size_t i = 0; i < cm.size(); ++i) cm[i] = 100.0 * traces[e].ee_err_m[i];
    render::Series& s = ax.AddLine(traces[e].label, traces[e].t, cm);
    s.color = render::PaletteColor(static_cast<int>(e));
    for (size_t i = std::min<size_t>(5, cm.size() / 10); i < cm.size(); ++i) {
      ee_max = std::max(ee_max, cm[i]);
    }
  }
  ax.y_min = 0.0;
  ax.y_max = 1.35 * ee_max;
  // The effective sample size of the particle filters, when a panel is left.
  const bool any_pf = std::any_of(traces.begin(), traces.end(), [](const Trace& tr) {
    return std::any_of(tr.ess.begin(), tr.ess.end(), [](double e) { return e > 0.0; });
  });
  if (nq + 1 < rows * cols && any_pf) {
    render::Axes& e = fig.axes((nq + 1) / cols, (nq + 1) % cols);
    e.x_min = t_min;
    e.x_max = t_max;
    e.title = "effective sample size (before resampling)";
    e.x_label = x_label;
    e.y_label = "ESS";
    e.y_min = 0.0;
    double ess_max = 1.0;
    for (size_t k = 0; k < traces.size(); ++k) {
      render::Series& s = e.AddLine(traces[k].label, traces[k].t, traces[k].ess);
      s.color = render::PaletteColor(static_cast<int>(k));
      for (double v : traces[k].ess) ess_max = std::max(ess_max, v);
    }
    e.y_max = 1.3 * ess_max;
  } else if (nq + 1 < rows * cols) {
    // Estimators without particles: the angle each one adds to the reference (its estimate of
    // the deflection, or its failure).
    render::Axes& d = fig.axes((nq + 1) / cols, (nq + 1) % cols);
    d.title = "estimate minus reference";
    d.x_label = x_label;
    d.y_label = "angle [deg]";
    for (int j = 0; j < nq; ++j) {
      for (const Trace& tr : traces) {
        std::vector<double> diff(tr.t.size());
        for (size_t i = 0; i < diff.size(); ++i) {
          diff[i] = Deg(AngleError(tr.mean[j][i], reference[j][i]));
        }
        d.AddLine(rig.joint_names()[j], tr.t, diff).color = render::PaletteColor(j);
      }
    }
    FitAxes(&d, 0, 0.5, /*from_zero=*/false);
  }
  fig.SavePng(path);
}

void WriteTraces(const Rig& rig, const std::vector<Trace>& traces,
                 const std::vector<std::vector<double>>* truth,
                 const std::vector<std::vector<double>>& reference, OutputDir* out) {
  std::ofstream csv(out->File("traces.csv"));
  csv << "t,estimator,joint,truth_deg,reference_deg,mean_deg,lower95_deg,upper95_deg\n";
  char line[512];
  for (const Trace& tr : traces) {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      for (int j = 0; j < rig.nq(); ++j) {
        char truth_text[64] = "";
        if (truth) std::snprintf(truth_text, sizeof(truth_text), "%.6f", Deg((*truth)[j][i]));
        std::snprintf(line, sizeof(line), "%.4f,%s,%s,%s,%.6f,%.6f,%.6f,%.6f\n", tr.t[i],
                      tr.label.c_str(), rig.joint_names()[j].c_str(), truth_text,
                      Deg(reference[j][i]), Deg(tr.mean[j][i]), Deg(tr.lower[j][i]),
                      Deg(tr.upper[j][i]));
        csv << line;
      }
    }
  }
  std::ofstream ee(out->File("ee.csv"));
  ee << "t,estimator,ee_err_m,ee_err_z_m,ess\n";
  for (const Trace& tr : traces) {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      std::snprintf(line, sizeof(line), "%.4f,%s,%.9f,%.9f,%.3f\n", tr.t[i], tr.label.c_str(),
                    tr.ee_err_m[i], tr.ee_err_z_m[i], tr.ess[i]);
      ee << line;
    }
  }
  // TUM trajectories (a pose per step, t in seconds of the run; the synthetic kinds count steps).
  TrajectoryRecorder trajectories;
  if (!traces.empty()) {
    const Trace& first = traces.front();
    for (size_t i = 0; i < first.t.size(); ++i) trajectories.AddTruth(first.t[i], first.T_true[i]);
  }
  for (const Trace& tr : traces) {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      trajectories.Add(tr.label, tr.t[i], tr.T_est[i], tr.cov[i]);
    }
  }
  trajectories.Write(*out, "base");
}

SyntheticOptions ParseSyntheticOptions(const ConfigNode& root) {
  SyntheticOptions o;
  o.k = root.GetDouble("deflection_k");
  if (!std::isfinite(o.k)) root.Child("deflection_k").Fail("must be finite");
  if (const auto n = root.Optional("noise")) {
    o.reference_std = n->GetDouble("reference_deg", 0.0) * M_PI / 180.0;
    o.orientation_std = n->GetDouble("orientation_deg", 0.0) * M_PI / 180.0;
    o.position_std = n->GetDouble("position_m", 0.0);
    if (!(o.reference_std >= 0 && o.orientation_std >= 0 && o.position_std >= 0)) {
      n->Fail("noise standard deviations must be >= 0");
    }
  }
  return o;
}

SyntheticRun MakeSyntheticRun(const Rig& rig, const Trajectory& trajectory,
                              const SyntheticOptions& options, std::uint64_t seed) {
  const int steps = trajectory.Steps();
  const int nq = rig.nq();
  const kinematics::PpoeModel& model = rig.chain->model;
  kinematics::PpoeData data(model);
  sim::NoiseStream ref_noise(seed, "jsk_synthetic/reference");
  sim::NoiseStream ori_noise(seed, "jsk_synthetic/orientation");
  sim::NoiseStream pos_noise(seed, "jsk_synthetic/position");
  SyntheticRun run;
  run.truth.resize(nq);
  run.reference.resize(nq);
  run.joints.resize(steps);
  run.orientations.resize(steps);
  run.positions.resize(steps);
  run.T_true.resize(steps);
  for (int s = 0; s < steps; ++s) {
    const Eigen::VectorXd ref = trajectory.AtStep(s);
    const Eigen::VectorXd g_act = rig.sim->GravityTorque(rig.ToActuators(ref));
    Eigen::VectorXd eff(nq);
    for (int j = 0; j < nq; ++j) {
      eff[j] = ref[j] + options.k * g_act[rig.act_of_q[j]];  // [PF eq. 31]
      run.deflection_max = std::max(run.deflection_max, std::abs(eff[j] - ref[j]));
      run.truth[j].push_back(eff[j]);
      run.reference[j].push_back(ref[j]);
    }
    kinematics::ForwardKinematics(model, data, eff);
    estimators::JointReading& jr = run.joints[s];
    jr.t = s;
    jr.q.resize(nq);
    jr.std = estimators::JointVector::Constant(nq, options.reference_std);
    for (int j = 0; j < nq; ++j) jr.q[j] = ref[j] + ref_noise.Normal(options.reference_std);
    for (kinematics::FrameId f : rig.imu_frames) {
      estimators::OrientationReading o;
      o.t = s;
      o.frame = f;
      Vec3 d;
      for (int a = 0; a < 3; ++a) d[a] = ori_noise.Normal(options.orientation_std);
      o.q_base_frame = Quat(data.T_base_frame[f].rotation() * lie::SO3Exp(d)).normalized();
      run.orientations[s].push_back(o);
    }
    run.T_true[s] = data.T_base_frame[rig.chain->end_effector];
    estimators::PositionReading& p = run.positions[s];
    p.t = s;
    p.frame = rig.chain->end_effector;
    for (int a = 0; a < 3; ++a)
      p.p_base[a] = run.T_true[s].translation()[a] + pos_noise.Normal(options.position_std);
    p.cov = Mat3::Identity() * std::max(options.position_std * options.position_std, 1e-12);
  }
  return run;
}

Trace RunSynthetic(const Rig& rig, const LabelledEstimator& spec, const SyntheticRun& run,
                   std::uint64_t seed, int* rejected) {
  auto est = MakeLabelled(rig, spec, seed);
  est->Reset();
  Trace tr;
  tr.label = spec.label;
  tr.Resize(rig.nq());
  *rejected = 0;
  const auto count = [&](estimators::UpdateStatus st) {
    *rejected +=
        st != estimators::UpdateStatus::kAccepted && st != estimators::UpdateStatus::kIgnored;
  };
  for (int s = 0; s < run.steps(); ++s) {
    est->Predict(s);
    count(est->Update(run.joints[s]));
    for (const auto& o : run.orientations[s]) count(est->Update(o));
    count(est->Update(run.positions[s]));
    tr.Add(s, est->Estimate(), PfSummary(*est), run.T_true[s]);
  }
  return tr;
}

DynamicOptions ParseDynamicOptions(const ConfigNode& root) {
  DynamicOptions o;
  o.filter_rate_hz = root.GetDouble("filter_rate_hz", o.filter_rate_hz);
  if (!(o.filter_rate_hz > 0.0)) root.Child("filter_rate_hz").Fail("must be > 0");
  if (const auto m = root.Optional("madgwick")) {
    o.madgwick_beta = m->GetDouble("beta", o.madgwick_beta);
    if (!(o.madgwick_beta > 0.0)) m->Child("beta").Fail("must be > 0");
    const std::string init = m->GetString("init", "accel");
    if (init != "accel" && init != "truth") m->Child("init").Fail("expected 'accel' or 'truth'");
    o.madgwick_init_truth = init == "truth";
  }
  return o;
}

std::vector<Snapshot> SimulateDynamic(Rig& rig, const Trajectory& trajectory,
                                      sim::SensorSuite& sensors, const DynamicOptions& options,
                                      const RunContext& ctx) {
  sim::Simulation& sim = *rig.sim;
  const int nq = rig.nq();
  ImuPipeline imus(rig.imu_sites, options.madgwick_beta);
  sim.SetCommand(rig.ToActuators(trajectory.AtTime(0.0)));
  sim.Settle();
  const double t0 = sim.time();
  const double dt = sim.timestep();
  const double period = 1.0 / options.filter_rate_hz;
  const double duration = trajectory.Duration();
  Eigen::VectorXd encoders = Eigen::VectorXd::Constant(nq, std::nan(""));
  std::vector<Snapshot> snaps;
  std::vector<sim::SensorReading> readings;
  int next_tick = 1;  // the first snapshot after one filter period
  const int total_ticks = static_cast<int>(std::floor(duration / period + 1e-9));
  while (sim.time() - t0 < duration - 1e-9) {
    const double t_next = sim.time() - t0 + dt;
    sim.SetCommand(rig.ToActuators(trajectory.AtTime(t_next)));
    sim.Step(1);
    readings.clear();
    sensors.Poll(sim, &readings);
    for (const sim::SensorReading& r : readings) {
      if (const auto* imu = std::get_if<sim::ImuReading>(&r)) {
        imus.Feed(*imu, rig, options.madgwick_init_truth);
      } else if (const auto* enc = std::get_if<sim::EncoderReading>(&r)) {
        for (int k = 0; k < nq; ++k) {
          if (rig.chain->q_joints[k] == enc->joint)
            encoders[k] = enc->position - rig.chain->q_qpos0[k];
        }
      }
    }
    const double t = sim.time() - t0;
    if (t + 1e-9 < next_tick * period) continue;
    ++next_tick;
    if (!encoders.allFinite() || !imus.Ready()) {
      throw InputError(
          "jsk scenario: the sensors must include an encoder for every declared "
          "joint and every IMU, sampled at least at the filter rate");
    }
    Snapshot s;
    s.t = t;
    s.reference = trajectory.AtTime(t, &s.segment);
    s.link = rig.LinkAngles();
    s.joints.t = t;
    s.joints.q = encoders;
    s.joints.std = estimators::JointVector::Zero(nq);
    for (size_t k = 0; k < rig.imu_frames.size(); ++k) {
      estimators::OrientationReading o;
      o.t = t;
      o.frame = rig.imu_frames[k];
      o.q_base_frame = imus.Orientation(static_cast<int>(k));
      s.imus.push_back(o);
      s.imu_true.push_back(Quat(sim.SitePose(rig.imu_sites[k]).linear()));
    }
    const std::string ee = rig.declared.end_effector;
    s.T_true = ToSE3(sim.Pose(ee));
    snaps.push_back(std::move(s));
    ctx.progress("simulation", static_cast<int>(snaps.size()), total_ticks);
  }
  return snaps;
}

Trace RunOnSnapshots(const Rig& rig, const LabelledEstimator& spec,
                     const std::vector<Snapshot>& snaps, std::uint64_t seed, bool with_position,
                     const RunContext& ctx, int* rejected) {
  auto est = MakeLabelled(rig, spec, seed);
  est->Reset();
  Trace tr;
  tr.label = spec.label;
  tr.Resize(rig.nq());
  *rejected = 0;
  const auto count = [&](estimators::UpdateStatus st) {
    *rejected +=
        st != estimators::UpdateStatus::kAccepted && st != estimators::UpdateStatus::kIgnored;
  };
  for (size_t i = 0; i < snaps.size(); ++i) {
    const Snapshot& s = snaps[i];
    est->Predict(s.t);
    count(est->Update(s.joints));
    for (const auto& o : s.imus) count(est->Update(o));
    if (with_position) {
      estimators::PositionReading p;
      p.t = s.t;
      p.frame = rig.chain->end_effector;
      p.p_base = s.T_true.translation();
      count(est->Update(p));
    }
    tr.Add(s.t, est->Estimate(), PfSummary(*est), s.T_true);
    ctx.progress(spec.label, static_cast<int>(i + 1), static_cast<int>(snaps.size()));
  }
  return tr;
}

}  // namespace flexbench::scenarios::jsk
