// Reading estimators from scenario files (their scores: error_stats.h).
//
//   estimators:
//     fk: {}
//     naive_ekf: {std_trans_m: [0.07, 0.07, 0.03], std_rot_deg: [5, 5, 15]}
//
// A labelled block (the jsk kinds) names its entries freely: the label is the registry name
// unless the entry's `estimator` key names another, so one estimator can run twice:
//
//   estimators:
//     pf_all: {conjugate_proposal: 1}
//     pf_all_bootstrap: {estimator: pf_all}
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "estimators/estimator.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

struct EstimatorSpec {
  std::string name;  // registry name
  estimators::Params params;
  std::string label;  // the entry's key (the name, unless a labelled entry names another)
  std::string where;  // "<file>:<line>: key '<path>'" of the entry, for messages
};

// Whether an `estimators:` block may label its entries (see above).
enum class EstimatorLabels { kNone, kAllowed };

// Reads the `estimators:` mapping; every value is a number or a list of numbers. Checks the
// names against the registry (InputError naming file, line and estimator). A labelled block
// must list at least one estimator.
std::vector<EstimatorSpec> ParseEstimators(const ConfigNode& node,
                                           EstimatorLabels labels = EstimatorLabels::kNone);

// The estimator of entry `e` on `setup` with e's parameters and `seed`; an InputError about
// its parameters names the entry's file, line and key.
std::unique_ptr<estimators::Estimator> MakeEstimatorOf(const EstimatorSpec& e,
                                                       estimators::EstimatorSetup setup,
                                                       std::uint64_t seed);

}  // namespace flexbench::scenarios
