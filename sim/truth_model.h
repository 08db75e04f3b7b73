// The truth model a scenario's `model:` names: an MJCF as it is, or a URDF with a position
// servo added per joint (sim/export_model.h UrdfToMjcf, the MJCF `flexbench convert` writes), so
// that the truth can command the URDF's joints and truth effects can act on them. And the
// declared model a robot file stands for when no declared-model YAML is given.
#pragma once

#include <string>
#include <vector>

#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {

// sim::LoadModel for an MJCF; a URDF is loaded as the MJCF UrdfToMjcf writes (servos at
// kDefaultServoKp), its messages naming `path`. Throws InputError as LoadModel does.
MjModelPtr LoadTruthModel(const std::string& path, std::vector<std::string>* warnings = nullptr);

// The rotation std about each actuated joint's axis in a declared model made from a robot file
// (deg): an encoder's resolution, as the MUKCa scenario declares.
inline constexpr double kDefaultSourceDeg = 0.1;

// The declared model of a robot file (MJCF or URDF) without a declared-model YAML: base `world`;
// the joints the truth commands (LoadTruthModel's position servos: every hinge and slide of a
// URDF) as actuated joints, in actuator order; the end effector the body reached from the
// deepest of them's body by following single children (a gripper's palm, not a finger); a source of
// kDefaultSourceDeg about each actuated joint's axis. `file` and `model_path` are `path`.
// Throws InputError naming the file when no joint is commanded.
DeclaredModel DeclaredModelOfRobot(const std::string& path);

}  // namespace flexbench::sim
