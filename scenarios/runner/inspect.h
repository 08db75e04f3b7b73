// `flexbench inspect MODEL`: what a truth model offers, as JSON on stdout: actuated joints,
// passive compliance joints, coupled joints, sensors, cameras, AprilTags and the effects it
// supports. MODEL may be a URDF: described as the truth has it, with a position servo per joint
// (sim/truth_model.h). It may also be a declared-model file (*.yaml): it is validated against
// its model and summarised, followed by the model's own description.
#pragma once

#include <string>

#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

// Description of a truth model (MJCF, or URDF with its servos). Throws InputError for a missing or
// rejected model.
Json InspectModel(const std::string& mjcf_path);

// The subcommand: prints JSON and returns 0, or prints one line on stderr and returns 2.
int InspectCommand(const std::string& path);

}  // namespace flexbench::scenarios
