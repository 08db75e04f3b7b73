// Dynamic effects: what a moving arm shows and a static posture does not — joint damping, dry
// friction, rotor inertia, servo stiffness and lag, the first bending mode of an elastic link,
// the base plate's sway, a payload's mass. One table, read by the truth (sim/effects: a scenario
// switches them on by name) and by dynamic identification (scenarios/identify/dynamic: each
// fitted row is a candidate family, evaluated by MuJoCo rollouts); both change the model through
// ApplyDynamic, so the parameter identification reports is the parameter the truth was given.
//
// A row acts at a location: a joint (damping, friction, armature), an actuated joint (servo gain,
// delay), a body holding passive bending joints (a link's mode), the base plate's joints, or the
// end-effector body (payload). Values add to the MJCF's own (damping, friction, armature, mass)
// or scale them (servo gain; a mode's stiffness and damping), so zero added / scale one is the
// MJCF as written.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "sim/declared_model.h"
#include "sim/effects/truth_setup.h"

namespace flexbench::sim {

enum class DynamicKind {
  kJointDamping,
  kJointFriction,
  kJointArmature,
  kServoGain,
  kServoDelay,
  kLinkMode,
  kBaseMode,
  kPayloadMass,
  // Truth only: no family of the identification stands for it.
  kStribeckFriction,
};
inline constexpr int kNumDynamicKinds = 9;

enum class DynamicLocation { kJoint, kActuatedJoint, kBendingBody, kBasePlate, kBody };

struct DynamicRow {
  DynamicKind kind;
  const char* name;  // the truth's effects: key, identification's family name
  DynamicLocation location;
  int num_values;
  std::array<const char*, 2> value_names;  // as scenario files give them, with the unit
  std::array<double, 2> lower;             // physical bounds of each value
  std::array<double, 2> upper;
  std::array<double, 2> neutral;  // the MJCF as written
  std::array<double, 2> fd_step;  // finite-difference step of each value
  bool fitted;                    // a candidate family of dynamic identification
  const char* description;
};

const std::array<DynamicRow, kNumDynamicKinds>& DynamicTable();
const DynamicRow& Row(DynamicKind kind);
// The row called `name`, nullptr when none.
const DynamicRow* FindDynamic(const std::string& name);

// The model's parts at a location: joint ids (a joint, an actuated joint, the passive joints of
// a bending body or the base plate) or the body id (payload). Empty when the model lacks them.
std::vector<int> DynamicParts(const TruthSetup& setup, DynamicKind kind,
                              const std::string& location);
// Whether the model has any location for the row; `why` says what is missing.
bool DynamicSupported(const ModelCatalog& catalog, DynamicKind kind, std::string* why);
// Every location of the model a fitted row can act at, in model order.
std::vector<std::string> DynamicLocations(const TruthSetup& setup, DynamicKind kind);

// Changes the truth `setup` (its model, released joints, servo delays, Stribeck friction) by the
// row's values at `location`. Throws InputError (prefixed `where`) when the location is not the
// model's or a value is outside the row's bounds.
void ApplyDynamic(TruthSetup& setup, DynamicKind kind, const std::string& location,
                  const double* values, const std::string& where);

// The values that act as `first` then `second` applied at one location (ApplyDynamic twice):
// added (damping, friction, armature, mass), multiplied (a servo gain, a mode's scales), or the
// second (a delay). An augmented model merges a refit of a declared effect with it so.
std::array<double, 2> Combined(DynamicKind kind, const std::array<double, 2>& first,
                               const std::array<double, 2>& second);

// Whether a row changes where a standing arm is at given joint readings (a link's mode bends
// the link under its load, a payload's mass loads the arm); the others change only its motion.
bool HasStandingPart(DynamicKind kind);

// An identified effect of a fitted dynamic row in a declared file (identified_effects: an entry
// whose type is a row's name), as dynamic identification writes the augmented model.
struct DeclaredDynamic {
  const DynamicRow* row = nullptr;
  std::string location;
  std::array<double, 2> values{};
  std::array<double, 2> stds{};  // 0 where the entry gives none
  std::string where;             // the entry, for messages
};

// Whether `effect` (type@location) is a dynamic row's.
bool IsDynamicEffect(const std::string& effect);

// The dynamic entries of `effects`, each checked: a fitted row, of the form type@location, given
// once, its number of finite values within the row's bounds, finite non-negative stds. Throws
// InputError naming the entry; the location is checked where the entry is applied (ApplyDynamic).
std::vector<DeclaredDynamic> DynamicEntries(const std::vector<IdentifiedEffect>& effects);

// A declared file's static effect (closed_loop's, from postures) that a dynamic row stands for
// in motion: where dynamic identification starts from when both kinds of data exist.
struct StaticCounterpart {
  std::string static_effect;  // type@location as the file names it
  DeclaredDynamic dynamic;
};

// link_bending@J: link_mode at the bending body of the link that ends at J, stiffness scale
// 1 / (c k) (k the body's bending joints' mean MJCF stiffness; the inverse of the mode's standing
// part, sim/declared_effects.h), damping scale 1; payload@B, B an effect:payload body:
// payload_mass@B, its mass. Values are clamped to the dynamic row's bounds. The other static
// effects have no dynamic counterpart.
std::vector<StaticCounterpart> DynamicCounterparts(const mjModel* model,
                                                   const ModelCatalog& catalog,
                                                   const DeclaredModel& declared);

}  // namespace flexbench::sim
