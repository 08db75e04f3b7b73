#include "estimators/imu/madgwick.h"

#include <cmath>
#include <sstream>

#include "estimators/error.h"

namespace flexbench::imu {

Madgwick::Madgwick(double beta) : beta_(beta) {
  if (!(beta > 0.0) || !std::isfinite(beta)) {
    std::ostringstream msg;
    msg << "Madgwick: beta must be finite and > 0, got " << beta;
    throw InputError(msg.str());
  }
}

void Madgwick::Reset(const Quat& q) {
  const double n = q.norm();
  if (!std::isfinite(n) || !(n > 0.0)) throw InputError("Madgwick: orientation is zero or NaN");
  q_ = q.normalized();
}

void Madgwick::InitFromAccel(const Vec3& accel) {
  const double n = accel.norm();
  if (!std::isfinite(n) || !(n > 0.0)) {
    throw InputError("Madgwick: cannot initialise from a zero or non-finite accelerometer");
  }
  // The rotation taking the measured up direction (sensor frame) to the earth's z.
  q_ = Quat::FromTwoVectors(accel / n, Vec3::UnitZ()).normalized();
}

bool Madgwick::Update(const Vec3& gyro, const Vec3& accel, double dt) {
  if (!gyro.allFinite() || !accel.allFinite() || !std::isfinite(dt) || dt < 0.0) return false;
  const double w = q_.w(), x = q_.x(), y = q_.y(), z = q_.z();
  // q_dot = 1/2 q (x) (0, omega), components (w, x, y, z).
  double dw = 0.5 * (-x * gyro.x() - y * gyro.y() - z * gyro.z());
  double dx = 0.5 * (w * gyro.x() + y * gyro.z() - z * gyro.y());
  double dy = 0.5 * (w * gyro.y() - x * gyro.z() + z * gyro.x());
  double dz = 0.5 * (w * gyro.z() + x * gyro.y() - y * gyro.x());
  const double an = accel.norm();
  if (an > 0.0) {
    const Vec3 a = accel / an;
    // f = R(q)^T e_z - a: the third row of R(q), minus the measured up direction.
    const double f0 = 2.0 * (x * z - w * y) - a.x();
    const double f1 = 2.0 * (w * x + y * z) - a.y();
    const double f2 = 1.0 - 2.0 * (x * x + y * y) - a.z();
    // Gradient J^T f with respect to (w, x, y, z).
    double gw = -2.0 * y * f0 + 2.0 * x * f1;
    double gx = 2.0 * z * f0 + 2.0 * w * f1 - 4.0 * x * f2;
    double gy = -2.0 * w * f0 + 2.0 * z * f1 - 4.0 * y * f2;
    double gz = 2.0 * x * f0 + 2.0 * y * f1;
    const double gn = std::sqrt(gw * gw + gx * gx + gy * gy + gz * gz);
    if (gn > 0.0) {
      dw -= beta_ * gw / gn;
      dx -= beta_ * gx / gn;
      dy -= beta_ * gy / gn;
      dz -= beta_ * gz / gn;
    }
  }
  Quat next(w + dw * dt, x + dx * dt, y + dy * dt, z + dz * dt);
  next.normalize();
  q_ = next;
  return true;
}

}  // namespace flexbench::imu
