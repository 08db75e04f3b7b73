// The identification as one call: rows of a declared model in, the effects it lacks, the errors
// before and after, the verdict and the augmented model's consistency out. The closed_loop
// scenario kind and `flexbench identify` (and through it the Python module) call Run; how the
// rows were obtained (files, logs, a simulated truth) and how the report is written are theirs.
//
//   outliers (FindOutliers)  ->  Identify (stages: identify.h)  ->  errors before and after
//   -> the fit's covariance under the readings' noise  ->  verdict  ->  NEES and source scale
#pragma once

#include <mujoco/mujoco.h>

#include <functional>
#include <string>
#include <vector>

#include "estimators/stats/chi_square.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/source_scaling.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"

namespace flexbench::identify {

struct Job {
  // The declared side: its file, the MuJoCo model it names (masses: the loads; the sources'
  // frames), its chain with couplings, and the candidates and measured points on that chain.
  const sim::DeclaredModel* declared = nullptr;
  const mjModel* mj = nullptr;
  const sim::DeclaredChain* chain = nullptr;
  const EffectModel* em = nullptr;
  DataSet cal, val;                  // the calibration and validation rows, as measured
  std::string cal_where, val_where;  // where each set was named, for messages
  std::vector<int> candidates;       // indices into em->candidates()
  IdentifyOptions opt;
  double reading_std_rad = 0.0;  // the joint readings' noise, when known (0: unknown)
  // Progress lines and warnings (either may be empty).
  std::function<void(const std::string&)> log, warn;
};

struct Report {
  // The rows identified and scored: outliers left out; after Run in the base frame at the
  // fit's measurement-frame poses.
  DataSet cal, val;
  RowLoads cal_loads, val_loads;              // under the declared model
  RowLoads cal_loads_after, val_loads_after;  // where the augmented model puts the arm
  std::vector<std::string> rejected;          // outliers left out, by row name
  IdentifyResult result;
  // Per row, the error under the declared model (before) and the augmented one (after), and
  // the rows' predicted markers.
  std::vector<double> cal_before, cal_after, val_before, val_after;
  std::vector<Vec3> cal_p0, cal_p1, val_p0, val_p1;
  // The validation error in the data's main unit (MainUnit), before and after; the verdict.
  double val_err_before = 0.0, val_err_after = 0.0;
  std::string verdict;
  double noise_ratio = 0.0;  // the calibration residual over the stated noise, after the fit
  double rss_over_reading_noise = 0.0;  // with reading_std_rad: NaN when nothing was fitted
  // Validation NEES before and after (the declared sources), its bounds, and the sources'
  // scale that makes the augmented model consistent on what the rows constrain.
  double nees_before = 0.0, nees_after = 0.0, nees_after_scaled = 0.0;
  stats::ChiSquareBounds nees_bounds{0.0, 0.0};
  double nees_bound_high_shared = 0.0;  // with reading_std_rad: the target of the scale
  double source_scale = 1.0;
  std::vector<SourceDirection> directions;  // of the declared sources
  std::vector<bool> constrained;            // per direction: sized by the rows
  std::vector<std::string> kept_declared;   // the others' names
  bool sources_cover_residual = true;
  double prepare_s = 0.0, identify_s = 0.0;  // wall-clock seconds
};

Report Run(const Job& job);
// The same with the job's rows moved into the report (one copy of a large data set, not two);
// the job's declared side stays valid for AugmentedModel and FittedUnder.
Report Run(Job&& job);

// The unit a data set is judged in: metres when it has point rows, else pixels when it has
// pixel rows, else radians (gravity rows alone).
RowUnit MainUnit(const DataSet& d);
bool HasUnit(const DataSet& d, RowUnit unit);

// The declared model with the fit: its effects (a refit adds to the file's own), the fitted
// frames and marker offsets, and the sources scaled to what remains.
sim::DeclaredModel AugmentedModel(const Job& job, const Report& report);

// Where the fit holds: the ranges, gravity torques and end-effector box of the rows on
// `augmented`'s chain, and the source directions those rows sized.
sim::FittedUnder FittedUnder(const Job& job, const Report& report,
                             const sim::DeclaredModel& augmented);

}  // namespace flexbench::identify
