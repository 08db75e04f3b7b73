// The identified effects of a declared file (`identified_effects:`, written by closed_loop and
// `flexbench identify`) turned into the kinematics' form (estimators/kinematics/model_effects.h):
// each `type@location` name found in the effect table (estimators/kinematics/effect_table.h),
// resolved to the chain's joints and frames, its values counted and checked by its row. The
// structure follows scenarios/identify/effect_model.h, which fitted them: the same link
// directions, tilt axes, mount and path to the end effector.
#pragma once

#include <mujoco/mujoco.h>

#include "estimators/kinematics/model_effects.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"

namespace flexbench::sim {

// Per-frame masses of the chain (each MuJoCo body's mass on the nearest chain frame at or above
// it, passive joints at their reference angle) and gravity in the base frame.
void ExtractMasses(const mjModel* m, const DeclaredChain& chain, kinematics::ModelEffects* effects);

// Fills chain->effects from declared.identified_effects. Throws InputError naming the file, line
// and key for an unknown effect type, a joint or frame the chain lacks, a wrong number of values,
// a non-finite value, or a load-driven effect on a model without masses.
void ApplyIdentifiedEffects(const mjModel* m, const DeclaredModel& declared, DeclaredChain* chain);

}  // namespace flexbench::sim
