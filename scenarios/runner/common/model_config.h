// The `model:` and `declared:` keys every scenario with a truth and a declared model has.
//
//   model: ../models/rover_arm.xml                  # MJCF or URDF, relative to the scenario
//   declared: ../models/rover_arm.declared.yaml     # a declared-model file, or inline:
//   declared: {actuated_joints: [...], end_effector: ee, sources: [...]}   (model: as above)
#pragma once
#include <mujoco/mujoco.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/posture_load.h"

namespace flexbench::scenarios {

// Reads both keys; `model_path` receives the resolved model path. An inline declared block
// describes the scenario's model. Throws InputError naming the file, line and key.
sim::DeclaredModel ReadModelAndDeclared(const ConfigNode& root, std::string* model_path);

// A warning about the run's results: one line on stderr (also under --quiet) and an entry of
// summary.json's top-level `warnings` (a list of strings).
void Warn(const RunContext& ctx, const std::string& line);

// Whether a run stays inside the conditions an augmented declared model was fitted under
// (sim::FittedUnder): the joint ranges, the gravity torque each joint held and the box the end
// effector reached. Its effects were fitted and its sources sized on those postures only: an
// error that grows with the posture or the load (a bending link, a compliant plate under another
// load) may be one the rows never showed, and a source they shrank is then too small. Observe
// every joint vector the estimators are given; Report warns once (Warn) naming what left its
// range, and says nothing for a model without fitted_under or a run inside.
class FittedRangeCheck {
 public:
  FittedRangeCheck() = default;
  // q_joints: the joints of the vectors observed, in their order (sim::DeclaredChain::q_joints,
  // a recorded log's joints.csv columns). `nominal` and `chain` (built from it, for d): the
  // torques and the box are checked with them (not with nullptr); both must outlive the check.
  FittedRangeCheck(const sim::DeclaredModel& d, const std::vector<std::string>& q_joints,
                   const mjModel* nominal, const sim::DeclaredChain* chain);
  void Observe(const double* q, int n);
  void Report(const RunContext& ctx) const;

 private:
  struct Joint {
    sim::FittedUnder::JointRange fitted;
    int q_index = -1;
    double min = INFINITY, max = -INFINITY;  // observed, rad or m
  };
  struct Torque {
    sim::FittedUnder::TorqueRange fitted;
    int chain_index = -1;
    double min = INFINITY, max = -INFINITY;  // observed, N m
  };
  std::vector<Joint> joints_;
  std::vector<Torque> torques_;
  sim::FittedUnder fitted_;
  Vec3 box_min_ = Vec3::Constant(INFINITY), box_max_ = Vec3::Constant(-INFINITY);
  std::vector<int> chain_of_observed_;  // per observed column, its chain variable (-1: none)
  const sim::DeclaredChain* chain_ = nullptr;
  std::unique_ptr<sim::PostureLoadEvaluator> load_;
  Eigen::VectorXd q_chain_;
  sim::PostureLoad at_;
  std::string file_;
};

}  // namespace flexbench::scenarios
