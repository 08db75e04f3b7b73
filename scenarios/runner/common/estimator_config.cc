#include "scenarios/runner/common/estimator_config.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>

#include "estimators/error.h"
#include "estimators/stats/chi_square.h"

namespace flexbench::scenarios {

namespace {

// Fails at `entry` unless `name` is in the estimator registry.
void CheckRegistered(const std::string& name, const ConfigNode& entry) {
  bool known = false;
  std::string list;
  for (const auto& e : estimators::EstimatorRegistry()) {
    known = known || name == e.name;
    list += std::string(list.empty() ? "" : ", ") + e.name;
  }
  if (!known) entry.Fail("unknown estimator '" + name + "' (known: " + list + ")");
}

// The entry's numeric parameters; with `name` set, its `estimator` key (a labelled entry's
// registry name) is read there instead.
std::map<std::string, std::vector<double>> ReadParams(const ConfigNode& entry, std::string* name) {
  std::map<std::string, std::vector<double>> values;
  if (entry.IsMap()) {
    for (const std::string& key : entry.Keys()) {
      const ConfigNode v = entry.Child(key);
      if (name && key == "estimator") {
        *name = v.AsString();
        continue;
      }
      values[key] = v.IsSequence() ? v.AsDoubleList() : std::vector<double>{v.AsDouble()};
    }
  } else if (!(entry.IsScalar() && entry.AsString().empty())) {
    entry.Fail("expected a mapping of parameters ({} for none)");
  }
  return values;
}

}  // namespace

std::vector<EstimatorSpec> ParseEstimators(const ConfigNode& node, EstimatorLabels labels) {
  const bool labelled = labels == EstimatorLabels::kAllowed;
  std::vector<EstimatorSpec> specs;
  for (const std::string& key : node.Keys()) {
    const ConfigNode entry = node.Child(key);
    EstimatorSpec spec;
    spec.name = spec.label = key;
    spec.where = entry.WhereKey();
    // An unlabelled key is the name: checked before its parameters. A labelled entry's name is
    // known only after them (its `estimator` key may come last).
    if (!labelled) CheckRegistered(spec.name, entry);
    const auto values = ReadParams(entry, labelled ? &spec.name : nullptr);
    if (labelled) CheckRegistered(spec.name, entry);
    spec.params = estimators::Params(values, spec.where);
    specs.push_back(std::move(spec));
  }
  if (labelled && specs.empty()) node.Fail("no estimators");
  return specs;
}

std::unique_ptr<estimators::Estimator> MakeEstimatorOf(const EstimatorSpec& e,
                                                       estimators::EstimatorSetup setup,
                                                       std::uint64_t seed) {
  setup.params = e.params;
  setup.seed = seed;
  try {
    return estimators::MakeEstimator(e.name, setup);
  } catch (const InputError& err) {
    const std::string what = err.what();
    if (e.where.empty() || what.rfind(e.where, 0) == 0) throw;
    throw InputError(e.where + ": " + what);
  }
}

}  // namespace flexbench::scenarios
