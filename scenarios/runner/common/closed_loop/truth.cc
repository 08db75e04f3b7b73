#include "scenarios/runner/common/closed_loop/truth.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/stats/chi_square.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/runner/common/sim_readings.h"

namespace flexbench::scenarios {
namespace {

using identify::DataSet;

// The truth's end effector and the command vector that moves it.
struct SocketTruth {
  sim::FrameRef ee;
  std::vector<int> act_index;  // per declared joint: its index among the truth's actuators
  Eigen::VectorXd cmd;
  kinematics::PpoeData pd;  // the declared chain's scratch
};

std::vector<int> ActuatorIndex(const ClosedLoopSetup& cl) {
  const std::vector<int> act = ActuatorIndices(*cl.truth.sim, *cl.chain);
  for (size_t k = 0; k < act.size(); ++k) {
    if (act[k] < 0) throw InputError(cl.chain->q_joints[k] + " is not actuated in truth");
  }
  return act;
}

// The truth settled at q: its end effector's position.
Vec3 TruePoint(ClosedLoopSetup& cl, const Eigen::VectorXd& q, SocketTruth* t) {
  for (int k = 0; k < q.size(); ++k) t->cmd[t->act_index[k]] = q[k];
  cl.truth.sim->SetCommand(t->cmd);
  cl.truth.sim->Settle();
  return Vec3(cl.truth.sim->Pose(t->ee).translation());
}

// Middle of joint k's range (0 when unlimited): where random starting postures centre.
double MidRange(const ClosedLoopSetup& cl, int k) {
  const int j = mj_name2id(cl.mj.get(), mjOBJ_JOINT, cl.chain->q_joints[k].c_str());
  if (cl.mj->jnt_limited[j]) return 0.5 * (cl.mj->jnt_range[2 * j] + cl.mj->jnt_range[2 * j + 1]);
  return 0.0;
}

bool InLimits(const ClosedLoopSetup& cl, const Eigen::VectorXd& q) {
  for (int k = 0; k < q.size(); ++k) {
    const int j = mj_name2id(cl.mj.get(), mjOBJ_JOINT, cl.chain->q_joints[k].c_str());
    if (cl.mj->jnt_limited[j] &&
        (q[k] < cl.mj->jnt_range[2 * j] || q[k] > cl.mj->jnt_range[2 * j + 1])) {
      return false;
    }
  }
  return true;
}

// Up to 5 random starts, each a damped Newton on the truth with the declared position
// Jacobian (close enough to converge); the null space keeps the random start's posture.
// True when the truth rests at the target within joint limits.
bool ReachSocket(ClosedLoopSetup& cl, const Vec3& target, std::mt19937_64& rng,
                 std::uniform_real_distribution<double>& u, SocketTruth* t) {
  const kinematics::PpoeModel& model = cl.chain->model;
  const int nq = model.nq();
  Eigen::VectorXd q(nq);
  bool ok = false;
  for (int attempt = 0; attempt < 5 && !ok; ++attempt) {
    for (int k = 0; k < nq; ++k) q[k] = 1.2 * u(rng) + MidRange(cl, k);
    for (int it = 0; it < 40; ++it) {
      const Vec3 err = target - TruePoint(cl, q, t);
      if (err.norm() < 1e-7) {
        ok = true;
        break;
      }
      kinematics::ForwardKinematics(model, t->pd, q);
      Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, nq);
      kinematics::ComputeFrameJacobian(model, t->pd, cl.chain->end_effector, J);
      const Eigen::Matrix<double, 3, Eigen::Dynamic> Jp =
          t->pd.T_base_frame[cl.chain->end_effector].rotation() * J.topRows<3>();
      const Eigen::MatrixXd JJt = Jp * Jp.transpose() + 1e-6 * Eigen::Matrix3d::Identity();
      Eigen::VectorXd dq = Jp.transpose() * JJt.ldlt().solve(err);
      const double n = dq.norm();
      if (n > 0.3) dq *= 0.3 / n;
      q += dq;
    }
    if (ok && !InLimits(cl, q)) ok = false;
  }
  return ok;
}

// The encoders' reading of the settled truth, with their noise.
identify::Observation EncoderRow(ClosedLoopSetup& cl, std::mt19937_64& rng,
                                 std::normal_distribution<double>& noise) {
  const int nq = cl.chain->model.nq();
  identify::Observation o;
  o.q.resize(nq);
  for (int k = 0; k < nq; ++k) {
    const int jid = mj_name2id(cl.truth.sim->model(), mjOBJ_JOINT, cl.chain->q_joints[k].c_str());
    o.q[k] = cl.truth.sim->MotorPosition(jid) - cl.truth.sim->JointOffset(jid) +
             cl.truth.encoder_noise_rad * noise(rng);
  }
  return o;
}

// The truth's effects against the found ones, where the data cannot single out every cause (a
// joint offset and the next axis's tilt about the same line; a play whose load never changes
// sign and an offset): `effects_named_up_to_equivalence`, each found entry (an equivalence set
// "a | b" counts by its members) holds exactly one truth effect and each truth effect is in
// one entry; `load_effects_named`, every load-driven truth effect is found by its own name,
// alone.
void ScoreNamesUpToEquivalence(const ClosedLoopSetup& cl, const std::vector<std::string>& found,
                               Json* m) {
  const auto members = [](const std::string& name) {
    std::vector<std::string> out;
    for (size_t start = 0;;) {
      const size_t bar = name.find(" | ", start);
      out.push_back(name.substr(start, bar == std::string::npos ? bar : bar - start));
      if (bar == std::string::npos) return out;
      start = bar + 3;
    }
  };
  std::vector<int> hits(cl.truth_names.size(), 0);
  bool one_each = true;
  for (const std::string& f : found) {
    int in_entry = 0;
    for (const std::string& member : members(f)) {
      const auto it = std::find(cl.truth_names.begin(), cl.truth_names.end(), member);
      if (it != cl.truth_names.end()) ++in_entry, ++hits[it - cl.truth_names.begin()];
    }
    one_each &= in_entry == 1;
  }
  for (int h : hits) one_each &= h == 1;
  (*m)["effects_named_up_to_equivalence"] = one_each;
  bool load_named = true;
  for (const std::string& t : cl.truth_names) {
    const int c = cl.em->FindCandidate(t);
    if (c < 0 || !kinematics::Row(cl.em->candidates()[c].type).load_driven) continue;
    load_named &= std::find(found.begin(), found.end(), t) != found.end();
  }
  (*m)["load_effects_named"] = load_named;
}

}  // namespace

