// Shared pieces of the particle-filter paper's scenarios on jsk_arm (jsk_*.cc): the model and
// its declared chain, labelled estimators, reference trajectories, per-step traces, the IMU
// pipeline (one Madgwick filter per IMU) and the Fig. 6-style plots.
//
//   model: ../models/jsk_arm.xml
//   declared: ../models/jsk_arm.declared.yaml
//   imus: [imu_link2, imu_link3]          # declared observed frames carrying 6-axis IMUs
//   estimators:                           # label: {estimator: NAME, numeric params...}
//     pf_all: {conjugate_proposal: 1}     # the label is the registry name unless `estimator`
//     pf_all_bootstrap: {estimator: pf_all}
//   trajectory:                           # reference angles, declared joint order, degrees
//     waypoints_deg: [[0, 0, 0, 0], [30, 60, 30, 10]]
//     segment_steps: 30                   # synthetic scenarios: filter steps per segment
//     hold_steps: 10                      #                      steps at rest at each waypoint
//     segment_s: 2.0                      # dynamic scenarios: motion time per segment
//     hold_s: 1.0                         #                    rest at each waypoint
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "estimators/estimator.h"
#include "estimators/imu/madgwick.h"
#include "estimators/pf/pf_estimator.h"
#include "render/plot.h"
#include "scenarios/runner/scenario_kind.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::scenarios::jsk {

struct LabelledEstimator {
  std::string label;
  std::string name;  // registry name
  estimators::Params params;
  std::string where;  // "<file>:<line>: key '<path>'" of the entry, for messages
};

// Whether the estimator is one of the particle filters (pf_*).
inline bool IsParticleFilter(const LabelledEstimator& e) { return e.name.rfind("pf_", 0) == 0; }

// Reads `estimators:` (see above). InputError naming file, line and estimator for unknown names.
std::vector<LabelledEstimator> ParseLabelledEstimators(const ConfigNode& node);

// The truth simulation, the declared chain and the estimators' setup.
struct Rig {
  std::unique_ptr<sim::Simulation> sim;
  sim::DeclaredModel declared;
  std::unique_ptr<sim::DeclaredChain> chain;
  std::vector<std::string> imu_sites;  // IMU site names, setup.imus order
  std::vector<kinematics::FrameId> imu_frames;
  estimators::EstimatorSetup setup;
  // Declared joint k is actuator act_of_q[k] of the simulation.
  std::vector<int> act_of_q;

  int nq() const { return chain->model.nq(); }
  const std::vector<std::string>& joint_names() const { return chain->q_joints; }
  // Declared q -> actuator command vector, and back.
  Eigen::VectorXd ToActuators(const Eigen::VectorXd& q) const;
  // Link-side angles of the declared joints in the truth (qpos - qpos0).
  Eigen::VectorXd LinkAngles() const;
};

// Reads model, declared, imus and (optional) effects; loads everything (InputError on bad
// names). Call in Configure.
Rig LoadRig(const ConfigNode& root, bool with_effects);

// Builds the estimator; InputError messages are prefixed with the entry's file and line.
std::unique_ptr<estimators::Estimator> MakeLabelled(const Rig& rig, const LabelledEstimator& e,
                                                    std::uint64_t seed);

// Reference waypoints (declared order, radians) and the per-segment timing.
struct Trajectory {
  std::vector<Eigen::VectorXd> waypoints;
  int segment_steps = 0;
  int hold_steps = 0;
  double segment_s = 0.0;
  double hold_s = 0.0;
  // Synthetic: the reference at filter step k (hold_steps at the first waypoint, then per
  // segment a linear move of segment_steps and a hold of hold_steps), k < Steps().
  int Steps() const;
  Eigen::VectorXd AtStep(int k) const;
  // Dynamic: the reference at time t (smooth-step between waypoints, holds at each), t <=
  // Duration(); `segment` returns the index of the waypoint being approached or held.
  double Duration() const;
  Eigen::VectorXd AtTime(double t, int* segment = nullptr) const;
};
Trajectory ParseTrajectory(const ConfigNode& node, int nq, bool dynamic);

