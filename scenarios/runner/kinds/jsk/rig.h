// The truth and the declared model of the particle-filter paper's scenarios on jsk_arm (the jsk
// kinds): the MuJoCo simulation, the declared chain, the IMU frames and the estimators' setup.
//
//   model: ../models/jsk_arm.xml
//   declared: ../models/jsk_arm.declared.yaml
//   imus: [imu_link2, imu_link3]          # declared observed frames carrying 6-axis IMUs
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "estimators/estimator.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/truth_rig.h"
#include "scenarios/runner/scenario_kind.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/simulation.h"

namespace flexbench::scenarios::jsk {

// The truth rig with the IMUs on the estimators' set-up.
struct Rig : TruthRig {
  std::vector<std::string> imu_sites;  // IMU site names, setup.imus order
  std::vector<kinematics::FrameId> imu_frames;
  // Declared joint k is actuator act_of_q[k] of the simulation.
  std::vector<int> act_of_q;

  int nq() const { return chain->model.nq(); }
  const std::vector<std::string>& joint_names() const { return chain->q_joints; }
  // Declared q -> actuator command vector, and back.
  Eigen::VectorXd ToActuators(const Eigen::VectorXd& q) const;
  // Link-side angles of the declared joints in the truth (qpos - qpos0).
  Eigen::VectorXd LinkAngles() const;
};

// Reads model and declared (ReadModelAndDeclared), imus and (optional) effects; loads everything
// (InputError on bad names). Call in Configure.
Rig LoadRig(const ConfigNode& root, bool with_effects);

inline double Deg(double rad) { return rad * 180.0 / M_PI; }
// Wrapped difference a - b in [-pi, pi] (std::remainder: a difference of exactly -pi stays -pi).
inline double AngleError(double a, double b) { return std::remainder(a - b, 2.0 * M_PI); }

}  // namespace flexbench::scenarios::jsk
