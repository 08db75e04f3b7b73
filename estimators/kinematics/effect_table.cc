#include "estimators/kinematics/effect_table.h"

#include "estimators/conventions.h"

// A kind added to EffectKind without its case in a switch below fails to build (and so in the
// switches that hold the kind's maths: effect_model.cc, declared_effects.cc).
#pragma GCC diagnostic error "-Wswitch"

namespace flexbench::kinematics {
namespace {

using E = EffectEntry;
using K = EffectKind;
using T = TruthOnlyKind;
constexpr EffectTruth kSimulated = EffectTruth::kSimulated;
constexpr EffectTruth kFitOnly = EffectTruth::kFitOnly;

// Uniform bounds of n values.
constexpr std::array<double, 6> All(double x) { return {x, x, x, x, x, x}; }

// The bounds are physical: angles within 10 deg (offsets, tilts, joint origins, gravity),
// lengths within 0.1 m, a camera within 0.5 m and 0.5 rad of its stated pose. Signs follow the
// loads (tau_J the torque the joint holds against gravity, M the weight's own moment), so a gear
// spring fits as c = -1/k <= 0 and compliances that sag under their weight as c >= 0.
constexpr std::array<EffectRow, kNumEffectKinds> kTable = {{
    {K::kJointOffset, "joint_offset", 1, "rad", false, E::kReadingToAngle, kSimulated, 1e-6,
     All(-10 * kDeg), All(10 * kDeg), "m", 0.1},
    {K::kJointCompliance, "joint_compliance", 1, "rad/Nm", true, E::kReadingToAngle, kSimulated,
     1e-7, All(-1.0), All(0.0)},
    // Half the play, either sign: the flank convention decides it.
    {K::kBacklash, "backlash", 1, "rad", true, E::kReadingToAngle, kSimulated, 1e-6, All(-5 * kDeg),
     All(5 * kDeg)},
    {K::kLinkLength, "link_length", 1, "m", false, E::kFixedTransform, kFitOnly, 1e-6, All(-0.1),
     All(0.1)},
    {K::kLinkOffset, "link_offset", 3, "m", false, E::kFixedTransform, kFitOnly, 1e-6, All(-0.1),
     All(0.1)},
    {K::kAxisTilt, "joint_axis_tilt", 1, "rad", false, E::kJointAxis, kFitOnly, 1e-6,
     All(-10 * kDeg), All(10 * kDeg)},
    {K::kLinkBending, "link_bending", 1, "rad/Nm", true, E::kFixedTransform, kSimulated, 1e-7,
     All(0.0), All(1.0)},
    {K::kBaseCompliance, "base_compliance", 2, "rad/Nm", true, E::kMountTilt, kSimulated, 1e-7,
     All(0.0), All(1.0)},
    // A strain of 1e-3: about 80 K of steel.
    {K::kThermalExpansion, "thermal_expansion", 1, "-", false, E::kFixedTransform, kSimulated, 1e-6,
     All(-1e-3), All(1e-3)},
    // Mass, then its first moment m c. A gram below zero is zero within the fit's precision (the
    // MUKCa-like data cannot separate it).
    {K::kPayload,
     "payload",
     4,
     "kg, kg m",
     true,
     E::kLoads,
     kSimulated,
     1e-3,
     {-1e-3, -50, -50, -50},
     {100, 50, 50, 50}},
    {K::kCameraOffset, "camera_offset", 6, "m, rad", false, E::kCameraPose, kFitOnly, 1e-6,
     All(-0.5), All(0.5)},
    {K::kJointOrigin,
     "joint_origin",
     6,
     "m, rad",
     false,
     E::kFixedTransform,
     kSimulated,
     1e-6,
     {-0.1, -0.1, -0.1, -10 * kDeg, -10 * kDeg, -10 * kDeg},
     {0.1, 0.1, 0.1, 10 * kDeg, 10 * kDeg, 10 * kDeg}},
    {K::kTransmissionError, "transmission_error", 4, "rad", false, E::kReadingToAngle, kSimulated,
     1e-6, All(-1 * kDeg), All(1 * kDeg)},
    {K::kJointErrorCurve, "joint_error_curve", 6, "rad", false, E::kReadingToAngle, kFitOnly, 1e-6,
     All(-1 * kDeg), All(1 * kDeg)},
    // Linear and cubic compliance: a spring that stiffens with the load.
    {K::kStiffeningSpring,
     "stiffening_spring",
     2,
     "rad/Nm",
     true,
     E::kReadingToAngle,
     kSimulated,
     1e-7,
     {-1.0, 0.0},
     {0.0, 1.0}},
    {K::kGravityTilt, "gravity_tilt", 2, "rad", true, E::kLoads, kFitOnly, 1e-6, All(-10 * kDeg),
     All(10 * kDeg)},
    // At most a bearing stiffness of 100 N m/rad: 10 N m would tip the joint by 6 deg, a broken
    // joint rather than a compliant one.
    {K::kLateralCompliance, "lateral_compliance", 2, "rad/Nm", true, E::kJointAxis, kSimulated,
     1e-7, All(0.0), All(1e-2)},
}};

constexpr std::array<TruthOnlyRow, kNumTruthOnlyKinds> kTruthOnly = {{
    {T::kNeckElasticity, "neck_elasticity",
     "a neck of many spring joints: no one location's compliance"},
    {T::kCameraMountSag, "camera_mount_sag",
     "the camera's pose moving with its weight: camera_offset is a constant pose error"},
    {T::kNonlinearWrist, "nonlinear_wrist",
     "a linkage the declared model states (coupled:), not one identification finds"},
    {T::kImuBias, "imu_bias", "a sensor's error, not the kinematics'"},
}};

// Whether k is an enumerator of EffectKind: every one has its case (the switch has no default).
constexpr bool IsEffectKind(EffectKind k) {
  switch (k) {
    case K::kJointOffset:
    case K::kJointCompliance:
    case K::kBacklash:
    case K::kLinkLength:
    case K::kLinkOffset:
    case K::kAxisTilt:
    case K::kLinkBending:
    case K::kBaseCompliance:
    case K::kThermalExpansion:
    case K::kPayload:
    case K::kCameraOffset:
    case K::kJointOrigin:
    case K::kTransmissionError:
    case K::kJointErrorCurve:
    case K::kStiffeningSpring:
    case K::kGravityTilt:
    case K::kLateralCompliance:
      return true;
  }
  return false;
}

constexpr bool IsTruthOnlyKind(TruthOnlyKind k) {
  switch (k) {
    case T::kNeckElasticity:
    case T::kCameraMountSag:
    case T::kNonlinearWrist:
    case T::kImuBias:
      return true;
  }
  return false;
}

// The enumerators of an enum whose values run from 0 (scanning past the last one).
template <class Kind>
constexpr int CountKinds(bool (*is_kind)(Kind)) {
  int n = 0;
  for (int i = 0; i < 256; ++i) n += is_kind(static_cast<Kind>(i)) ? 1 : 0;
  return n;
}

// Every row in its place (a missing row is zero-initialised: no name), with its values' count
// and bounds in order.
constexpr bool RowsComplete() {
  for (int i = 0; i < kNumEffectKinds; ++i) {
    const EffectRow& r = kTable[i];
    if (static_cast<int>(r.kind) != i || r.name == nullptr || r.unit == nullptr) return false;
    if (r.num_values < 1 || r.num_values > 6 || !(r.fd_step > 0.0)) return false;
    for (int k = 0; k < r.num_values; ++k) {
      if (!(r.lower[k] <= r.upper[k])) return false;
    }
  }
  for (int i = 0; i < kNumTruthOnlyKinds; ++i) {
    const TruthOnlyRow& r = kTruthOnly[i];
    if (static_cast<int>(r.kind) != i || r.name == nullptr || r.why == nullptr) return false;
  }
  return true;
}

static_assert(CountKinds(IsEffectKind) == kNumEffectKinds,
              "kNumEffectKinds must count every EffectKind: each kind needs its row");
static_assert(CountKinds(IsTruthOnlyKind) == kNumTruthOnlyKinds,
              "kNumTruthOnlyKinds must count every TruthOnlyKind: each kind needs its row");
static_assert(RowsComplete(), "every kind needs its row, in kind order, with its values' bounds");

}  // namespace

const std::array<EffectRow, kNumEffectKinds>& EffectTable() { return kTable; }

const EffectRow& Row(EffectKind kind) { return kTable[static_cast<int>(kind)]; }

const std::array<TruthOnlyRow, kNumTruthOnlyKinds>& TruthOnlyTable() { return kTruthOnly; }

const TruthOnlyRow& Row(TruthOnlyKind kind) { return kTruthOnly[static_cast<int>(kind)]; }

const EffectRow* FindEffect(const std::string& file_name, int* axis) {
  for (const EffectRow& r : kTable) {
    const int n = r.kind == K::kAxisTilt ? 2 : 1;
    for (int a = 0; a < n; ++a) {
      if (file_name != FileName(r.kind, a)) continue;
      if (axis != nullptr) *axis = a;
      return &r;
    }
  }
  return nullptr;
}

std::string FileName(EffectKind kind, int axis) {
  const std::string name = Row(kind).name;
  if (kind != K::kAxisTilt) return name;
  return name + (axis == 0 ? "_a" : "_b");
}

}  // namespace flexbench::kinematics
