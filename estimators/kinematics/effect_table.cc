#include "estimators/kinematics/effect_table.h"

#include "estimators/conventions.h"

namespace flexbench::kinematics {
namespace {

using E = EffectEntry;
using K = EffectKind;

// Uniform bounds of n values.
constexpr std::array<double, 6> All(double x) { return {x, x, x, x, x, x}; }

}  // namespace

const std::array<EffectRow, kNumEffectKinds>& EffectTable() {
  static const std::array<EffectRow, kNumEffectKinds> table = {{
      {K::kJointOffset, "joint_offset", 1, "rad", false, E::kReadingToAngle, 1e-6, All(-10 * kDeg),
       All(10 * kDeg)},
      {K::kJointCompliance, "joint_compliance", 1, "rad/Nm", true, E::kReadingToAngle, 1e-7,
       All(-1.0), All(0.0)},
      {K::kBacklash, "backlash", 1, "rad", true, E::kReadingToAngle, 1e-6, All(-5 * kDeg),
       All(5 * kDeg)},
      {K::kLinkLength, "link_length", 1, "m", false, E::kFixedTransform, 1e-6, All(-0.1), All(0.1)},
      {K::kLinkOffset, "link_offset", 3, "m", false, E::kFixedTransform, 1e-6, All(-0.1), All(0.1)},
      {K::kAxisTilt, "joint_axis_tilt", 1, "rad", false, E::kJointAxis, 1e-6, All(-10 * kDeg),
       All(10 * kDeg)},
      {K::kLinkBending, "link_bending", 1, "rad/Nm", true, E::kFixedTransform, 1e-7, All(0.0),
       All(1.0)},
      {K::kBaseCompliance, "base_compliance", 2, "rad/Nm", true, E::kMountTilt, 1e-7, All(0.0),
       All(1.0)},
      {K::kThermalExpansion, "thermal_expansion", 1, "-", false, E::kFixedTransform, 1e-6,
       All(-1e-3), All(1e-3)},
      // Mass, then its first moment m c.
      {K::kPayload,
       "payload",
       4,
       "kg, kg m",
       true,
       E::kLoads,
       1e-3,
       {-1e-3, -50, -50, -50},
       {100, 50, 50, 50}},
      {K::kCameraOffset, "camera_offset", 6, "m, rad", false, E::kCameraPose, 1e-6, All(-0.5),
       All(0.5)},
      {K::kJointOrigin,
       "joint_origin",
       6,
       "m, rad",
       false,
       E::kFixedTransform,
       1e-6,
       {-0.1, -0.1, -0.1, -10 * kDeg, -10 * kDeg, -10 * kDeg},
       {0.1, 0.1, 0.1, 10 * kDeg, 10 * kDeg, 10 * kDeg}},
      {K::kTransmissionError, "transmission_error", 4, "rad", false, E::kReadingToAngle, 1e-6,
       All(-1 * kDeg), All(1 * kDeg)},
      {K::kJointErrorCurve, "joint_error_curve", 6, "rad", false, E::kReadingToAngle, 1e-6,
       All(-1 * kDeg), All(1 * kDeg)},
      // Linear and cubic compliance: a spring that stiffens with the load.
      {K::kStiffeningSpring,
       "stiffening_spring",
       2,
       "rad/Nm",
       true,
       E::kReadingToAngle,
       1e-7,
       {-1.0, 0.0},
       {0.0, 1.0}},
      {K::kGravityTilt, "gravity_tilt", 2, "rad", true, E::kLoads, 1e-6, All(-10 * kDeg),
       All(10 * kDeg)},
      {K::kLateralCompliance, "lateral_compliance", 2, "rad/Nm", true, E::kJointAxis, 1e-7,
       All(0.0), All(1e-2)},
  }};
  return table;
}

const EffectRow& Row(EffectKind kind) { return EffectTable()[static_cast<int>(kind)]; }

const EffectRow* FindEffect(const std::string& file_name) {
  for (const EffectRow& r : EffectTable()) {
    if (file_name == r.name) return r.kind == K::kAxisTilt ? nullptr : &r;
    if (r.kind == K::kAxisTilt &&
        (file_name == std::string(r.name) + "_a" || file_name == std::string(r.name) + "_b")) {
      return &r;
    }
  }
  return nullptr;
}

}  // namespace flexbench::kinematics