// The `truth` block: effects, the expected names, and where simulated data come from (sockets
// in a workspace, or a tracker).
void ReadTruth(ClosedLoopSetup& cl, const ConfigNode& t) {
  cl.truth.effects = sim::ParseEffects(t.Child("effects"));
  for (const ConfigNode& n : t.Child("expected").Items()) cl.truth_names.push_back(n.AsString());
  cl.truth.encoder_noise_rad = t.GetDouble("encoder_noise_deg", 0.0) * kDeg;
  cl.truth.present = true;
  if (const auto tr = t.Optional("tracker")) {
    cl.truth.tracker = ParseTrackerTruth(*tr);
    return;
  }
  cl.truth.socket_distance_m = t.GetDouble("socket_distance_m", 0.05);
  const auto ws = t.Child("workspace");
  for (const auto& [key, out] :
       {std::pair{"center", &cl.truth.ws_center}, std::pair{"half_extent", &cl.truth.ws_half}}) {
    const std::vector<double> v = ws.Child(key).AsDoubleList();
    if (v.size() != 3) ws.Child(key).Fail("expected [x, y, z] in metres");
    *out = Vec3(v[0], v[1], v[2]);
  }
}

// The tracker's frame is a declared measurement frame and its markers are measured points.
void CheckTrackerTruth(ClosedLoopSetup& cl) {
  const auto f = std::find_if(cl.frames.begin(), cl.frames.end(),
                              [&](const auto& fr) { return fr.name == cl.truth.tracker->frame; });
  if (f == cl.frames.end()) {
    throw InputError(cl.truth.tracker->frame_where + ": '" + cl.truth.tracker->frame +
                     "' is not declared in the scenario's 'frames'");
  }
  cl.truth.tracker_frame = static_cast<int>(f - cl.frames.begin());
  for (const std::string& m : cl.truth.tracker->markers) {
    const auto it = std::find(cl.points.begin(), cl.points.end(), m);
    if (it == cl.points.end()) {
      throw InputError(
          cl.truth.tracker->markers_where + ": '" + m +
          "' is neither the end effector nor one of 'markers' (--marker on the command line)");
    }
    cl.truth.tracker_points.push_back(static_cast<int>(it - cl.points.begin()));
    cl.truth.sim->Frame(m);  // the truth has it (InputError naming the model otherwise)
  }
  ResolvePostures(*cl.truth.tracker, *cl.truth.sim, *cl.chain);  // before any work
}

