// Dynamic runs: the truth moved along the trajectory by its servos (sim::Simulation::Step), the
// sensors polled at their rates, one Madgwick filter per IMU, and snapshots at the filter rate.
// Every estimator later sees the same snapshots.
//
//   filter_rate_hz: 10
//   madgwick: {beta: 0.05, init: accel}   # init: accel (yaw 0) or truth (a calibrated yaw)
//   sensors: [...]                        # sim sensors: motor-side encoders and the IMUs
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "estimators/imu/madgwick.h"
#include "estimators/measurement.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/jsk/trace.h"
#include "scenarios/runner/kinds/jsk/trajectory.h"
#include "sim/sensors/sensor.h"

namespace flexbench::scenarios::jsk {

struct DynamicOptions {
  double filter_rate_hz = 10.0;
  double madgwick_beta = 0.05;
  bool madgwick_init_truth = false;
};
DynamicOptions ParseDynamicOptions(const ConfigNode& root);

// One Madgwick filter per IMU site, fed with the simulation's IMU readings.
class ImuPipeline {
 public:
  ImuPipeline(const std::vector<std::string>& sites, double beta);
  // init_truth: start from the true orientation (a calibrated yaw); else from the first
  // accelerometer reading (yaw 0 about the vertical).
  void Feed(const sim::ImuReading& r, const Rig& rig, bool init_truth);
  bool Ready() const;
  const Quat& Orientation(int k) const { return filters_[k].orientation(); }

 private:
  std::vector<std::string> sites_;
  std::vector<imu::Madgwick> filters_;
  std::vector<double> last_t_;
  std::vector<bool> started_;
};

struct Snapshot {
  double t = 0.0;
  int segment = 0;                                   // waypoint being approached or held
  Eigen::VectorXd reference;                         // commanded angles (declared order)
  Eigen::VectorXd link;                              // true link-side angles (declared order)
  estimators::JointReading joints;                   // latest encoder readings
  std::vector<estimators::OrientationReading> imus;  // Madgwick orientations
  lie::SE3 T_true;                                   // the end effector (declared) in the world
  std::vector<Quat> imu_true;                        // true IMU orientations (for diagnostics)
};

// Settles the truth at the first waypoint, then steps through the trajectory. The sensor list
// must give an encoder for every declared joint and every IMU (InputError otherwise).
std::vector<Snapshot> SimulateDynamic(Rig& rig, const Trajectory& trajectory,
                                      sim::SensorSuite& sensors, const DynamicOptions& options,
                                      const RunContext& ctx);

// Runs an estimator over snapshots; `with_position` adds the end effector's position reading.
Trace RunOnSnapshots(const Rig& rig, const EstimatorSpec& spec, const std::vector<Snapshot>& snaps,
                     std::uint64_t seed, bool with_position, const RunContext& ctx, int* rejected);

}  // namespace flexbench::scenarios::jsk
