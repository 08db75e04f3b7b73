// The identifiable effects, one row each: the one place an effect's name, its parameters and
// their units, its physical bounds, whether it acts through the gravity loads and how it enters
// the chain are written. The identification (its candidates), the declared-model files (their
// identified_effects) and the scenarios read this table; an effect's maths lives with the layer
// that evaluates it (kinematics::ModelEffects for estimators, identify::EffectModel for the
// fit), its truth physics in sim/effects/.
#pragma once

#include <array>
#include <string>

namespace flexbench::kinematics {

enum class EffectKind {
  kJointOffset,
  kJointCompliance,
  kBacklash,
  kLinkLength,
  kLinkOffset,
  kAxisTilt,
  kLinkBending,
  kBaseCompliance,
  kThermalExpansion,
  kPayload,
  kCameraOffset,
  kJointOrigin,
  kTransmissionError,
  kJointErrorCurve,
  kStiffeningSpring,
  kGravityTilt,
  kLateralCompliance,
};
inline constexpr int kNumEffectKinds = 17;

// How an effect changes the chain the estimators predict with.
enum class EffectEntry {
  kReadingToAngle,  // the reading -> joint-angle map (offsets, gear and spring deflection)
  kFixedTransform,  // a link's fixed transform (lengths, offsets, bending, origins)
  kJointAxis,       // the direction of a joint's axis
  kMountTilt,       // the arm's mount tilting under its load
  kLoads,           // the loads every load-driven term sees (payload, gravity's direction)
  kCameraPose,      // an observing camera's pose
};

struct EffectRow {
  EffectKind kind;
  const char* name;  // as identification and declared files name it (an axis tilt adds _a/_b)
  int num_values;
  const char* unit;  // of its values (a prismatic joint's offset is in m)
  bool load_driven;  // acts through the gravity torques / moments (needs the arm's masses)
  EffectEntry enters;
  double fd_step;  // finite-difference step of its values in the fit
  // Physical bounds of each value (revolute joints; a prismatic joint's offset: +-0.1 m).
  std::array<double, 6> lower, upper;
};

// Every row, in EffectKind order.
const std::array<EffectRow, kNumEffectKinds>& EffectTable();
const EffectRow& Row(EffectKind kind);
// The row of a name as declared files write it ("joint_axis_tilt_a" finds the axis tilt);
// nullptr when no effect has that name.
const EffectRow* FindEffect(const std::string& file_name);

// The stiffening spring's reference torque: its cubic term is t[1] tau^3 / tau0^2, so t[1] is
// the extra deflection at tau0 (rad/Nm, as the linear term).
inline constexpr double kStiffeningTau0Nm = 10.0;

}  // namespace flexbench::kinematics
