#include "scenarios/runner/kinds/jsk/synthetic.h"

#include <algorithm>
#include <cmath>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"
#include "scenarios/runner/common/log_export.h"
#include "sim/rng.h"

namespace flexbench::scenarios::jsk {

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

sim::RecordedLog SyntheticLog(const Rig& rig, const SyntheticRun& run,
                              const SyntheticOptions& options) {
  sim::RecordedLog log = LogOfChain(rig.declared, *rig.chain);
  log.joint_std = options.reference_std;
  log.sensed_frames = rig.imu_sites;
  log.sensed_frames.push_back(rig.declared.end_effector);
  const int ee = static_cast<int>(log.sensed_frames.size()) - 1;
  // The positions' covariance is std^2: the floor MakeSyntheticRun puts on it as a std.
  const double position_std = std::max(options.position_std, 1e-6);
  for (int s = 0; s < run.steps(); ++s) {
    AddStepToLog(run.joints[s], run.T_true[s], &log);
    for (size_t k = 0; k < run.orientations[s].size(); ++k) {
      log.orientations.push_back(
          {run.orientations[s][k].t, static_cast<int>(k), run.orientations[s][k].q_base_frame});
    }
    log.positions.push_back({run.positions[s].t, ee, run.positions[s].p_base, position_std});
  }
  return log;
}

Trace RunSynthetic(const Rig& rig, const EstimatorSpec& spec, const SyntheticRun& run,
                   std::uint64_t seed, int* rejected) {
  TracedRun r(rig, spec, seed);
  for (int s = 0; s < run.steps(); ++s) {
    r.est->Predict(s);
    r.Count(r.est->Update(run.joints[s]));
    for (const auto& o : run.orientations[s]) r.Count(r.est->Update(o));
    r.Count(r.est->Update(run.positions[s]));
    r.Record(s, run.T_true[s]);
  }
  *rejected = r.rejected;
  return std::move(r.trace);
}

}  // namespace flexbench::scenarios::jsk
