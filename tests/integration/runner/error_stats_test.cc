// ErrorStats' NEES and its running mismatch test (issue 15) against draws whose covariance is
// known: errors drawn from the stated covariance keep the 6-DoF and position NEES at their
// dof and rarely flag; errors twice the stated size flag almost always, and early.
#include <gtest/gtest.h>

#include <random>

#include "estimators/lie/se3.h"
#include "scenarios/runner/common/estimator_config.h"

namespace flexbench::scenarios {
namespace {

Mat6 RandomCovariance(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Mat6 A;
  for (int i = 0; i < 36; ++i) A(i) = n(rng);
  Mat6 C = A * A.transpose() / 6.0 + 0.2 * Mat6::Identity();
  const Vec6 s = (Vec6() << 1e-3, 1e-3, 2e-3, 5e-3, 5e-3, 1e-2).finished();
  return s.asDiagonal() * C * s.asDiagonal();
}

struct RunResult {
  double nees = 0.0, nees_position = 0.0;
  bool flagged = false;
  int first = -1;
};

// One run of `steps` estimates whose errors are `inflate` times the stated covariance's.
RunResult Track(std::mt19937_64& rng, int steps, double inflate) {
  std::normal_distribution<double> n(0.0, 1.0);
  ErrorStats stats(10);
  for (int k = 0; k < steps; ++k) {
    const Mat6 cov = RandomCovariance(rng);
    const Eigen::LLT<Mat6> llt(cov);
    Vec6 z;
    for (int i = 0; i < 6; ++i) z[i] = n(rng);
    const Vec6 e = inflate * Vec6(llt.matrixL() * z);
    const lie::SE3 T_est = lie::SE3::Exp(Vec6::Constant(0.1 * k));
    stats.Add(T_est, cov, T_est * lie::SE3::Exp(e));
  }
  Json m;
  stats.WriteMetrics(&m);
  return {m["nees_mean"].get<double>(), m["nees_position_mean"].get<double>(),
          m["mismatch_flagged"].get<bool>(), m["mismatch_first_step"].get<int>()};
}

TEST(ErrorStats, ConsistentErrorsKeepNeesAtItsDofAndRarelyFlag) {
  std::mt19937_64 rng(5);
  const int runs = 400;
  double nees = 0.0, pos = 0.0;
  int flagged = 0;
  for (int r = 0; r < runs; ++r) {
    const RunResult res = Track(rng, 30, 1.0);
    nees += res.nees / runs;
    pos += res.nees_position / runs;
    flagged += res.flagged;
  }
  // Mean of 12000 chi-square(6) / chi-square(3) draws: within +-2% of the dof (about 6 sigma).
  EXPECT_NEAR(nees, 6.0, 0.12);
  EXPECT_NEAR(pos, 3.0, 0.06);
  // 21 overlapping windows of 10 per run, each a one-sided 99.5% test: the run's false-alarm
  // rate is near 5%: 16 of 400 (0.04) at this seed; at 97.5% per window it was 74 (0.19).
  EXPECT_LT(flagged, 0.1 * runs) << flagged << " of " << runs;
}

TEST(ErrorStats, ErrorsTwiceTheStatedSizeFlagEarly) {
  std::mt19937_64 rng(6);
  const int runs = 200;
  int flagged = 0, at_first_window = 0;
  for (int r = 0; r < runs; ++r) {
    const RunResult res = Track(rng, 30, 2.0);
    flagged += res.flagged;
    at_first_window += res.first == 9;
  }
  EXPECT_GT(flagged, 0.98 * runs);
  EXPECT_GT(at_first_window, 0.9 * runs);
}

TEST(ErrorStats, FewerEstimatesThanTheWindowNeverFlag) {
  std::mt19937_64 rng(7);
  const RunResult res = Track(rng, 9, 10.0);
  EXPECT_FALSE(res.flagged);
  EXPECT_EQ(res.first, -1);
  EXPECT_GT(res.nees, 20.0);
}

}  // namespace
}  // namespace flexbench::scenarios
