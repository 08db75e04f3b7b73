// Where a log's IMU is at rest (identify::FindStaticWindows): windows inside the rests only, the
// joints' mean there, and the up direction's standard error checked against Monte Carlo (the
// squared error in its units follows chi-square with 2 degrees of freedom per window).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "estimators/lie/so3.h"
#include "estimators/stats/chi_square.h"
#include "scenarios/identify/log_gravity.h"

namespace flexbench::identify {
namespace {

// One hinge about x: it turns 0 -> 1 rad over [0, 1] s, rests over [1, 3], turns back to 0 over
// [3, 4], rests over [4, 6]. Joints at 100 Hz, one IMU on the link at 200 Hz: the gyro reads the
// hinge's rate, the accelerometer the up direction turned into the link plus noise.
sim::RecordedLog HingeLog(std::mt19937_64& rng, double accel_std) {
  const auto angle = [](double t) {
    if (t < 1.0) return t;
    if (t < 3.0) return 1.0;
    if (t < 4.0) return 4.0 - t;
    return 0.0;
  };
  const auto rate = [](double t) { return t < 1.0 ? 1.0 : (t >= 3.0 && t < 4.0 ? -1.0 : 0.0); };
  sim::RecordedLog log;
  log.joints = {"hinge"};
  log.joint_is_slide = {0};
  for (int i = 0; i <= 600; ++i) {
    log.joint_t.push_back(0.01 * i);
    log.joint_q.push_back(angle(0.01 * i));
  }
  log.imus.push_back({"imu", "link", false, Quat::Identity(), 0.05});
  std::normal_distribution<double> n(0.0, accel_std);
  for (int i = 0; i <= 1200; ++i) {
    const double t = 0.005 * i;
    estimators::ImuReading r;
    r.t = t;
    r.gyro = Vec3(rate(t), 0.0, 0.0);
    r.accel = lie::SO3Exp(Vec3(angle(t), 0.0, 0.0)).transpose() * Vec3(0.0, 0.0, 9.81) +
              Vec3(n(rng), n(rng), n(rng));
    log.imu.push_back(r);
  }
  return log;
}

TEST(StaticWindows, LieInsideTheRestsWithTheJointsMeanThere) {
  std::mt19937_64 rng(3);
  const sim::RecordedLog log = HingeLog(rng, 0.05);
  const std::vector<StaticWindow> w =
      FindStaticWindows(log, {0}, -INFINITY, INFINITY, StaticWindowOptions{});
  ASSERT_EQ(w.size(), 2u);
  // A reading is at rest when the joints are within 0.25 s of it (min_s / 2).
  EXPECT_GE(w[0].t_begin, 1.0 + 0.25 - 1e-9);
  EXPECT_LE(w[0].t_end, 3.0 - 0.25 + 1e-9);
  EXPECT_GE(w[1].t_begin, 4.0 + 0.25 - 1e-9);
  EXPECT_LE(w[1].t_end, 6.0);
  EXPECT_GT(w[0].t_end - w[0].t_begin, 1.4);
  EXPECT_NEAR(w[0].q[0], 1.0, 1e-12);
  EXPECT_NEAR(w[1].q[0], 0.0, 1e-12);
  EXPECT_NEAR(w[0].accel_norm, 9.81, 0.01);
  // A rest shorter than min_s gives none.
  StaticWindowOptions longer;
  longer.min_s = 2.5;
  EXPECT_TRUE(FindStaticWindows(log, {0}, -INFINITY, INFINITY, longer).empty());
  // A time span keeps the windows inside it.
  EXPECT_EQ(FindStaticWindows(log, {0}, 3.5, INFINITY).size(), 1u);
}

TEST(StaticWindows, TheUpDirectionsStandardErrorMatchesMonteCarlo) {
  std::mt19937_64 rng(11);
  double sum = 0.0;
  int dof = 0;
  for (int trial = 0; trial < 40; ++trial) {
    const sim::RecordedLog log = HingeLog(rng, 0.2);
    for (const StaticWindow& w : FindStaticWindows(log, {0}, -INFINITY, INFINITY)) {
      const Vec3 truth = lie::SO3Exp(Vec3(w.q[0], 0.0, 0.0)).transpose() * Vec3::UnitZ();
      const double angle = std::atan2(w.up.cross(truth).norm(), w.up.dot(truth));
      sum += std::pow(angle / w.std_rad, 2);
      dof += 2;
    }
  }
  ASSERT_EQ(dof, 160);
  EXPECT_GT(sum, stats::ChiSquareQuantile(0.001, dof)) << sum;
  EXPECT_LT(sum, stats::ChiSquareQuantile(0.999, dof)) << sum;
}

}  // namespace
}  // namespace flexbench::identify
