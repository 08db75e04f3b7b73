// Madgwick's 6-axis filter: a static tilt converges to the accelerometer's roll and pitch; pure
// gyro rotation integrates exactly; a gyro bias about the vertical makes the yaw drift at the
// bias rate while roll and pitch stay put (the drift the axis-symmetric Bingham absorbs).
#include "estimators/imu/madgwick.h"

#include <gtest/gtest.h>

#include <cmath>

#include "estimators/error.h"

namespace flexbench::imu {
namespace {

constexpr double kG = 9.81;

// Specific force of a sensor at rest with orientation q_earth_sensor: +g up, in the sensor frame.
Vec3 AccelAtRest(const Quat& q) { return q.inverse() * Vec3(0.0, 0.0, kG); }

// Angle between the sensor's up axes of two orientations (tilt only, yaw ignored).
double TiltError(const Quat& a, const Quat& b) {
  const Vec3 ua = a.inverse() * Vec3::UnitZ();
  const Vec3 ub = b.inverse() * Vec3::UnitZ();
  return std::acos(std::clamp(ua.dot(ub), -1.0, 1.0));
}

double Yaw(const Quat& q) {
  const Mat3 R = q.toRotationMatrix();
  return std::atan2(R(1, 0), R(0, 0));
}

TEST(Madgwick, StaticTiltConverges) {
  const Quat truth =
      Quat(Eigen::AngleAxisd(0.4, Vec3::UnitZ()) * Eigen::AngleAxisd(0.9, Vec3::UnitY()) *
           Eigen::AngleAxisd(-0.3, Vec3::UnitX()));
  Madgwick f(0.1);
  f.Reset();
  const double dt = 0.005;
  for (int k = 0; k < 6000; ++k) f.Update(Vec3::Zero(), AccelAtRest(truth), dt);  // 30 s
  // The normalised gradient step leaves a jitter of about beta * dt.
  EXPECT_LT(TiltError(f.orientation(), truth), 2.0 * 0.1 * dt);
  // Initialising from the accelerometer is immediate.
  Madgwick g(0.1);
  g.InitFromAccel(AccelAtRest(truth));
  EXPECT_LT(TiltError(g.orientation(), truth), 1e-12);
}

TEST(Madgwick, GyroIntegration) {
  // Rotating about the vertical at 0.5 rad/s for 2 s, accelerometer consistent with rest.
  Madgwick f(0.05);
  f.Reset();
  const double dt = 0.001;
  Quat truth = Quat::Identity();
  const Vec3 omega(0.0, 0.0, 0.5);
  for (int k = 0; k < 2000; ++k) {
    truth = truth * Quat(Eigen::AngleAxisd(omega.norm() * dt, omega.normalized()));
    f.Update(omega, AccelAtRest(truth), dt);
  }
  EXPECT_NEAR(Yaw(f.orientation()), 1.0, 1e-6);
  EXPECT_LT(TiltError(f.orientation(), truth), 1e-9);
}

TEST(Madgwick, YawDriftsWithAVerticalGyroBias) {
  const Quat truth = Quat(Eigen::AngleAxisd(0.7, Vec3::UnitY()));  // a pitched link, at rest
  Madgwick f(0.1);
  f.Reset(truth);
  const double bias = 0.002;  // rad/s about the earth's vertical, seen in the sensor frame
  const Vec3 gyro = truth.inverse() * Vec3(0.0, 0.0, bias);
  const double dt = 0.005;
  for (int k = 0; k < 20000; ++k) f.Update(gyro, AccelAtRest(truth), dt);  // 100 s
  EXPECT_NEAR(Yaw(f.orientation()) - Yaw(truth), bias * 100.0, 1e-3);
  EXPECT_LT(TiltError(f.orientation(), truth), 1e-4);
}

TEST(Madgwick, BadInput) {
  EXPECT_THROW(Madgwick(0.0), InputError);
  EXPECT_THROW(Madgwick(NAN), InputError);
  Madgwick f(0.1);
  EXPECT_THROW(f.InitFromAccel(Vec3::Zero()), InputError);
  EXPECT_THROW(f.Reset(Quat(0.0, 0.0, 0.0, 0.0)), InputError);
  const Quat before = f.orientation();
  EXPECT_FALSE(f.Update(Vec3(NAN, 0.0, 0.0), Vec3(0.0, 0.0, kG), 0.01));
  EXPECT_FALSE(f.Update(Vec3::Zero(), Vec3(0.0, 0.0, kG), -1.0));
  EXPECT_TRUE(f.orientation().coeffs().isApprox(before.coeffs()));
  EXPECT_TRUE(f.Update(Vec3(0.1, 0.0, 0.0), Vec3::Zero(), 0.01));  // free fall: gyro only
}

}  // namespace
}  // namespace flexbench::imu
