// Extrinsic Tait-Bryan angles against SciPy 1.10's Rotation.as_euler (the values below were
// printed by scipy.spatial.transform), including its gimbal-lock convention (yaw := 0).
#include "estimators/imu/euler.h"

#include <gtest/gtest.h>

#include <random>

#include "estimators/error.h"

namespace flexbench::imu {
namespace {

struct ScipyCase {
  double xyzw[4];
  double xyz[3];
  double yxz[3];
};

// R.as_quat(), R.as_euler('xyz'), R.as_euler('yxz') for: a generic quaternion;
// from_euler('xyz', [0.3, -1.2, 2.0]); from_euler('yz', [pi/2, 0.7]) (xyz gimbal lock);
// from_euler('yz', [-pi/2, -0.4]) (xyz gimbal lock); from_euler('xyz', [0.01, pi/2 - 1e-4, 0.7])
// (near the lock); from_euler('yxz', [2.5, -0.4, -3.0]).
const ScipyCase kCases[] = {
    {{0.10259783520851541, 0.20519567041703082, 0.3077935056255462, 0.9233805168766387},
     {0.3392926144540447, 0.3212885892648105, 0.6989996140390012},
     {0.33929261445404446, 0.3212885892648103, 0.5880026035475674}},
    {{0.5364341138911902, -0.19786775626458644, 0.7322877628656068, 0.3699208359120593},
     {0.29999999999999993, -1.2000000000000004, 2.0},
     {-1.215172097254859, 0.10728975709398103, 2.280701030029996}},
    {{-0.24246536490574871, 0.664236815315985, 0.24246536490574874, 0.6642368153159851},
     {-0.7000000000000001, 1.5707963118937354, 0.0},
     {1.5707963267948966, 0.0, 0.6999999999999997}},
    {{-0.14048043101898117, -0.6930117232058353, -0.1404804310189812, 0.6930117232058354},
     {-0.4, -1.5707963267948966, 0.0},
     {-1.5707963267948963, 0.0, -0.40000000000000036}},
    {{-0.23912887438253336, 0.6654076825049475, 0.23915345273295652, 0.66547398412398},
     {0.010000000000547014, 1.5706963267951588, 0.7000000000008283},
     {1.5706963317948546, 9.999833316953755e-07, 0.6900000000499964}},
    {{0.9233069515427893, 0.12827837179401416, -0.3215991444638238, -0.16620145258924368},
     {-2.6560023662570216, 0.5838369352580979, 0.4246839154427067},
     {2.5, -0.40000000000000036, -3.0}},
};

Mat3 FromXyzw(const double* q) {
  return Quat(q[3], q[0], q[1], q[2]).normalized().toRotationMatrix();
}

TEST(Euler, MatchesScipy) {
  int index = 0;
  for (const ScipyCase& c : kCases) {
    const Mat3 R = FromXyzw(c.xyzw);
    const Vec3 xyz = EulerFromRotation(R, EulerOrder::kXYZ);
    const Vec3 yxz = EulerFromRotation(R, EulerOrder::kYXZ);
    // Near the lock the angles are ill-conditioned in the quaternion's last digits.
    const double tol = index == 4 ? 1e-7 : 1e-9;
    for (int k = 0; k < 3; ++k) {
      // SciPy takes the middle angle from an arccos, which loses half the digits at the lock.
      const double tol_k = (index == 2 || index == 3) && k == 1 ? 3e-8 : tol;
      EXPECT_NEAR(xyz(k), c.xyz[k], tol_k) << "case " << index << " xyz " << k;
      EXPECT_NEAR(yxz(k), c.yxz[k], tol_k) << "case " << index << " yxz " << k;
    }
    ++index;
  }
}

TEST(Euler, RoundTripsAwayFromTheLock) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> a(-M_PI, M_PI), b(-1.5, 1.5);
  for (EulerOrder order : {EulerOrder::kXYZ, EulerOrder::kYXZ}) {
    for (int i = 0; i < 200; ++i) {
      const Vec3 angles(a(rng), b(rng), a(rng));
      const Mat3 R = RotationFromEuler(angles, order);
      bool locked = true;
      EXPECT_TRUE(EulerFromRotation(R, order, &locked).isApprox(angles, 1e-12));
      EXPECT_FALSE(locked);
    }
  }
}

TEST(Euler, GimbalLockPutsTheYawIntoTheFirstAngle) {
  // A link pitched by 90 deg and yawed: 'xyz' is locked and cannot cancel the yaw, 'yxz' can.
  const Mat3 R = RotationFromEuler(Vec3(M_PI / 2, 0.0, 0.6), EulerOrder::kYXZ);  // Rz Rx Ry
  bool locked = false;
  const Vec3 xyz = EulerFromRotation(R, EulerOrder::kXYZ, &locked);
  EXPECT_TRUE(locked);
  EXPECT_EQ(xyz(2), 0.0);
  EXPECT_TRUE(RotationFromEuler(xyz, EulerOrder::kXYZ).isApprox(R, 1e-12));
  const Mat3 pitch_only = Eigen::AngleAxisd(M_PI / 2, Vec3::UnitY()).toRotationMatrix();
  EXPECT_TRUE(CancelYaw(R, EulerOrder::kYXZ).isApprox(pitch_only, 1e-12));
  EXPECT_FALSE(CancelYaw(R, EulerOrder::kXYZ).isApprox(pitch_only, 1e-3));
}

TEST(Euler, ParseOrder) {
  EXPECT_EQ(ParseEulerOrder("xyz", "t"), EulerOrder::kXYZ);
  EXPECT_EQ(ParseEulerOrder("yxz", "t"), EulerOrder::kYXZ);
  EXPECT_THROW(ParseEulerOrder("zyx", "t"), InputError);
  EXPECT_STREQ(ToString(EulerOrder::kYXZ), "yxz");
}

}  // namespace
}  // namespace flexbench::imu
