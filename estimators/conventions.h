// The one place where flexbench's conventions are written in code (docs/design.md, "Conventions").
// tests/unit/conventions/ pins every statement here.
//
// - SE(3) tangent vectors are xi = [rho; theta]: translation first, rotation second
//   [PPOE eq. 2]. Index ranges below name the two blocks.
// - Perturbations are right-multiplied (local): X = Xbar * Exp(xi). Covariances live in the
//   tangent space at Xbar; Ad_X [PPOE eq. 7] maps them to the global frame [PPOE eq. 10].
// - Quaternions: MuJoCo stores (w, x, y, z); Eigen's coeffs() are (x, y, z, w); the
//   particle-filter paper writes (x, y, z, w) with w >= 0. Convert only at boundaries, with the
//   helpers below, never by indexing raw arrays elsewhere.
// - Frames in names: T_a_b is the pose of frame b expressed in frame a; p_a is a point in a.
// - SI units everywhere (m, rad, s).
// - Angles of von Mises variables are wrapped to [-pi, pi).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace flexbench {

using Vec3 = Eigen::Vector3d;
using Vec4 = Eigen::Vector4d;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat3 = Eigen::Matrix3d;
using Mat4 = Eigen::Matrix4d;
using Mat6 = Eigen::Matrix<double, 6, 6>;
using Quat = Eigen::Quaterniond;

// Radians in a degree: deg * kDeg is rad, rad / kDeg is deg (files and messages speak degrees).
inline constexpr double kDeg = M_PI / 180.0;

// Block offsets of xi = [rho; theta].
inline constexpr int kTransIdx = 0;
inline constexpr int kRotIdx = 3;

// MuJoCo (w, x, y, z) array -> Eigen quaternion.
inline Quat QuatFromWxyz(const double* wxyz) { return Quat(wxyz[0], wxyz[1], wxyz[2], wxyz[3]); }

// Eigen quaternion -> MuJoCo (w, x, y, z) array.
inline void QuatToWxyz(const Quat& q, double* wxyz) {
  wxyz[0] = q.w();
  wxyz[1] = q.x();
  wxyz[2] = q.y();
  wxyz[3] = q.z();
}

// Eigen quaternion -> the particle-filter paper's (x, y, z, w) with w >= 0 (q and -q are the
// same rotation; the Bingham density is antipodally symmetric, the sign is for readability).
inline Vec4 QuatToXyzwPositive(const Quat& q) {
  Vec4 v(q.x(), q.y(), q.z(), q.w());
  return q.w() < 0.0 ? Vec4(-v) : v;
}

// The paper's (x, y, z, w) -> Eigen quaternion.
inline Quat QuatFromXyzw(const Vec4& xyzw) { return Quat(xyzw[3], xyzw[0], xyzw[1], xyzw[2]); }

// MuJoCo's row-major 3x3 (xmat) -> Eigen matrix.
inline Mat3 RotFromRowMajor(const double* xmat) {
  Mat3 R;
  R << xmat[0], xmat[1], xmat[2], xmat[3], xmat[4], xmat[5], xmat[6], xmat[7], xmat[8];
  return R;
}

// Homogeneous transform from rotation and translation.
inline Mat4 MakeTransform(const Mat3& R, const Vec3& t) {
  Mat4 T = Mat4::Identity();
  T.topLeftCorner<3, 3>() = R;
  T.topRightCorner<3, 1>() = t;
  return T;
}

// Wraps an angle to [-pi, pi).
inline double WrapAngle(double a) {
  constexpr double kTwoPi = 2.0 * M_PI;
  double w = std::fmod(a + M_PI, kTwoPi);
  if (w < 0.0) w += kTwoPi;
  // Just below -pi, fmod gives -ulp and -ulp + 2 pi rounds up to 2 pi: that +pi is -pi.
  const double r = w - M_PI;
  return r >= M_PI ? -M_PI : r;
}

}  // namespace flexbench
