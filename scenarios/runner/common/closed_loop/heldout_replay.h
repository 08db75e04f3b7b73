// A validation log's held-out time span replayed through estimators under the declared and the
// augmented model, each scored against the log's truth; the held-out truth has the last word on
// the verdict.
#pragma once

#include <string>

#include "scenarios/identify/run.h"
#include "scenarios/runner/common/closed_loop/setup.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

// Checked before any work: the log's truth is the end effector's and the span has joint rows
// (cl.replay_held_out); without such truth it is said and left out.
void CheckHeldOutReplay(ClosedLoopSetup& cl);

// The replay (metrics heldout_replay.<estimator>.before/after, trajectories heldout_before and
// heldout_after); returns the label of the estimator that judges it.
std::string ReplayHeldOut(const ClosedLoopSetup& cl, RunContext& ctx, const identify::Job& job,
                          const identify::Report& rep, Json* m);

// An augmented model that replays the held-out truth more than 10% worse than the declared one
// (by `judge`'s mean position error) fits the rows, not the arm: the verdict is unexplained.
void JudgeHeldOutReplay(RunContext& ctx, const std::string& judge, Json* m, identify::Report* rep);

}  // namespace flexbench::scenarios