// Tracker rows from the truth settled at random postures; the tracker's true pose is drawn
// once per run (the same for calibration and validation).
void SimulateTracker(ClosedLoopSetup& cl, const Source& s, RunContext& ctx, const std::string& what,
                     DataSet* d) {
  cl.truth.T_true_tracker = DrawTrackerPose(*cl.truth.tracker, ctx.seed);
  TrackerRowsSetup setup;
  setup.sim = cl.truth.sim.get();
  setup.chain = cl.chain.get();
  setup.base_body = cl.declared.base;
  setup.marker_points = cl.truth.tracker_points;
  setup.frame_index = cl.truth.tracker_frame;
  setup.T_base_tracker = cl.truth.T_true_tracker;
  setup.encoder_noise_rad = cl.truth.encoder_noise_rad;
  std::vector<double> truth_errors;
  const size_t first = d->rows.size();
  SimulateTrackerRows(*cl.truth.tracker, setup, s.postures, ctx.seed,
                      "closed_loop/" + what + "/" + std::to_string(s.seed), what, d, &truth_errors);
  for (size_t r = first; r < d->rows.size(); ++r) {
    cl.truth.row_err[d->rows[r].where] = truth_errors[r - first];
  }
}

// The fitted tracker pose against the truth's: the error of xi (T = T_ref Exp(xi)) under the
// fit's reported covariance, its 99% bound (chi-square, 6 dof) and the largest per-axis z.
void ScoreTrackerPose(const ClosedLoopSetup& cl, RunContext& ctx, const DataSet& cal,
                      const identify::IdentifyResult& res) {
  const lie::SE3& T_ref = cal.frames[cl.truth.tracker_frame].T_ref;
  const Vec6 e = (T_ref.Inverse() * res.after.T_base_frames[cl.truth.tracker_frame]).Log() -
                 (T_ref.Inverse() * cl.truth.T_true_tracker).Log();
  const Mat6& C = res.frame_cov[cl.truth.tracker_frame];
  double max_z = 0.0;
  for (int k = 0; k < 6; ++k) max_z = std::max(max_z, std::abs(e[k]) / std::sqrt(C(k, k)));
  const Eigen::Quaterniond q(cl.truth.T_true_tracker.rotation());
  const Vec3& t = cl.truth.T_true_tracker.translation();
  const lie::SE3 dT =
      cl.truth.T_true_tracker.Inverse() * res.after.T_base_frames[cl.truth.tracker_frame];
  (*ctx.summary)["metrics"]["tracker_pose"] = {
      {"frame", cl.truth.tracker->frame},
      {"T_base_frame_true", {t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z()}},
      {"err_m", dT.translation().norm()},
      {"err_deg", Eigen::AngleAxisd(dT.rotation()).angle() / kDeg},
      {"nees", e.dot(C.ldlt().solve(e))},
      {"nees_bound_99", stats::ChiSquareQuantile(0.99, 6.0)},
      {"max_abs_z", max_z}};
}

