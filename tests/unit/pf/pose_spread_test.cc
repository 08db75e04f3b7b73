// The PF summary's end-effector spread (block-wise, no libm) against its definition written with
// lie::SE3::Log per particle, and its atan2 against std::atan2.
#include "estimators/pf/pose_spread.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::pf {
namespace {

TEST(Atan2UpperHalf, WithinTwoUlpOfStdAtan2) {
  // Angles in [0, 2.34] (the closed form's range) at radii from 1e-12 to 10, plus the exact
  // axes and the small-angle end.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> angle(0.0, 2.34);
  std::uniform_real_distribution<double> log_radius(-12.0, 1.0);
  double worst_ulp = 0.0;
  for (int i = 0; i < 200000; ++i) {
    const double a = i < 1000 ? 1e-9 * i : angle(rng);
    const double r = std::pow(10.0, log_radius(rng));
    const double y = r * std::sin(a), x = r * std::cos(a);
    const double expected = std::atan2(y, x);
    const double got = internal::Atan2UpperHalf(y, x);
    const double ulp = std::nextafter(std::abs(expected), HUGE_VAL) - std::abs(expected);
    worst_ulp = std::max(worst_ulp, std::abs(got - expected) / ulp);
  }
  EXPECT_LE(worst_ulp, 2.0);
  EXPECT_EQ(internal::Atan2UpperHalf(0.0, 1.0), 0.0);
  EXPECT_NEAR(internal::Atan2UpperHalf(1.0, 0.0), M_PI_2, 1e-16);
  EXPECT_NEAR(internal::Atan2UpperHalf(1.0, 1.0), M_PI_4, 1e-16);
}

// Particles about a configuration with a joint spread from tight (the converged filter) to
// uniform (after a reset: rotations near pi of the mean too), random weights with some below
// the negligible threshold.
class PoseSpreadVsDefinition : public ::testing::TestWithParam<double> {};

TEST_P(PoseSpreadVsDefinition, EqualsTheSecondMomentOfTheLogs) {
  const double spread = GetParam();
  testing::JskLikeArm arm;
  const int n = 301;  // two passes of kept positions, the second partial; a partial lane row
  const int nq = arm.model.nq();
  BatchKinematics fk(arm.model, {arm.imu2, arm.grasp}, n);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> c(nq * n), s(nq * n), w(n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < nq; ++j) {
      const double q = 0.4 * j + spread * g(rng);
      c[j * n + i] = std::cos(q);
      s[j * n + i] = std::sin(q);
    }
    w[i] = u(rng) < 0.1 ? 1e-16 : u(rng);
  }
  fk.Compute(c.data(), s.data(), n, n);
  const double negligible = 1e-14;
  for (int k = 0; k < 2; ++k) {
    const lie::SE3 T_mean = fk.Pose(k, 0) * lie::SE3::Exp(0.05 * Vec6::Ones());
    Mat6 expected = Mat6::Zero();
    const lie::SE3 T_mean_inv = T_mean.Inverse();
    int near_pi = 0;
    for (int i = 0; i < n; ++i) {
      if (w[i] < negligible) continue;
      const Vec6 xi = (T_mean_inv * fk.Pose(k, i)).Log();
      near_pi += xi.segment<3>(kRotIdx).norm() > 2.3;
      expected += w[i] * xi * xi.transpose();
    }
    KeptParticles kept(n);
    kept.Select(w.data(), n, negligible);
    Mat6 got;
    PoseSpread(fk, k, T_mean, kept, &got);
    EXPECT_LT((got - expected).cwiseAbs().maxCoeff(), 1e-13 * expected.cwiseAbs().maxCoeff())
        << "spread " << spread << " output " << k << " (" << near_pi << " near pi)\n"
        << got << "\n\n"
        << expected;
    EXPECT_TRUE(got == got.transpose());
    if (spread > 3.0) {
      EXPECT_GT(near_pi, 0);  // the fallback is exercised
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Spreads, PoseSpreadVsDefinition,
                         ::testing::Values(1e-7, 1e-3, 0.05, 0.5, 10.0));

}  // namespace
}  // namespace flexbench::pf
