// Which dynamic effect the model lacks: the static identification's stages (selection.h) on
// rollouts of a moving arm's log.
//   screening      every candidate family at every location, by one Gauss-Newton step on the
//                  current fit's residual (its own Jacobian columns, the chosen ones' beside
//                  it), ranked by BIC = N ln(RSS/N) + k ln N
//   fit            the best few refitted by Levenberg-Marquardt over the rollouts
//   cross-validation  folds of segments held out in turn (a Gauss-Newton step from the fit on
//                  the other folds, the held-out rollout exact): a candidate is kept only when
//                  its held-out error drops by more than cv_min_gain
//   equivalence    a chosen effect's swap for another candidate that explains the same
//   verdict        explained / partly_explained / unexplained, from what is left
// Parameter uncertainty: the sandwich covariance with segments as clusters (a segment's
// residuals are correlated, so the textbook (J'J)^-1 s^2 is too small).
#pragma once

#include <string>
#include <vector>

#include "scenarios/identify/dynamic/fit.h"

namespace flexbench::identify::dynamic {

struct DynamicIdentifyOptions {
  int max_effects = 3;
  double bic_threshold = 10.0;  // a screened candidate lowers BIC by more than this
  int screen_keep = 3;          // screened candidates refitted per round
  double cv_min_gain = 0.05;    // relative held-out error drop a candidate must bring
  int iterations = 8;           // Levenberg-Marquardt iterations per fit
  // The part of the declared model's explained excess a swap may leave unexplained and still be
  // an equivalent effect.
  double equivalence = 0.05;
  // Normalised residual RMS (1: the readings' noise) up to which a stream is explained.
  double explained_rms = 1.5;
};

struct ChosenEffect {
  std::string name;  // family@location
  std::vector<std::string> value_names;
  std::vector<double> values;
  std::vector<double> std_errors;
  std::vector<std::string> equivalent;  // other candidates that explain the same
};

struct StreamError {
  std::string stream;  // encoders, gyro, accel
  std::string unit;
  double noise = 0.0;  // the readings' std (the log's, or estimated)
  bool noise_from_log = false;
  int entries = 0;
  double rms_before = 0.0, rms_after = 0.0;  // in the unit
};

struct DynamicReport {
  int segments = 0;
  int folds = 0;
  int diverged_declared = 0;  // segments the declared model's rollout lost (left out)
  std::string first_divergence;
  std::vector<StreamError> streams;
  double heldout_before = 0.0;  // held-out normalised RMS, declared model
  double heldout_after = 0.0;   // with the chosen effects
  std::vector<ChosenEffect> chosen;
  std::string verdict;  // explained, partly_explained, unexplained
  std::vector<std::string> log;
  int rollouts = 0;
  FitState final_state;
};

DynamicReport IdentifyDynamics(const DynamicProblem& problem,
                               const DynamicIdentifyOptions& options);

}  // namespace flexbench::identify::dynamic
