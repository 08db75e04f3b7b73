// The statistics a sweep reports. The Wilson interval against published values, the
// bootstrap interval against its stated 95% coverage by Monte Carlo, same data same bytes.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "scenarios/sweep/stats.h"

namespace flexbench::scenarios::sweep {
namespace {

TEST(Wilson, MatchesTheTextbookValues) {
  // 8 of 10: Wilson score 95% interval [0.4902, 0.9433] (Newcombe 1998, method 3).
  const Proportion p = WilsonInterval(8, 10);
  EXPECT_DOUBLE_EQ(p.fraction, 0.8);
  EXPECT_NEAR(p.wilson_low, 0.4902, 1e-4);
  EXPECT_NEAR(p.wilson_high, 0.9433, 1e-4);
  // All passed: the upper end is 1, the lower n / (n + z^2).
  const Proportion all = WilsonInterval(32, 32);
  EXPECT_DOUBLE_EQ(all.wilson_high, 1.0);
  EXPECT_NEAR(all.wilson_low, 32.0 / (32.0 + 1.959963984540054 * 1.959963984540054), 1e-12);
  EXPECT_TRUE(std::isnan(WilsonInterval(0, 0).fraction));
}

TEST(Summarize, MomentsAndOrderStatistics) {
  const SampleSummary s = Summarize({3.0, 1.0, NAN, 2.0, 10.0}, 7);
  EXPECT_EQ(s.n, 4);  // the NaN is left out
  EXPECT_DOUBLE_EQ(s.mean, 4.0);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, 10.0);
  EXPECT_NEAR(s.std, std::sqrt((1.0 + 9.0 + 4.0 + 36.0) / 3.0), 1e-12);
  EXPECT_LE(s.ci_low, s.mean);
  EXPECT_GE(s.ci_high, s.mean);
  EXPECT_GE(s.ci_low, s.min);
  EXPECT_LE(s.ci_high, s.max);
  const SampleSummary one = Summarize({5.0}, 1);
  EXPECT_EQ(one.std, 0.0);
  EXPECT_EQ(one.ci_low, 5.0);
  EXPECT_EQ(one.ci_high, 5.0);
  EXPECT_TRUE(std::isnan(Summarize({}, 1).mean));
}

TEST(Summarize, SameDataAndSeedGiveTheSameInterval) {
  std::vector<double> x;
  for (int i = 0; i < 20; ++i) x.push_back(std::sin(1.7 * i) + 0.01 * i * i);
  const SampleSummary a = Summarize(x, 42);
  const SampleSummary b = Summarize(x, 42);
  EXPECT_EQ(a.ci_low, b.ci_low);
  EXPECT_EQ(a.ci_high, b.ci_high);
  const SampleSummary c = Summarize(x, 43);
  EXPECT_TRUE(c.ci_low != a.ci_low || c.ci_high != a.ci_high);  // the seed is used
}

// The percentile bootstrap's interval of the mean covers the true mean about 95% of the time
// (it under-covers a little at small n). 400 samples of 32 from N(1, 2^2): the count of misses
// is Binomial(400, ~0.06); outside [8, 45] would be a broken interval.
TEST(Summarize, BootstrapIntervalCoversTheMeanAtItsLevel) {
  std::mt19937_64 rng(2026);
  std::normal_distribution<double> normal(1.0, 2.0);
  int misses = 0;
  double width = 0.0;
  for (int trial = 0; trial < 400; ++trial) {
    std::vector<double> x(32);
    for (double& v : x) v = normal(rng);
    const SampleSummary s = Summarize(x, StableHash("coverage") + trial, 1000);
    misses += (s.ci_low > 1.0 || s.ci_high < 1.0) ? 1 : 0;
    width += (s.ci_high - s.ci_low) / 400.0;
  }
  EXPECT_GE(misses, 8);
  EXPECT_LE(misses, 45);
  // Width near 2 * 1.96 * sigma / sqrt(n) = 1.386.
  EXPECT_NEAR(width, 2.0 * 1.96 * 2.0 / std::sqrt(32.0), 0.15);
}

TEST(SortedQuantile, InterpolatesBetweenOrderStatistics) {
  const std::vector<double> v{1.0, 2.0, 3.0, 4.0};
  EXPECT_DOUBLE_EQ(SortedQuantile(v, 0.0), 1.0);
  EXPECT_DOUBLE_EQ(SortedQuantile(v, 1.0), 4.0);
  EXPECT_DOUBLE_EQ(SortedQuantile(v, 0.5), 2.5);
  EXPECT_DOUBLE_EQ(SortedQuantile(v, 0.25), 1.75);
}

}  // namespace
}  // namespace flexbench::scenarios::sweep
