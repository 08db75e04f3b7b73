// Resampling: unbiased (E[copies of i] = N w_i) for both schemes, stratified and systematic
// never leave a particle's count further than one from N w_i (systematic) or within the
// stratified bound, zero weights are never picked, ESS bounds.
#include "estimators/pf/resampling.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace flexbench::pf {
namespace {

std::vector<double> TestWeights(int n) {
  std::mt19937_64 rng(3);
  std::exponential_distribution<double> e(1.0);
  std::vector<double> w(n);
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    w[i] = (i % 7 == 3) ? 0.0 : std::pow(e(rng), 3.0);  // heavy-tailed, some exact zeros
    sum += w[i];
  }
  for (double& v : w) v /= sum;
  return w;
}

class ResamplingTest : public ::testing::TestWithParam<ResamplingScheme> {};

TEST_P(ResamplingTest, UnbiasedAndNeverPicksZeroWeights) {
  const int n = 64;
  const std::vector<double> w = TestWeights(n);
  std::mt19937_64 rng(5);
  std::vector<int> ancestors(n);
  std::vector<double> mean_count(n, 0.0);
  const int runs = 20000;
  for (int r = 0; r < runs; ++r) {
    Resample(GetParam(), w.data(), n, rng, ancestors.data());
    std::vector<int> count(n, 0);
    for (int k = 0; k < n; ++k) {
      ASSERT_GE(ancestors[k], 0);
      ASSERT_LT(ancestors[k], n);
      if (k > 0) {
        ASSERT_GE(ancestors[k], ancestors[k - 1]);
      }
      ++count[ancestors[k]];
    }
    for (int i = 0; i < n; ++i) {
      if (w[i] == 0.0) {
        ASSERT_EQ(count[i], 0);
      }
      // Both schemes put floor(N w_i) - 1 <= copies <= ceil(N w_i) + 1.
      ASSERT_LE(std::abs(count[i] - n * w[i]), 2.0);
      mean_count[i] += count[i];
    }
  }
  for (int i = 0; i < n; ++i) {
    const double expected = n * w[i];
    // Per-run count variance is at most 1/4 + ... < 1: 5 sigma over `runs`.
    EXPECT_NEAR(mean_count[i] / runs, expected, 5.0 / std::sqrt(double(runs)) + 1e-12) << i;
  }
}

INSTANTIATE_TEST_SUITE_P(Schemes, ResamplingTest,
                         ::testing::Values(ResamplingScheme::kStratified,
                                           ResamplingScheme::kSystematic));

TEST(Resampling, SystematicCountsAreFloorOrCeil) {
  const int n = 100;
  const std::vector<double> w = TestWeights(n);
  std::mt19937_64 rng(6);
  std::vector<int> ancestors(n);
  Resample(ResamplingScheme::kSystematic, w.data(), n, rng, ancestors.data());
  std::vector<int> count(n, 0);
  for (int a : ancestors) ++count[a];
  for (int i = 0; i < n; ++i) {
    EXPECT_GE(count[i], std::floor(n * w[i]) - 1e-9);
    EXPECT_LE(count[i], std::ceil(n * w[i]) + 1e-9);
  }
}

TEST(Resampling, SingleSurvivorAndUnnormalisedWeights) {
  std::vector<double> w(10, 0.0);
  w[7] = 3.5;  // not normalised: the cumulative sum is rescaled
  std::mt19937_64 rng(1);
  std::vector<int> ancestors(10);
  Resample(ResamplingScheme::kStratified, w.data(), 10, rng, ancestors.data());
  for (int a : ancestors) EXPECT_EQ(a, 7);
}

TEST(Resampling, EffectiveSampleSize) {
  std::vector<double> w(50, 1.0 / 50);
  EXPECT_NEAR(EffectiveSampleSize(w.data(), 50), 50.0, 1e-12);
  std::fill(w.begin(), w.end(), 0.0);
  w[3] = 1.0;
  EXPECT_NEAR(EffectiveSampleSize(w.data(), 50), 1.0, 1e-12);
}

}  // namespace
}  // namespace flexbench::pf
