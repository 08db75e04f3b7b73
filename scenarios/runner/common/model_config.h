// The `model:` and `declared:` keys every scenario with a truth and a declared model has.
//
//   model: ../models/rover_arm.xml                  # MJCF or URDF, relative to the scenario
//   declared: ../models/rover_arm.declared.yaml     # a declared-model file, or inline:
//   declared: {actuated_joints: [...], end_effector: ee, sources: [...]}   (model: as above)
#pragma once
#include <string>
#include <vector>

#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"
#include "sim/declared_model.h"

namespace flexbench::scenarios {

// Reads both keys; `model_path` receives the resolved model path. An inline declared block
// describes the scenario's model. Throws InputError naming the file, line and key.
sim::DeclaredModel ReadModelAndDeclared(const ConfigNode& root, std::string* model_path);

// A warning about the run's results: one line on stderr (also under --quiet) and an entry of
// summary.json's top-level `warnings` (a list of strings).
void Warn(RunContext& ctx, const std::string& line);

// Whether a run stays inside the joint ranges an augmented declared model was fitted under
// (sim::FittedUnder). Its effects were fitted and its sources sized on those postures only: an
// error that grows with the posture (a bending link, a compliant plate under another load) may
// be one the rows never showed, and a source they shrank is then too small. Observe every joint
// vector the estimators are given; Report warns once (Warn) naming each joint outside, and
// says nothing for a model without fitted_under or a run inside.
class FittedRangeCheck {
 public:
  FittedRangeCheck() = default;
  // q_joints: the joints of the vectors observed, in their order (sim::DeclaredChain::q_joints,
  // a recorded log's joints.csv columns).
  FittedRangeCheck(const sim::DeclaredModel& d, const std::vector<std::string>& q_joints);
  void Observe(const double* q, int n);
  void Report(RunContext& ctx) const;

 private:
  struct Joint {
    sim::FittedUnder::JointRange fitted;
    int q_index = -1;
    double min = INFINITY, max = -INFINITY;  // observed, rad or m
  };
  std::vector<Joint> joints_;
  std::string file_;
};

}  // namespace flexbench::scenarios
