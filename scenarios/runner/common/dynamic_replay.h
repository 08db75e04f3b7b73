// What dynamic identification hands on: the augmented model (the declared file with the chosen
// effects as identified_effects, and the MJCF they fold into), and the log's last fold replayed
// through the estimators under the declared model and under one fitted without that fold.
#pragma once

#include <mujoco/mujoco.h>

#include <string>
#include <vector>

#include "scenarios/identify/dynamic/select.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/scenario_kind.h"
#include "sim/declared_model.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {

// `declared` with the chosen effects added to its identified_effects: their values (with their
// standard errors), or the values fitted without the last fold; a static effect the fit started
// from and replaced by its dynamic counterpart (DynamicReport::replaced_static) leaves.
sim::DeclaredModel DynamicAugmented(const sim::DeclaredModel& declared,
                                    const identify::dynamic::DynamicReport& rep,
                                    bool heldout_values);

// declared_augmented.yaml and calibrated_model.xml (sim::ExportMjcf) when effects were chosen
// and the verdict is not unexplained; summary.json's calibrated_model says what the MJCF cannot
// hold, or why nothing was written.
void WriteDynamicAugmented(const sim::DeclaredModel& declared,
                           const identify::dynamic::DynamicReport& rep, RunContext& ctx);

// The last fold's span of `log` (it needs truth of the end effector, else it is said and left)
// replayed from the log's start by `specs` under the declared model and under the augmented one
// (values fitted without that fold), scored on the span: metrics
// heldout_replay.<label>.before/after, heldout_replay_lowered (the first estimator's mean
// position error lower after), trajectories heldout_before and heldout_after. Effects that do not
// move the end effector at given joint readings leave the replay as it was: the log says which.
void ReplayDynamicHeldOut(const sim::RecordedLog& log, const mjModel* nominal,
                          const sim::DeclaredModel& declared,
                          const identify::dynamic::DynamicReport& rep,
                          const std::vector<EstimatorSpec>& specs, RunContext& ctx);

}  // namespace flexbench::scenarios
