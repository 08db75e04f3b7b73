// Madgwick's orientation filter for a 6-axis IMU (gyro + accelerometer, no magnetometer):
// S. Madgwick, "An efficient orientation filter for inertial and inertial/magnetic sensor
// arrays", 2010 (the particle-filter paper's ref. [19], used "without magnetic option").
//
// The orientation q = q_earth_sensor maps sensor-frame vectors to the earth frame (z up), as an
// Eigen quaternion. Each update integrates the gyro, q_dot = 1/2 q (x) (0, omega), and takes one
// normalised gradient step of size beta (rad/s) on
//
//   F(q) = 1/2 | R(q)^T e_z - a / |a| |^2,
//
// the mismatch between the predicted and the measured direction of "up" in the sensor frame (the
// accelerometer measures the specific force, +g up at rest). F does not change when q is rotated
// about the earth's z axis, so yaw is driven by the gyro alone: a gyro bias along the vertical
// makes the yaw drift at the bias rate, which is the drift the paper's axis-symmetric Bingham
// absorbs (sec. IV-E). Roll and pitch converge to the accelerometer's at a rate set by beta.
#pragma once

#include "estimators/conventions.h"

namespace flexbench::imu {

class Madgwick {
 public:
  // beta > 0 and finite (InputError otherwise). Madgwick suggests beta = sqrt(3/4) * (gyro
  // error, rad/s).
  explicit Madgwick(double beta = 0.1);

  double beta() const { return beta_; }
  // Sets the orientation (normalised; InputError when not finite or zero).
  void Reset(const Quat& q_earth_sensor = Quat::Identity());
  // The orientation whose "up" matches the accelerometer, with the smallest rotation (no yaw
  // about the vertical). InputError for a zero or non-finite reading.
  void InitFromAccel(const Vec3& accel);
  // One step of dt seconds (dt >= 0). Non-finite inputs leave the state unchanged and return
  // false. A zero accelerometer reading (free fall) integrates the gyro only.
  bool Update(const Vec3& gyro, const Vec3& accel, double dt);

  const Quat& orientation() const { return q_; }

 private:
  double beta_;
  Quat q_ = Quat::Identity();
};

}  // namespace flexbench::imu
