// The effect vocabulary, the one place an effect's name is written. The identifiable effects, one
// row each: its parameters and their units, its physical bounds, whether it acts through the
// gravity loads, how it enters the chain and whether the truth simulates it. The effects only the
// truth has, one row each in the truth-only table. The identification (its candidates), the
// declared-model files (their identified_effects), the truth's effect list (sim/effects/) and
// the scenarios read these tables; an effect's maths lives with the layer that evaluates it
// (identify::EffectModel for the fit, sim/declared_effects.cc turning it into
// kinematics::ModelEffects for the estimators), its truth physics in sim/effects/.
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

// Whether the simulated truth can hold an identifiable effect.
enum class EffectTruth {
  kSimulated,  // sim/effects/ has an effect of the row's name that makes it
  kFitOnly,    // none does: measured data may hold it, the simulated truth does not
};

struct EffectRow {
  EffectKind kind;
  const char* name;  // as identification and declared files name it (an axis tilt adds _a/_b)
  int num_values;
  const char* unit;  // of its values (at a revolute joint; slide_unit at a prismatic one)
  bool load_driven;  // acts through the gravity torques / moments (needs the arm's masses)
  EffectEntry enters;
  EffectTruth truth;
  double fd_step;  // finite-difference step of its values in the fit
  // Physical bounds of each value (at a revolute joint; slide_bound at a prismatic one).
  std::array<double, 6> lower, upper;
  // At a prismatic joint: the unit of its value and its bound, +-slide_bound (nullptr: the
  // effect's value is the same at either joint).
  const char* slide_unit = nullptr;
  double slide_bound = 0.0;
};

// Every row, in EffectKind order.
const std::array<EffectRow, kNumEffectKinds>& EffectTable();
const EffectRow& Row(EffectKind kind);
// The row of a name as declared files write it ("joint_axis_tilt_a" finds the axis tilt, and
// sets *axis to 0 for a, 1 for b); nullptr when no effect has that name.
const EffectRow* FindEffect(const std::string& file_name, int* axis = nullptr);
// The name declared files give an effect: the row's, with _a / _b for an axis tilt's axis.
std::string FileName(EffectKind kind, int axis = 0);

// The effects the truth simulates (sim/effects/) that are no row: identification has no
// candidate of their own, and sees them, if at all, as the rows' effects they resemble.
enum class TruthOnlyKind {
  kNeckElasticity,
  kCameraMountSag,
  kNonlinearWrist,
  kImuBias,
};
inline constexpr int kNumTruthOnlyKinds = 4;

struct TruthOnlyRow {
  TruthOnlyKind kind;
  const char* name;  // as scenario files name it (the truth's effects:)
  const char* why;   // why no row stands for it
};

// Every truth-only row, in TruthOnlyKind order.
const std::array<TruthOnlyRow, kNumTruthOnlyKinds>& TruthOnlyTable();
const TruthOnlyRow& Row(TruthOnlyKind kind);

// The stiffening spring's reference torque: its cubic term is t[1] tau^3 / tau0^2, so t[1] is
// the extra deflection at tau0 (rad/Nm, as the linear term).
inline constexpr double kStiffeningTau0Nm = 10.0;

}  // namespace flexbench::kinematics
