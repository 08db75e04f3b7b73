// Tait-Bryan angles about fixed (extrinsic) axes, with the gimbal-lock convention of SciPy's
// Rotation.as_euler, which the particle-filter paper's direct-fusion baseline used (sec. IV-D):
//
//   order "xyz": R = Rz(a3) Ry(a2) Rx(a1);   order "yxz": R = Rz(a3) Rx(a2) Ry(a1),
//
// angles[k] about the k-th letter. The last extrinsic rotation is about the world z axis, i.e.
// the yaw. The middle angle is in [-pi/2, pi/2]; at gimbal lock (middle angle within
// kGimbalLockTol of +-pi/2) the first and third axes coincide and only their sum or difference
// is defined: as SciPy does for extrinsic sequences, the third angle (the yaw) is set to 0 and
// the whole rotation about the shared axis goes into the first angle. Close to the lock the
// decomposition is exact but ill-conditioned: a small tilt error moves the first and third
// angles by large, opposite amounts.
#pragma once

#include <string>

#include "estimators/conventions.h"

namespace flexbench::imu {

enum class EulerOrder { kXYZ, kYXZ };

inline constexpr double kGimbalLockTol = 1e-7;

// "xyz" or "yxz" (InputError otherwise, naming `what`).
EulerOrder ParseEulerOrder(const std::string& text, const std::string& what);
const char* ToString(EulerOrder order);

// Angles (a1, a2, a3) of R for the order; `gimbal_lock` reports the degenerate case.
Vec3 EulerFromRotation(const Mat3& R, EulerOrder order, bool* gimbal_lock = nullptr);
Mat3 RotationFromEuler(const Vec3& angles, EulerOrder order);

// The paper's steps 2-4: decompose, set the yaw (the last, z angle) to 0, recompose.
Mat3 CancelYaw(const Mat3& R, EulerOrder order);

}  // namespace flexbench::imu
