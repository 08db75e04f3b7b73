// The simulated truth of a closed_loop run (its `truth` block): a MuJoCo robot with the truth's
// effects that a user hand-guides into sockets, or that a tracker watches at random settled
// postures; its rows are the encoders' readings there. And the scores only a known truth
// allows: the effects found against the truth's, the fitted tracker pose against the true one.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "scenarios/runner/common/closed_loop/setup.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

// The `truth` block: effects, the expected names, and where simulated data come from (sockets
// in a workspace, or a tracker).
void ReadTruth(ClosedLoopSetup& cl, const ConfigNode& t);
// The tracker's frame is a declared measurement frame and its markers are measured points.
void CheckTrackerTruth(ClosedLoopSetup& cl);

// Socket rows of a `simulate:` source (`what`: calibration or validation), appended to d.
void SimulateSockets(ClosedLoopSetup& cl, const Source& s, RunContext& ctx, const std::string& what,
                     identify::DataSet* d);
// Tracker rows of a `simulate:` source with truth.tracker, appended to d.
void SimulateTracker(ClosedLoopSetup& cl, const Source& s, RunContext& ctx, const std::string& what,
                     identify::DataSet* d);

// effects_found, and against the truth's (or the expected) names: effect_found_correct and, for
// a tracker or expected names, effects_named_up_to_equivalence and load_effects_named.
void ScoreNames(const ClosedLoopSetup& cl, const identify::IdentifyResult& res, Json* m);
// The fitted tracker pose against the true one (metrics.tracker_pose).
void ScoreTrackerPose(const ClosedLoopSetup& cl, RunContext& ctx, const identify::DataSet& cal,
                      const identify::IdentifyResult& res);
// Simulated tracker rows: the truth's own error per row; nullopt when a row has none.
std::optional<std::vector<double>> TruthRowErrors(const ClosedLoopSetup& cl,
                                                  const identify::DataSet& d);

}  // namespace flexbench::scenarios
