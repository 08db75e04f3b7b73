// Gates: pass/fail conditions on metrics, declared in the scenario file next to what they gate.
//
//   gates:
//     - {name: tag_found, metric: detections, op: ">=", threshold: 1}
//     - name: ppoe_beats_naive
//       metric: estimators.ppoe_ekf.metrics.lateral_err_mean_m
//       op: "<"
//       threshold: {metric: estimators.naive_ekf.metrics.lateral_err_mean_m, scale: 0.8}
//
// A metric path is looked up under `metrics` first, then from the summary's root.
#pragma once

#include <string>
#include <vector>

#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"

namespace flexbench::scenarios {

struct GateSpec {
  std::string name;
  std::string metric;
  std::string op;  // <, <=, >, >=, ==, !=
  double threshold = 0.0;
  std::string threshold_metric;  // when set, threshold = scale * value of this metric
  double scale = 1.0;
  bool threshold_is_bool = false;
  bool threshold_bool = false;
  std::string where;  // "<file>:<line>" of the gate, for messages
};

std::vector<GateSpec> ParseGates(const ConfigNode& root);

// Throws InputError "<file>:<line>: gate '<name>': metric '<path>' is not in this scenario's
// results" for a gate whose metric (or threshold metric) path names nothing in `summary`: a
// typo, not a failed gate.
void CheckGateMetricsExist(const std::vector<GateSpec>& gates, const Json& summary);

// Evaluates every gate against `summary`, returns the `gates` array. A missing or non-numeric
// (or non-finite) metric fails its gate (value null).
Json EvaluateGates(const std::vector<GateSpec>& gates, const Json& summary, bool* all_passed);

// Looks up a dotted metric path ("a.b.c") under summary.metrics, then from the root.
const Json* FindMetric(const Json& summary, const std::string& path);

}  // namespace flexbench::scenarios
