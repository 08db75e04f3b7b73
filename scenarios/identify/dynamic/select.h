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
//   removal, swap  after each addition an earlier effect no longer needed leaves; at the end a
//                  chosen effect is swapped for a candidate when the swap lowers the held-out
//                  error (forward selection's path can pick a stand-in first)
//   verdict        explained / partly_explained / unexplained, from what the residual still
//                  shows (motion_diagnostics.h)
// Parameter uncertainty: the sandwich covariance with segments as clusters (a segment's
// residuals are correlated, so the textbook (J'J)^-1 s^2 is too small).
#pragma once

#include <string>
#include <vector>

#include "scenarios/identify/dynamic/fit.h"
#include "scenarios/identify/dynamic/motion_diagnostics.h"

namespace flexbench::identify::dynamic {

struct DynamicIdentifyOptions {
  int max_effects = 6;          // chosen at most; a round at it only checks that no more is needed
  double bic_threshold = 10.0;  // a screened candidate lowers BIC by more than this
  int screen_keep = 3;          // screened candidates refitted per round
  double cv_min_gain = 0.05;    // relative held-out error drop a candidate must bring
  int iterations = 8;           // Levenberg-Marquardt iterations per fit
  int joint_iterations = 10;    // of the final fit of the effects with the segments' starts
  // The part of the declared model's explained excess a swap may leave unexplained and still be
  // an equivalent effect.
  double equivalence = 0.05;
  // Held-out normalised RMS (1: the readings' noise) up to which a fit can be explained: a
  // rollout from a recorded state starts with its speed estimated from noisy encoders, so even
  // the truth's model stays above 1 (1.4 on the shipped scenarios).
  double explained_heldout = 2.0;
};

struct ChosenEffect {
  std::string name;  // family@location
  std::vector<std::string> value_names;
  std::vector<double> values;
  std::vector<double> std_errors;
  std::vector<std::string> equivalent;  // other candidates that explain the same
  std::vector<double> heldout_values;   // fitted without the last fold (DynamicReport)
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
  // The warm start's static effects whose dynamic counterpart was chosen: the augmented model
  // carries the counterpart in their place.
  std::vector<std::string> replaced_static;
  // The last fold's time span (encoder rows), which ChosenEffect::heldout_values never saw.
  double heldout_from_s = 0.0, heldout_to_s = 0.0;
  // Not empty when max_effects, not the held-out error, ended selection (a candidate would still
  // have been kept): then the verdict is not explained.
  std::string capped;
  // What the residual still shows (motion_diagnostics.h), located.
  MotionDiagnostics diagnostics;
  // unexplained: no effect lowers the held-out error by cv_min_gain and the declared model does
  // not hold the log; no_effect: none is needed (the declared model's held-out error is within
  // explained_heldout of the noise, the residual shows nothing left); explained: the chosen ones
  // lower it to there; partly_explained: they help, but something is left.
  std::string verdict;
  std::vector<std::string> log;
  long rollouts = 0;  // of the whole log, the declared model's included
  FitState final_state;
  FitState declared_state;  // the declared model from the final fit's segment starts
};

// Selects (each segment started at the encoders' speeds), then fits the chosen effects jointly
// with every segment's start speeds (`problem` keeps the fitted starts). The held-out errors are
// the selection's. `warm`: the declared file's static effects in their
// dynamic families (sim::DynamicCounterparts), fitted first and kept as the starting set when
// they lower the held-out error; selection goes on from there and may remove them.
DynamicReport IdentifyDynamics(DynamicProblem& problem, const DynamicIdentifyOptions& options,
                               const std::vector<sim::StaticCounterpart>& warm = {});

}  // namespace flexbench::identify::dynamic
