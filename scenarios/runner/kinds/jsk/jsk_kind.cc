#include "scenarios/runner/kinds/jsk/jsk_kind.h"

#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/kinds/jsk/plots.h"

namespace flexbench::scenarios::jsk {

void FailAt(const ConfigNode& node, const std::string& key, const std::string& message) {
  if (const auto child = node.Optional(key)) child->Fail(message);
  node.Fail("'" + key + "' (default) " + message);
}

std::vector<EstimatorSpec> ParseAndCheckEstimators(const ConfigNode& root, const Rig& rig) {
  std::vector<EstimatorSpec> specs =
      ParseEstimators(root.Child("estimators"), EstimatorLabels::kAllowed);
  for (const EstimatorSpec& e : specs) rig.MakeEstimator(e);
  return specs;
}

void CheckFittedRange(const Rig& rig, const std::vector<estimators::JointReading>& joints,
                      const RunContext& ctx) {
  if (rig.declared.fitted_under.empty()) return;
  FittedRangeCheck range(rig.declared, rig.chain->q_joints, rig.sim->nominal_model(),
                         rig.chain.get());
  for (const estimators::JointReading& j : joints) {
    range.Observe(j.q.data(), static_cast<int>(j.q.size()));
  }
  range.Report(ctx);
}

void SyntheticKind::ConfigureSynthetic(const ConfigNode& root) {
  rig_ = LoadRig(root, /*with_effects=*/false);
  options_ = ParseSyntheticOptions(root);
  trajectory_ = ParseTrajectory(root.Child("trajectory"), rig_.nq(), /*dynamic=*/false);
  burn_in_ = root.GetInt("burn_in_steps", 5);
  if (burn_in_ < 0 || burn_in_ >= trajectory_.Steps()) {
    FailAt(root, "burn_in_steps", "must be in [0, number of steps)");
  }
}

void DynamicKind::Configure(const ConfigNode& root) {
  rig_ = LoadRig(root, /*with_effects=*/true);
  trajectory_ = ParseTrajectory(root.Child("trajectory"), rig_.nq(), /*dynamic=*/true);
  options_ = ParseDynamicOptions(root, rig_);
  burn_in_s_ = root.GetDouble("burn_in_s", 1.0);
  if (!(burn_in_s_ >= 0.0 && burn_in_s_ < trajectory_.Duration())) {
    FailAt(root, "burn_in_s", "must be in [0, trajectory duration)");
  }
  ConfigureKind(root);
  sensors_node_ = std::make_unique<ConfigNode>(root.Child("sensors"));
  sim::SensorSuite::Parse(*sensors_node_, *rig_.sim, 0);
  estimators_ = ParseAndCheckEstimators(root, rig_);
}

std::vector<Snapshot> DynamicKind::Simulate(const RunContext& ctx) {
  sim::SensorSuite sensors = sim::SensorSuite::Parse(*sensors_node_, *rig_.sim, ctx.seed);
  std::vector<Snapshot> snaps = SimulateDynamic(rig_, trajectory_, sensors, options_, ctx);
  std::vector<estimators::JointReading> joints;
  for (const Snapshot& s : snaps) joints.push_back(s.joints);
  CheckFittedRange(rig_, joints, ctx);
  if (!ctx.export_log.empty()) ExportLog(rig_, options_, snaps, ctx.export_log);
  return snaps;
}

std::vector<Trace> DynamicKind::Estimate(const std::vector<Snapshot>& snaps, const RunContext& ctx,
                                         std::vector<int>* rejected, StageTimer* timer) const {
  std::vector<Trace> traces;
  rejected->assign(estimators_.size(), 0);
  for (size_t e = 0; e < estimators_.size(); ++e) {
    std::optional<StageTimer::Scope> t;
    if (timer) t.emplace(timer, estimators_[e].label);
    traces.push_back(RunOnSnapshots(rig_, estimators_[e], snaps, ctx.seed,
                                    /*with_position=*/false, ctx, &(*rejected)[e]));
  }
  return traces;
}

std::vector<std::vector<double>> DynamicKind::Reference(const std::vector<Snapshot>& snaps) const {
  std::vector<std::vector<double>> reference(rig_.nq());
  for (const Snapshot& s : snaps) {
    for (int j = 0; j < rig_.nq(); ++j) reference[j].push_back(s.reference[j]);
  }
  return reference;
}

void DynamicKind::PlotEachTrace(const std::string& prefix, const std::string& title,
                                const std::vector<Trace>& traces,
                                const std::vector<std::vector<double>>* truth,
                                const std::vector<std::vector<double>>& reference,
                                const RunContext& ctx) const {
  for (const Trace& tr : traces) {
    PlotJointBands(rig_, title + tr.label, {tr}, truth, reference,
                   (ctx.out->FramesDir() / (prefix + tr.label + ".png")).string(), "time [s]");
  }
}

void DynamicKind::WriteRunMetrics(const std::vector<Snapshot>& snaps, const RunContext& ctx) const {
  Json& metrics = (*ctx.summary)["metrics"];
  metrics["snapshots"] = static_cast<int>(snaps.size());
  metrics["duration_s"] = trajectory_.Duration();
}

}  // namespace flexbench::scenarios::jsk
