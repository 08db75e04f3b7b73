// The `model:` and `declared:` keys every scenario with a truth and a declared model has.
//
//   model: ../models/rover_arm.xml                  # MJCF or URDF, relative to the scenario
//   declared: ../models/rover_arm.declared.yaml     # a declared-model file, or inline:
//   declared: {actuated_joints: [...], end_effector: ee, sources: [...]}   (model: as above)
#pragma once
#include <string>

#include "sim/config.h"
#include "sim/declared_model.h"

namespace flexbench::scenarios {

// Reads both keys; `model_path` receives the resolved model path. An inline declared block
// describes the scenario's model. Throws InputError naming the file, line and key.
sim::DeclaredModel ReadModelAndDeclared(const ConfigNode& root, std::string* model_path);

}  // namespace flexbench::scenarios
