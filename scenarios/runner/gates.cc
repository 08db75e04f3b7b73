#include "scenarios/runner/gates.h"

#include <cmath>

namespace flexbench::scenarios {
namespace {

const Json* Walk(const Json& root, const std::string& path) {
  const Json* node = &root;
  size_t start = 0;
  while (start <= path.size()) {
    const size_t dot = path.find('.', start);
    const std::string key = path.substr(start, dot == std::string::npos ? dot : dot - start);
    if (!node->is_object() || !node->contains(key)) return nullptr;
    node = &(*node)[key];
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  return node;
}

bool Compare(double v, const std::string& op, double t) {
  if (op == "<") return v < t;
  if (op == "<=") return v <= t;
  if (op == ">") return v > t;
  if (op == ">=") return v >= t;
  if (op == "==") return v == t;
  return v != t;
}

}  // namespace

std::vector<GateSpec> ParseGates(const ConfigNode& root) {
  std::vector<GateSpec> gates;
  const auto node = root.Optional("gates");
  if (!node) return gates;
  for (const ConfigNode& g : node->Items()) {
    GateSpec s;
    s.where = g.Where();
    s.name = g.GetString("name");
    s.metric = g.GetString("metric");
    const ConfigNode op = g.Child("op");
    s.op = op.AsString();
    if (s.op != "<" && s.op != "<=" && s.op != ">" && s.op != ">=" && s.op != "==" &&
        s.op != "!=") {
      op.Fail("unknown operator '" + s.op + "' (expected <, <=, >, >=, == or !=)");
    }
    const ConfigNode t = g.Child("threshold");
    if (t.IsMap()) {
      s.threshold_metric = t.GetString("metric");
      s.scale = t.GetDouble("scale", 1.0);
    } else if (t.AsString() == "true" || t.AsString() == "false") {
      s.threshold_is_bool = true;
      s.threshold_bool = t.AsBool();
    } else {
      s.threshold = t.AsDouble();
    }
    gates.push_back(s);
  }
  return gates;
}

const Json* FindMetric(const Json& summary, const std::string& path) {
  if (summary.contains("metrics")) {
    if (const Json* m = Walk(summary["metrics"], path)) return m;
  }
  return Walk(summary, path);
}

void CheckGateMetricsExist(const std::vector<GateSpec>& gates, const Json& summary) {
  for (const GateSpec& g : gates) {
    for (const std::string* path : {&g.metric, &g.threshold_metric}) {
      if (path->empty() || FindMetric(summary, *path)) continue;
      throw InputError(g.where + ": gate '" + CapForMessage(g.name) + "': metric '" +
                       CapForMessage(*path) +
                       "' is not in this scenario's results (a typo? see summary.json)");
    }
  }
}

Json EvaluateGates(const std::vector<GateSpec>& gates, const Json& summary, bool* all_passed) {
  Json out = Json::array();
  *all_passed = true;
  for (const GateSpec& g : gates) {
    Json row;
    row["name"] = g.name;
    row["metric"] = g.metric;
    row["op"] = g.op;
    const Json* value = FindMetric(summary, g.metric);
    bool passed = false;
    if (g.threshold_is_bool) {
      row["threshold"] = g.threshold_bool;
      row["value"] = value ? *value : Json();
      if (value && value->is_boolean()) {
        const bool v = value->get<bool>();
        passed = g.op == "=="   ? v == g.threshold_bool
                 : g.op == "!=" ? v != g.threshold_bool
                                : false;
      }
    } else {
      double threshold = g.threshold;
      bool threshold_ok = true;
      if (!g.threshold_metric.empty()) {
        const Json* t = FindMetric(summary, g.threshold_metric);
        threshold_ok = t && t->is_number();
        threshold = threshold_ok ? g.scale * t->get<double>() : NAN;
        row["threshold_metric"] = g.threshold_metric;
        row["threshold_scale"] = g.scale;
      }
      row["threshold"] = threshold_ok ? Json(threshold) : Json();
      row["value"] = value ? *value : Json();
      if (value && value->is_number() && threshold_ok) {
        const double v = value->get<double>();
        passed = std::isfinite(v) && Compare(v, g.op, threshold);
      }
    }
    row["passed"] = passed;
    *all_passed = *all_passed && passed;
    out.push_back(row);
  }
  return out;
}

}  // namespace flexbench::scenarios