// The truth guides its end effector into two sockets per placement, from random starting
// configurations (a user hand-guiding the ball); the encoders are read there.
void SimulateSockets(ClosedLoopSetup& cl, const Source& s, RunContext& ctx, const std::string& what,
                     DataSet* d) {
  std::mt19937_64 rng(ctx.seed * 1000003ULL + static_cast<std::uint64_t>(s.seed));
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  SocketTruth truth{cl.truth.sim->Frame(cl.declared.end_effector), ActuatorIndex(cl),
                    Eigen::VectorXd::Zero(cl.truth.sim->num_actuated()),
                    kinematics::PpoeData(cl.chain->model)};
  int failed = 0;
  for (int p = 0; p < s.sim_placements; ++p) {
    const std::string set = what + "_" + std::to_string(p);
    const int si = identify::LabelIndex(&d->sets, set);
    Vec3 c0;
    for (int k = 0; k < 3; ++k) c0[k] = cl.truth.ws_center[k] + cl.truth.ws_half[k] * u(rng);
    const double yaw = M_PI * u(rng);
    const Vec3 dir(std::cos(yaw), std::sin(yaw), 0.0);
    int g[2] = {-1, -1};  // a socket becomes a group with its first reached configuration
    for (int h = 0; h < 2; ++h) {
      const Vec3 target = c0 + (h - 0.5) * cl.truth.socket_distance_m * dir;
      for (int r = 0; r < s.per_socket; ++r) {
        if (!ReachSocket(cl, target, rng, u, &truth)) {
          ++failed;
          continue;
        }
        identify::Observation o = EncoderRow(cl, rng, noise);
        o.type = identify::ObservationType::kGroup;
        if (g[h] < 0) {
          g[h] = identify::LabelIndex(&d->groups, set + "/socket_" + std::to_string(h));
        }
        o.group = g[h];
        o.set = si;
        o.where = set + "/socket_" + std::to_string(h) + "/" + std::to_string(r);
        d->rows.push_back(o);
      }
    }
    // A socket no configuration reached is no group, and has no distance.
    if (g[0] >= 0 && g[1] >= 0) {
      d->distances.push_back({g[0], g[1], cl.truth.socket_distance_m});
    }
  }
  if (failed > 0) {
    ctx.log(what + ": " + std::to_string(failed) +
            " configurations skipped (the truth could not reach the socket within joint "
            "limits)");
  }
  (*ctx.summary)["metrics"][what + "_skipped_configurations"] = failed;
}

void ScoreNames(const ClosedLoopSetup& cl, const identify::IdentifyResult& res, Json* m) {
  std::vector<std::string> found;
  for (const auto& e : res.effects) found.push_back(e.name);
  if (cl.truth.present || !cl.truth_names.empty()) {
    (*m)["truth_effects"] = cl.truth_names;
    std::set<std::string> a(found.begin(), found.end()),
        b(cl.truth_names.begin(), cl.truth_names.end());
    (*m)["effect_found_correct"] = a == b;
    if (cl.truth.tracker || !cl.truth.present) ScoreNamesUpToEquivalence(cl, found, m);
  }
  (*m)["effects_found"] = found;
}

// Simulated tracker rows: the truth's own error per row (its marker against the measured
// point: the tracker's noise), weighted as the other errors. nullopt when a row has none.
std::optional<std::vector<double>> TruthRowErrors(const ClosedLoopSetup& cl, const DataSet& d) {
  std::vector<double> out(d.rows.size(), 0.0);
  for (size_t r = 0; r < d.rows.size(); ++r) {
    const auto it = cl.truth.row_err.find(d.rows[r].where);
    if (it == cl.truth.row_err.end()) return std::nullopt;
    out[r] = it->second;
  }
  return out;
}

}  // namespace flexbench::scenarios
