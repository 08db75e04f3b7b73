#include "scenarios/runner/common/simulated_tracker.h"

#include <algorithm>
#include <cmath>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/runner/common/sim_readings.h"
#include "sim/rng.h"

namespace flexbench::scenarios {
namespace {

std::pair<double, double> ParseRange(const ConfigNode& n) {
  const std::vector<double> v = n.AsDoubleList();
  if (v.size() != 2 || !std::isfinite(v[0]) || !std::isfinite(v[1]) || !(v[0] < v[1]) ||
      std::abs(v[0]) > 360.0 || std::abs(v[1]) > 360.0) {
    n.Fail("expected [low, high] in degrees, low < high, within 360");
  }
  return {v[0] * kDeg, v[1] * kDeg};
}

double NonNegative(const ConfigNode& t, const char* key) {
  const double v = t.GetDouble(key);
  if (!(std::isfinite(v) && v >= 0.0)) t.Child(key).Fail("must be >= 0");
  return v;
}

// One row per marker of the settled truth: its position in the tracker frame, with noise.
void AppendMarkerRows(const TrackerTruth& t, const TrackerRowsSetup& s, const Eigen::VectorXd& q,
                      int posture, int set, sim::NoiseStream& noise, identify::DataSet* d,
                      std::vector<double>* truth_errors) {
  const Eigen::Isometry3d T_base_world = s.sim->BodyPose(s.base_body).inverse();
  const lie::SE3 T_tracker_base = s.T_base_tracker.Inverse();
  const int pose = static_cast<int>(d->poses.size());
  d->poses.push_back(d->sets[set] + "/posture_" + std::to_string(posture));
  for (size_t m = 0; m < t.markers.size(); ++m) {
    identify::Observation o;
    o.q = q;
    o.type = identify::ObservationType::kPoint;
    o.frame = s.frame_index;
    o.point = s.marker_points[m];
    const Vec3 p_base = T_base_world * (s.sim->Pose(t.markers[m]) * t.marker_offsets[m]);
    const Vec3 p_true = T_tracker_base * p_base;
    o.p_frame = p_true;
    for (int k = 0; k < 3; ++k) o.p_frame[k] += noise.Normal(t.noise_std_m);
    if (truth_errors) truth_errors->push_back((o.p_frame - p_true).norm());
    o.set = set;
    o.pose = pose;
    o.where = d->poses[pose] + "/" + t.markers[m];
    d->rows.push_back(o);
  }
}

}  // namespace

TrackerTruth ParseTrackerTruth(const ConfigNode& n) {
  TrackerTruth t;
  t.frame = n.GetString("frame");
  t.frame_where = n.Child("frame").WhereKey();
  t.markers_where = n.Child("markers").WhereKey();
  t.postures_where = n.Child("postures_deg").WhereKey();
  t.T_nominal = identify::ParseFramePose(n.Child("T_base_tracker"));
  t.pose_std_m = NonNegative(n, "pose_std_m");
  t.pose_std_rad = NonNegative(n, "pose_std_deg") * kDeg;
  t.noise_std_m = n.GetDouble("noise_std_m");
  if (!(std::isfinite(t.noise_std_m) && t.noise_std_m > 0.0)) {
    n.Child("noise_std_m").Fail("must be > 0 (a standard deviation, m)");
  }
  for (const ConfigNode& m : n.Child("markers").Items()) t.markers.push_back(m.AsString());
  if (t.markers.empty()) n.Child("markers").Fail("name at least one marker");
  const ConfigNode p = n.Child("postures_deg");
  if (!p.IsMap()) p.Fail("expected {default: [low, high], JOINT: [low, high], ...}");
  t.default_range = ParseRange(p.Child("default"));
  for (const std::string& j : p.Keys()) {
    if (j != "default") t.ranges.emplace_back(j, ParseRange(p.Child(j)));
  }
  t.marker_offsets.assign(t.markers.size(), Vec3::Zero());
  if (const auto o = n.Optional("marker_offsets_mm")) {
    if (!o->IsMap()) o->Fail("expected {marker: [x, y, z]} in mm");
    for (const std::string& name : o->Keys()) {
      const ConfigNode v = o->Child(name);
      const auto it = std::find(t.markers.begin(), t.markers.end(), name);
      if (it == t.markers.end()) v.Fail("'" + name + "' is not one of the tracker's markers");
      const std::vector<double> x = v.AsDoubleList();
      if (x.size() != 3) v.Fail("expected [x, y, z] in mm");
      t.marker_offsets[it - t.markers.begin()] = Vec3(x[0], x[1], x[2]) * 1e-3;
    }
  }
  return t;
}

lie::SE3 DrawTrackerPose(const TrackerTruth& t, std::uint64_t seed) {
  sim::NoiseStream rng(seed, "closed_loop/tracker_pose/" + t.frame);
  Vec6 xi;
  for (int k = 0; k < 3; ++k) xi[k] = rng.Normal(t.pose_std_m);
  for (int k = 3; k < 6; ++k) xi[k] = rng.Normal(t.pose_std_rad);
  return t.T_nominal * lie::SE3::Exp(xi);
}

PostureSpace ResolvePostures(const TrackerTruth& t, const sim::Simulation& sim,
                             const sim::DeclaredChain& chain) {
  PostureSpace out;
  out.actuator = ActuatorIndices(sim, chain);
  for (size_t k = 0; k < out.actuator.size(); ++k) {
    if (out.actuator[k] < 0 && !chain.IsCoupled(static_cast<int>(k))) {
      throw InputError(t.postures_where + ": joint '" + chain.q_joints[k] +
                       "' of the declared model is not actuated in the truth");
    }
  }
  out.range.assign(chain.q_joints.size(), t.default_range);
  for (const auto& [joint, r] : t.ranges) {
    const auto it = std::find(chain.q_joints.begin(), chain.q_joints.end(), joint);
    if (it == chain.q_joints.end()) {
      throw InputError(t.postures_where + ": '" + joint +
                       "' is not an actuated joint of the declared model");
    }
    if (chain.IsCoupled(static_cast<int>(it - chain.q_joints.begin()))) {
      throw InputError(t.postures_where + ": '" + joint +
                       "' is coupled in the declared model: it follows its drivers' ranges");
    }
    out.range[it - chain.q_joints.begin()] = r;
  }
  return out;
}

void SimulateTrackerRows(const TrackerTruth& t, const TrackerRowsSetup& s, int postures,
                         std::uint64_t seed, const std::string& stream, const std::string& set,
                         identify::DataSet* d, std::vector<double>* truth_errors) {
  const sim::DeclaredChain& chain = *s.chain;
  const int nq = chain.model.nq();
  const PostureSpace space = ResolvePostures(t, *s.sim, chain);
  sim::NoiseStream u(seed, stream + "/postures"), n(seed, stream + "/readings");
  const int si = identify::LabelIndex(&d->sets, set);
  Eigen::VectorXd cmd = Eigen::VectorXd::Zero(s.sim->num_actuated());
  for (int c = 0; c < postures; ++c) {
    for (int k = 0; k < nq; ++k) {
      if (space.actuator[k] < 0) continue;  // coupled
      const auto [lo, hi] = space.range[k];
      cmd[space.actuator[k]] = lo + (hi - lo) * u.Uniform();
    }
    s.sim->SetCommand(cmd);
    s.sim->Settle();
    // Readings: the encoders (motor side of an elastic gear) with their offsets and noise.
    Eigen::VectorXd q = Eigen::VectorXd::Zero(nq);
    for (int k = 0; k < nq; ++k) {
      if (space.actuator[k] < 0) continue;
      const int jid = mj_name2id(s.sim->model(), mjOBJ_JOINT, chain.q_joints[k].c_str());
      q[k] = s.sim->MotorPosition(jid) - s.sim->JointOffset(jid) + n.Normal(s.encoder_noise_rad);
    }
    chain.ApplyCouplings(&q);
    AppendMarkerRows(t, s, q, c, si, n, d, truth_errors);
  }
}

}  // namespace flexbench::scenarios
