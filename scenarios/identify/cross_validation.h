// Cross-validation of a model's effects: fit on all data but one fold, score the fold.
//
// Folds are the data's sets (placements, sessions) when it has two or more; with one set, the
// groups (sockets) when there are at least four; otherwise rows in round robin (k = 5), the rows
// of one posture (a `pose` label, else the same readings in the same set: every marker seen at
// once) always in the same fold, since they share the posture's reading errors. A
// held-out fold is scored with its own nuisance parameters re-estimated from the prediction
// (each group's point is the mean of its rows), so the score sees only what the effects
// predict: the mean squared whitened residual per residual entry, distances included.
#pragma once
#include <string>
#include <vector>

#include "scenarios/identify/identify.h"

namespace flexbench::identify {

// One fold's training rows. Data with groups: the fold's rows as data sets of their own
// (Subset, RowLoads::Subset: the groups renumbered). Without: those stay empty and the fits read
// the rows in place (train_rows; the test rows are Folds::test_rows), a copy of no row.
struct FoldData {
  DataSet train, test;
  RowLoads train_loads, test_loads;
  std::vector<int> train_rows;
};

struct Folds {
  std::string by;                           // "set", "group", "row"
  std::vector<std::vector<int>> test_rows;  // per fold, row indices into the data set
  // Per fold, its subsets made once (CacheFolds); empty: CrossValidate makes them per call.
  std::vector<FoldData> cache;
};

// Fills `folds->cache` when it takes at most `max_bytes` (with groups every row is copied once
// per fold; without, a row index per fold): a selection cross-validates dozens of models on the
// same folds (the copies were a tenth of identifying 10,000 rows).
void CacheFolds(const DataSet& data, const RowLoads& loads, Folds* folds,
                size_t max_bytes = size_t{128} << 20);

// `by`: "auto" (as above) or "set", "group", "row" (fewer than two folds then: none).
Folds MakeFolds(const DataSet& data, const std::string& by = "auto");

// The rows `rows` of `data` as a data set of their own (groups, sets and distances renumbered,
// distances only between groups that keep rows). `loads` likewise, when given.
DataSet Subset(const DataSet& data, const std::vector<int>& rows);

// Sum of squared whitened residuals of `data` under (active, theta), group points at the mean
// of their rows' predictions, measurement frames and marker offsets at `nuisance`'s (fitted on
// the other folds; null: at their references), priors left out; `*entries` the number of
// residual entries. `rows`: the rows of `data` scored (null: all; as Problem's).
double HeldOutSquares(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                      const std::vector<int>& active, const Eigen::VectorXd& theta,
                      const IdentifyOptions& opt, int* entries, const Fit* nuisance = nullptr,
                      const std::vector<int>* rows = nullptr);

// Mean squared whitened residual over the held-out folds of `fit`'s model, each fold's
// parameters fitted on the other folds (starting from `fit`'s values, its bases kept).
double CrossValidate(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                     const Folds& folds, const Fit& fit, const IdentifyOptions& opt);

}  // namespace flexbench::identify
