// The IMUs' orientation filters on the estimator side: each IMU's raw readings run its own
// Madgwick filter exactly as the filter run by hand (the same bits), started from the given
// orientation or the first accelerometer reading; readings the filter cannot take are refused
// and leave it as it was.
#include "estimators/imu/imu_orientations.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "estimators/error.h"

namespace flexbench::imu {
namespace {

using estimators::ImuReading;
using estimators::ImuSetup;
using estimators::UpdateStatus;

bool SameBits(const Quat& a, const Quat& b) {
  return std::memcmp(a.coeffs().data(), b.coeffs().data(), 4 * sizeof(double)) == 0;
}

std::vector<ImuSetup> TwoImus() {
  std::vector<ImuSetup> imus(2);
  imus[0].frame = 3;
  imus[0].filter_beta = 0.07;
  imus[1].frame = 5;
  imus[1].has_initial = true;
  imus[1].q_base_frame_initial = Quat(Eigen::AngleAxisd(0.6, Vec3(1, 2, 3).normalized()));
  return imus;
}

TEST(ImuOrientations, EachImuRunsItsOwnMadgwickBitForBit) {
  const std::vector<ImuSetup> imus = TwoImus();
  ImuOrientations f(imus);
  Madgwick by_hand[2] = {Madgwick(0.07), Madgwick(0.05)};
  double last_t[2] = {0.0, 0.0};
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < 400; ++i) {
    ImuReading z;
    z.imu = i % 2;
    z.t = 0.0025 * i + 1e-4 * z.imu;
    z.gyro = Vec3(n(rng), n(rng), n(rng)) * 0.3 + Vec3(0.0, 0.0, 0.2);  // yaw: unseen by accel
    z.accel = Vec3(0.5 * n(rng), 0.5 * n(rng), 9.81);
    ASSERT_EQ(f.Feed(z), UpdateStatus::kAccepted);
    Madgwick& m = by_hand[z.imu];
    if (i < 2) {
      if (z.imu == 0) m.InitFromAccel(z.accel);
      if (z.imu == 1) m.Reset(imus[1].q_base_frame_initial);
    } else {
      m.Update(z.gyro, z.accel, z.t - last_t[z.imu]);
    }
    last_t[z.imu] = z.t;
    EXPECT_TRUE(f.fresh(z.imu));
    const estimators::OrientationReading o = f.Take(z.imu);
    EXPECT_FALSE(f.fresh(z.imu));
    EXPECT_EQ(o.frame, imus[z.imu].frame);
    EXPECT_EQ(o.t, z.t);
    ASSERT_TRUE(SameBits(o.q_base_frame, m.orientation())) << "reading " << i;
  }
  // The filters moved (the readings were not at rest).
  EXPECT_GT(by_hand[0].orientation().angularDistance(Quat::Identity()), 0.05);
  EXPECT_GT(by_hand[1].orientation().angularDistance(imus[1].q_base_frame_initial), 0.05);
}

TEST(ImuOrientations, ReadingsItCannotTakeAreRefusedAndLeaveTheFilter) {
  ImuOrientations f(TwoImus());
  ImuReading z;
  z.imu = 0;
  z.t = 1.0;
  EXPECT_EQ(f.Feed(z), UpdateStatus::kRejectedOutside);  // no "up" to start from
  EXPECT_FALSE(f.ready(0));
  z.accel = Vec3(0.0, 0.0, 9.81);
  z.gyro = Vec3(0.0, std::nan(""), 0.0);
  EXPECT_EQ(f.Feed(z), UpdateStatus::kRejectedNonFinite);
  EXPECT_FALSE(f.ready(0));
  z.gyro = Vec3(0.1, 0.0, 0.0);
  EXPECT_EQ(f.Feed(z), UpdateStatus::kAccepted);
  const Quat q = f.Take(0).q_base_frame;
  z.t = 0.5;  // before the last reading
  EXPECT_EQ(f.Feed(z), UpdateStatus::kRejectedOutside);
  z.t = 1.1;
  z.accel.x() = std::numeric_limits<double>::infinity();
  EXPECT_EQ(f.Feed(z), UpdateStatus::kRejectedNonFinite);
  EXPECT_FALSE(f.fresh(0));
  EXPECT_TRUE(SameBits(f.Take(0).q_base_frame, q));
  z.imu = 2;
  EXPECT_THROW(f.Feed(z), InputError);
  f.Reset();
  EXPECT_FALSE(f.ready(0));
  std::vector<ImuSetup> bad = TwoImus();
  bad[0].filter_beta = 0.0;
  EXPECT_THROW(ImuOrientations{bad}, InputError);
  bad = TwoImus();
  bad[1].q_base_frame_initial = Quat(0.0, 0.0, 0.0, 0.0);
  EXPECT_THROW(ImuOrientations{bad}, InputError);
}

}  // namespace
}  // namespace flexbench::imu
