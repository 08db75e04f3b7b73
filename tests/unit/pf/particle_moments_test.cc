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

// Every kept particle once, in its own lane, in order; padding weighs 0; and so a four-lane sum
// over the positions has the bits of the same sum over all particles (what the summary's pose
// spread and band masses rely on to give the same bits as before the particles were gathered).
class KeptParticlesTest : public ::testing::TestWithParam<int> {};

TEST_P(KeptParticlesTest, KeepLanesAndOrderSoLaneSumsKeepTheirBits) {
  const int n = GetParam();
  const double negligible = 1e-14;
  std::mt19937_64 rng(n);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> w(n);
  for (int i = 0; i < n; ++i) {  // lanes kept unevenly: lane 1 mostly negligible
    const double p_negligible = i % 4 == 1 ? 0.8 : 0.4;
    w[i] = u(rng) < p_negligible ? 1e-15 * u(rng) : u(rng) / n;
  }
  if (n > 6) w[6] = std::numeric_limits<double>::quiet_NaN();  // never kept
  KeptParticles kept(n);
  kept.Select(w.data(), n, negligible);
  ASSERT_EQ(kept.size() % 4, 0);
  ASSERT_LE(kept.size(), n + 3);
  std::vector<int> seen(n, 0);
  int last[4] = {-1, -1, -1, -1};
  double lanes[4] = {0.0, 0.0, 0.0, 0.0}, lanes_all[4] = {0.0, 0.0, 0.0, 0.0};
  for (int p = 0; p < kept.size(); ++p) {
    const double wp = kept.weight()[p];
    lanes[p & 3] += wp * wp;
    if (wp == 0.0) continue;  // padding
    const int i = kept.index()[p];
    ASSERT_EQ(wp, w[i]);
    EXPECT_EQ(i % 4, p % 4) << "position " << p;
    EXPECT_GT(i, last[p & 3]) << "position " << p;
    last[p & 3] = i;
    ++seen[i];
  }
  for (int i = 0; i < n; ++i) {
    const bool keep = w[i] >= negligible;
    EXPECT_EQ(seen[i], keep ? 1 : 0) << "particle " << i;
    lanes_all[i & 3] += keep ? w[i] * w[i] : 0.0;
  }
  for (int l = 0; l < 4; ++l) EXPECT_EQ(lanes[l], lanes_all[l]) << "lane " << l;
  std::vector<double> x(n), y(n), gx(n + 4), gy(n + 4);
  for (int i = 0; i < n; ++i) {
    x[i] = i;
    y[i] = -i;
  }
  kept.Gather(x.data(), y.data(), gx.data(), gy.data());
  for (int p = 0; p < kept.size(); ++p) {
    EXPECT_EQ(gx[p], kept.index()[p]);
    EXPECT_EQ(gy[p], -kept.index()[p]);
  }
}

INSTANTIATE_TEST_SUITE_P(Sizes, KeptParticlesTest, ::testing::Values(1, 3, 4, 7, 64, 301, 2049));

}  // namespace
}  // namespace flexbench::pf
