#include "estimators/imu/euler.h"

#include <cmath>

#include "estimators/error.h"

namespace flexbench::imu {
namespace {

struct Axes {
  int i, j, k;  // first, middle, last (= z) axis
  double eps;   // +1 for an even permutation of (x, y, z), -1 for odd
};

Axes AxesOf(EulerOrder order) {
  return order == EulerOrder::kXYZ ? Axes{0, 1, 2, 1.0} : Axes{1, 0, 2, -1.0};
}

// Rotation by `angle` about coordinate axis `axis`.
Mat3 Elementary(int axis, double angle) {
  const int a = (axis + 1) % 3, b = (axis + 2) % 3;
  const double c = std::cos(angle), s = std::sin(angle);
  Mat3 R = Mat3::Zero();
  R(axis, axis) = 1.0;
  R(a, a) = c;
  R(a, b) = -s;
  R(b, a) = s;
  R(b, b) = c;
  return R;
}

}  // namespace

EulerOrder ParseEulerOrder(const std::string& text, const std::string& what) {
  if (text == "xyz") return EulerOrder::kXYZ;
  if (text == "yxz") return EulerOrder::kYXZ;
  throw InputError(what + ": Euler order must be 'xyz' or 'yxz', got '" + text + "'");
}

const char* ToString(EulerOrder order) { return order == EulerOrder::kXYZ ? "xyz" : "yxz"; }

Vec3 EulerFromRotation(const Mat3& R, EulerOrder order, bool* gimbal_lock) {
  const Axes ax = AxesOf(order);
  const int i = ax.i, j = ax.j, k = ax.k;
  const double eps = ax.eps;
  // R = R_k(a3) R_j(a2) R_i(a1): row k of R is (R_j(a2) R_i(a1)) row k, whose entry i is
  // -eps sin(a2) and whose entries j, k are eps cos(a2) sin(a1), cos(a2) cos(a1).
  const double sin_b = -eps * R(k, i);
  const double cos_b = std::hypot(R(k, j), R(k, k));
  const double b = std::atan2(sin_b, cos_b);
  const bool locked = cos_b < kGimbalLockTol;
  if (gimbal_lock) *gimbal_lock = locked;
  double a1, a3;
  if (!locked) {
    a1 = std::atan2(eps * R(k, j), R(k, k));
    a3 = std::atan2(eps * R(j, i), R(i, i));
  } else {
    // SciPy's extrinsic convention: the yaw is 0 and R_j(a2)^T R = R_i(a1) carries the rest.
    a3 = 0.0;
    const Mat3 M = Elementary(j, b).transpose() * R;
    const int p = (i + 1) % 3, q = (i + 2) % 3;
    a1 = std::atan2(M(q, p), M(p, p));
  }
  return Vec3(a1, b, a3);
}

Mat3 RotationFromEuler(const Vec3& angles, EulerOrder order) {
  const Axes ax = AxesOf(order);
  return Elementary(ax.k, angles(2)) * Elementary(ax.j, angles(1)) * Elementary(ax.i, angles(0));
}

Mat3 CancelYaw(const Mat3& R, EulerOrder order) {
  Vec3 a = EulerFromRotation(R, order);
  a(2) = 0.0;
  return RotationFromEuler(a, order);
}

}  // namespace flexbench::imu
