// Synthetic runs (sec. IV-B): theta_eff = theta_ref + k g(theta_ref) [PF eq. 31] with g the
// rigid nominal model's gravity torque; the virtual sensors read the rigid model at theta_eff.
//
//   deflection_k: 0.033
//   noise: {reference_deg: 0, orientation_deg: 0, position_m: 0}   # optional
#pragma once

#include <cstdint>
#include <vector>

#include "estimators/measurement.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/jsk/trace.h"
#include "scenarios/runner/kinds/jsk/trajectory.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios::jsk {

struct SyntheticOptions {
  double k = 0.033;
  double reference_std = 0.0;    // rad
  double orientation_std = 0.0;  // rad, a right perturbation of the true orientation
  double position_std = 0.0;     // m
};
SyntheticOptions ParseSyntheticOptions(const ConfigNode& root);

struct SyntheticRun {
  std::vector<std::vector<double>> truth, reference;  // [joint][step]
  std::vector<estimators::JointReading> joints;
  std::vector<std::vector<estimators::OrientationReading>> orientations;
  std::vector<estimators::PositionReading> positions;
  std::vector<lie::SE3> T_true;  // the end effector in the base frame
  double deflection_max = 0.0;   // rad
  int steps() const { return static_cast<int>(joints.size()); }
};
SyntheticRun MakeSyntheticRun(const Rig& rig, const Trajectory& trajectory,
                              const SyntheticOptions& options, std::uint64_t seed);

// The run's readings as a recorded log (--export-log): the reference encoders with their
// noise, each IMU frame's orientation readings (orientations.csv) and the end effector's
// positions (positions.csv), the truth.
sim::RecordedLog SyntheticLog(const Rig& rig, const SyntheticRun& run,
                              const SyntheticOptions& options);

// Runs an estimator over a synthetic run (Predict, encoders, IMUs, end-effector position).
Trace RunSynthetic(const Rig& rig, const EstimatorSpec& spec, const SyntheticRun& run,
                   std::uint64_t seed, int* rejected);

}  // namespace flexbench::scenarios::jsk