// Per-step traces of one estimator.
struct Trace {
  std::string label;
  std::vector<double> t;
  std::vector<std::vector<double>> mean, lower, upper;  // [joint][step], radians
  std::vector<double> ee_err_m;                         // |p_est - p_true| of the end effector
  std::vector<double> ee_err_z_m;                       // z component p_est - p_true
  std::vector<double> ess;
  // The end effector's pose per step: the estimate (mean, covariance) and the truth, for the
  // TUM trajectories.
  std::vector<lie::SE3> T_est, T_true;
  std::vector<Mat6> cov;
  void Resize(int nq) { mean.resize(nq), lower.resize(nq), upper.resize(nq); }
  // Appends one step from a belief (and the particle summary's interval when `pf` is set).
  void Add(double time, const estimators::Belief& b, const pf::ParticleSummary* pf,
           const lie::SE3& T_true);
};

// The particle summary of an estimator when it is a particle filter.
const pf::ParticleSummary* PfSummary(const estimators::Estimator& e);

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

// Joint plots in the style of the paper's Fig. 6: per joint the estimate's mean and 95% band
// (thin lines of the same colour), the reference (grey, dashed) and, when given, the truth
// (black); the last panel the end-effector error. Saved as frames/<file>.
void PlotJointBands(const Rig& rig, const std::string& title, const std::vector<Trace>& traces,
                    const std::vector<std::vector<double>>* truth,
                    const std::vector<std::vector<double>>& reference, const std::string& path,
                    const std::string& x_label);

// "traces.csv": t, label, joint, truth, reference, mean, lower, upper (degrees) and "ee.csv".
void WriteTraces(const Rig& rig, const std::vector<Trace>& traces,
                 const std::vector<std::vector<double>>* truth,
                 const std::vector<std::vector<double>>& reference, OutputDir* out);

// ---- Synthetic runs (sec. IV-B): theta_eff = theta_ref + k g(theta_ref) [PF eq. 31] with g the
// rigid nominal model's gravity torque; the virtual sensors read the rigid model at theta_eff.
//
//   deflection_k: 0.033
//   noise: {reference_deg: 0, orientation_deg: 0, position_m: 0}   # optional
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

// Runs an estimator over a synthetic run (Predict, encoders, IMUs, end-effector position).
Trace RunSynthetic(const Rig& rig, const LabelledEstimator& spec, const SyntheticRun& run,
                   std::uint64_t seed, int* rejected);

// ---- Dynamic runs: the truth moved along the trajectory by its servos (sim::Simulation::Step),
// the sensors polled at their rates, one Madgwick filter per IMU, and snapshots at the filter
// rate. Every estimator later sees the same snapshots.
//
//   filter_rate_hz: 10
//   madgwick: {beta: 0.05, init: accel}   # init: accel (yaw 0) or truth (a calibrated yaw)
//   sensors: [...]                        # sim sensors: motor-side encoders and the IMUs
struct DynamicOptions {
  double filter_rate_hz = 10.0;
  double madgwick_beta = 0.05;
  bool madgwick_init_truth = false;
};
DynamicOptions ParseDynamicOptions(const ConfigNode& root);

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
Trace RunOnSnapshots(const Rig& rig, const LabelledEstimator& spec,
                     const std::vector<Snapshot>& snaps, std::uint64_t seed, bool with_position,
                     const RunContext& ctx, int* rejected);

// Fits an axes' limits to its series: x from the first to the last sample, y from 0 (or the
// data's minimum when negative or when !from_zero) to the maximum with head room for the
// legend, ignoring the first `skip` samples of each series (the flat prior's first steps).
void FitAxes(render::Axes* ax, size_t skip = 5, double headroom = 0.4, bool from_zero = true);
// A dashed, thin line for the comparison runs (labels containing "bootstrap" or "_n2048").
void StyleComparison(render::Series* s);

// Fails naming `key` (its line) when present, else the node (for defaults that do not fit).
[[noreturn]] void FailAt(const ConfigNode& node, const std::string& key,
                         const std::string& message);

double Deg(double rad);
// Wrapped difference a - b in (-pi, pi].
double AngleError(double a, double b);

}  // namespace flexbench::scenarios::jsk
