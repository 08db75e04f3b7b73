// What the particle-filter paper's scenarios on jsk_arm (the jsk kinds) share: the set-up every
// one reads (the rig, the trajectory, the burn-in and a labelled `estimators:` block) and the
// collect and estimate steps of their runs. The synthetic kinds (sec. IV-B, V-A) derive from
// SyntheticKind, the dynamic ones (sec. IV-C..E) from DynamicKind.
//
//   model: ../models/jsk_arm.xml            # rig.h
//   declared: ../models/jsk_arm.declared.yaml
//   imus: [imu_link2, imu_link3]
//   estimators:                           # label: {estimator: NAME, numeric params...}
//     pf_all: {conjugate_proposal: 1}     # the label is the registry name unless `estimator`
//     pf_all_bootstrap: {estimator: pf_all}
//   trajectory: {...}                     # trajectory.h
//   burn_in_steps: 5                      # synthetic: steps left out of the metrics
//   burn_in_s: 1.0                        # dynamic: seconds left out of the metrics
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/stage_timer.h"
#include "scenarios/runner/kinds/jsk/dynamic.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/jsk/synthetic.h"
#include "scenarios/runner/kinds/jsk/trace.h"
#include "scenarios/runner/kinds/jsk/trajectory.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios::jsk {

// Fails naming `key` (its line) when present, else the node (for defaults that do not fit).
[[noreturn]] void FailAt(const ConfigNode& node, const std::string& key,
                         const std::string& message);

// Reads the labelled `estimators:` block and builds every estimator once: bad parameters fail
// before any work.
std::vector<EstimatorSpec> ParseAndCheckEstimators(const ConfigNode& root, const Rig& rig);

// Warns when the joint readings leave the conditions an augmented declared model was fitted
// under (FittedRangeCheck); says nothing for a declared model without fitted_under.
void CheckFittedRange(const Rig& rig, const std::vector<estimators::JointReading>& joints,
                      const RunContext& ctx);

// Synthetic runs: the rigid model read at the deflected angles of [PF eq. 31].
class SyntheticKind : public ScenarioKind {
 protected:
  // Reads the rig (no truth effects), the deflection options, the trajectory in steps and
  // burn_in_steps.
  void ConfigureSynthetic(const ConfigNode& root);

  Rig rig_;
  SyntheticOptions options_;
  Trajectory trajectory_;
  int burn_in_ = 5;
};

// Dynamic runs: the truth stepped along the trajectory, the estimators on its snapshots.
class DynamicKind : public ScenarioKind {
 public:
  // The rig (with its truth effects), the trajectory in seconds, the dynamic options, burn_in_s,
  // the kind's own keys (ConfigureKind), the sensors and the estimators.
  void Configure(const ConfigNode& root) final;
  // Simulate writes the snapshots' readings as a recorded log when the run asks for one.
  bool ExportsLog() const final { return true; }

 protected:
  virtual void ConfigureKind(const ConfigNode& /*root*/) {}

  // Collect: the truth simulated with the run's seed.
  std::vector<Snapshot> Simulate(const RunContext& ctx);
  // Estimate: every estimator over the same snapshots (each stretch timed under its label when
  // `timer` is set); `rejected` receives each one's rejected readings.
  std::vector<Trace> Estimate(const std::vector<Snapshot>& snaps, const RunContext& ctx,
                              std::vector<int>* rejected, StageTimer* timer = nullptr) const;
  // The commanded angles per joint, [joint][snapshot].
  std::vector<std::vector<double>> Reference(const std::vector<Snapshot>& snaps) const;
  // Report: Fig. 6-style joint plots of every trace, frames/<prefix><label>.png.
  void PlotEachTrace(const std::string& prefix, const std::string& title,
                     const std::vector<Trace>& traces,
                     const std::vector<std::vector<double>>* truth,
                     const std::vector<std::vector<double>>& reference,
                     const RunContext& ctx) const;
  // The scenario's metrics every dynamic kind writes.
  void WriteRunMetrics(const std::vector<Snapshot>& snaps, const RunContext& ctx) const;

  Rig rig_;
  Trajectory trajectory_;
  DynamicOptions options_;
  double burn_in_s_ = 1.0;
  std::unique_ptr<ConfigNode> sensors_node_;
  std::vector<EstimatorSpec> estimators_;
};

}  // namespace flexbench::scenarios::jsk
