// The summary's weight and resultant loops against their plain definitions: libm's exp, one
// running sum.
#include "estimators/pf/particle_moments.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace flexbench::pf {
namespace {

double UlpDistance(double a, double b) {
  if (a == b) return 0.0;
  return std::abs(a - b) / (std::nextafter(std::abs(b), HUGE_VAL) - std::abs(b));
}

TEST(ExpNonPositive, WithinTwoUlpOfStdExp) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> wide(-708.0, 0.0), narrow(-1.0, 0.0);
  double worst = 0.0;
  for (int i = 0; i < 200000; ++i) {
    const double x = i % 2 ? wide(rng) : narrow(rng);
    worst = std::max(worst, UlpDistance(internal::ExpNonPositive(x), std::exp(x)));
  }
  EXPECT_LE(worst, 2.0);
  EXPECT_EQ(internal::ExpNonPositive(0.0), 1.0);
  EXPECT_EQ(internal::ExpNonPositive(-0.0), 1.0);
  EXPECT_LE(UlpDistance(internal::ExpNonPositive(-708.0), std::exp(-708.0)), 1.0);
  EXPECT_EQ(internal::ExpNonPositive(-708.5), 0.0);
  EXPECT_EQ(internal::ExpNonPositive(-std::numeric_limits<double>::infinity()), 0.0);
}

class MomentsTest : public ::testing::TestWithParam<int> {};

TEST_P(MomentsTest, EqualThePlainSums) {
  const int n = GetParam();
  std::mt19937_64 rng(n);
  std::uniform_real_distribution<double> lw(-30.0, 0.0), angle(-M_PI, M_PI);
  std::vector<double> log_w(n), c(n), s(n), w(n);
  for (int i = 0; i < n; ++i) {
    log_w[i] = i % 11 == 3 ? -std::numeric_limits<double>::infinity() : lw(rng);
    const double a = angle(rng);
    c[i] = std::cos(a);
    s[i] = std::sin(a);
  }
  log_w[0] = 0.0;                // max-normalised
  if (n > 1) log_w[1] = -400.0;  // flushed to 0: far below anything a sum here can see
  double sum = 0.0, sum2 = 0.0;
  for (int i = 0; i < n; ++i) {
    sum += std::exp(log_w[i]);
    sum2 += std::exp(log_w[i]) * std::exp(log_w[i]);
  }
  EXPECT_NEAR(NormalisedWeights(log_w.data(), n, w.data()), sum * sum / sum2,
              1e-13 * sum * sum / sum2);
  double sc = 0.0, ss = 0.0, ref_sc = 0.0, ref_ss = 0.0;
  for (int i = 0; i < n; ++i) {
    EXPECT_NEAR(w[i], std::exp(log_w[i]) / sum, 1e-15);
    ref_sc += std::exp(log_w[i]) / sum * c[i];
    ref_ss += std::exp(log_w[i]) / sum * s[i];
  }
  WeightedResultant(c.data(), s.data(), w.data(), n, &sc, &ss);
  EXPECT_NEAR(sc, ref_sc, 1e-14);
  EXPECT_NEAR(ss, ref_ss, 1e-14);
}

INSTANTIATE_TEST_SUITE_P(Sizes, MomentsTest, ::testing::Values(1, 2, 3, 4, 5, 7, 64, 2049));

}  // namespace
}  // namespace flexbench::pf
