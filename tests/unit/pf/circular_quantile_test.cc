// WeightedCircularQuantiles against the sorted definition it replaces (the particle filter's
// 95% intervals used to be): every particle's deviation through atan2, all sorted, the
// midpoint walk. Concentrated, broad and wrapped clouds, heavy and negligible weights, ties,
// far outliers and tiny particle counts. WeightedCircularTailQuantiles (the summary's fast path)
// against the same definition, per seed, with bands that hold the quantiles and bands that miss.
#include "estimators/pf/circular_quantile.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>
#include <utility>
#include <vector>

namespace flexbench::pf {
namespace {

double SortedQuantile(const std::vector<double>& c, const std::vector<double>& s,
                      const std::vector<double>& w, double cm, double sm, double negligible,
                      double p) {
  std::vector<std::pair<double, double>> pairs;
  double kept = 0.0;
  for (size_t i = 0; i < c.size(); ++i) {
    if (w[i] < negligible) continue;
    pairs.emplace_back(std::atan2(s[i] * cm - c[i] * sm, c[i] * cm + s[i] * sm), w[i]);
    kept += w[i];
  }
  std::sort(pairs.begin(), pairs.end());
  const double target = p * kept;
  double cum = 0.0, prev_mid = -1.0, prev_d = pairs.front().first;
  for (const auto& [d, wi] : pairs) {
    const double mid = cum + 0.5 * wi;
    if (mid >= target) {
      if (prev_mid < 0.0) return d;
      return prev_d + (d - prev_d) * (target - prev_mid) / (mid - prev_mid);
    }
    cum += wi;
    prev_mid = mid;
    prev_d = d;
  }
  return pairs.back().first;
}

struct Cloud {
  std::vector<double> c, s, w;
  double cm = 1.0, sm = 0.0;
};

// n angles around `centre` with spread `spread` (rad), weights log-normal with `weight_spread`,
// a fraction `negligible_share` of them below 1e-14, optional outliers and duplicates.
Cloud Make(std::mt19937_64& rng, int n, double centre, double spread, double weight_spread,
           double negligible_share, int outliers, bool duplicates) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Cloud cl;
  std::vector<double> a(n);
  for (int i = 0; i < n; ++i) a[i] = centre + spread * g(rng);
  for (int i = 0; i < std::min(outliers, n); ++i) a[i] = centre + M_PI * (2.0 * u(rng) - 1.0);
  if (duplicates) {
    for (int i = 1; i < n; i += 3) a[i] = a[i - 1];
  }
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    cl.c.push_back(std::cos(a[i]));
    cl.s.push_back(std::sin(a[i]));
    double wi = std::exp(weight_spread * g(rng));
    if (u(rng) < negligible_share) wi = 1e-20;
    cl.w.push_back(wi);
    sum += wi;
  }
  for (double& wi : cl.w) wi /= sum;
  double sc = 0.0, ss = 0.0;
  for (int i = 0; i < n; ++i) sc += cl.w[i] * cl.c[i], ss += cl.w[i] * cl.s[i];
  const double r = std::hypot(sc, ss);
  cl.cm = sc / r;
  cl.sm = ss / r;
  return cl;
}

TEST(WeightedCircularQuantiles, EqualTheSortedDefinition) {
  std::mt19937_64 rng(18);
  const double probs[5] = {0.025, 0.975, 0.5, 1e-6, 1.0 - 1e-6};
  int cases = 0;
  for (int n : {1, 2, 3, 10, 257, 2048}) {
    for (double spread : {1e-6, 0.01, 0.5, 3.0}) {
      for (double centre : {0.0, 3.1, -3.1}) {
        for (int variant = 0; variant < 4; ++variant) {
          const Cloud cl = Make(rng, n, centre, spread, variant == 1 ? 3.0 : 0.3,
                                variant == 2 ? 0.3 : 0.0, variant == 3 ? 3 : 0, variant == 1);
          CircularQuantileScratch scratch(n);
          bool any_kept = false;
          for (double wi : cl.w) any_kept = any_kept || wi >= 1e-14;
          ASSERT_TRUE(any_kept);
          double out[5];
          WeightedCircularQuantiles(cl.c.data(), cl.s.data(), cl.w.data(), n, cl.cm, cl.sm, 1e-14,
                                    probs, 5, out, &scratch);
          for (int k = 0; k < 5; ++k) {
            const double ref = SortedQuantile(cl.c, cl.s, cl.w, cl.cm, cl.sm, 1e-14, probs[k]);
            EXPECT_NEAR(out[k], ref, 1e-12)
                << "n " << n << " spread " << spread << " centre " << centre << " variant "
                << variant << " p " << probs[k];
          }
          ++cases;
        }
      }
    }
  }
  EXPECT_EQ(cases, 6 * 4 * 3 * 4);
}

// (seed, spread of the cloud in rad): clouds centred anywhere on the circle, so that many wrap
// through +-pi, with the quantiles' bands guessed from the circular standard deviation as the
// summary does and deliberately off.
class TailQuantilesTest : public ::testing::TestWithParam<std::tuple<int, double>> {};

TEST_P(TailQuantilesTest, EqualTheSortedDefinition) {
  const auto [seed, spread] = GetParam();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> centre(-M_PI, M_PI);
  const double probs[4] = {0.025, 0.975, 0.5, 1e-6};
  // (inner, outer) in circular standard deviations: the summary's, narrow, missing, beyond pi.
  const double bands[5][2] = {{1.6, 2.5}, {1.9, 2.0}, {0.1, 0.5}, {3.0, 9.0}, {1.0, 100.0}};
  int fast = 0, fallbacks = 0;
  for (int n : {1, 2, 7, 64, 513, 2048}) {
    for (int variant = 0; variant < 4; ++variant) {
      const Cloud cl = Make(rng, n, centre(rng), spread, variant == 1 ? 3.0 : 0.3,
                            variant == 2 ? 0.3 : 0.0, variant == 3 ? 5 : 0, variant == 1);
      bool any_kept = false;
      for (double wi : cl.w) any_kept = any_kept || wi >= 1e-14;
      if (!any_kept) continue;
      double sc = 0.0, ss = 0.0;
      for (int i = 0; i < n; ++i) sc += cl.w[i] * cl.c[i], ss += cl.w[i] * cl.s[i];
      const double sigma = std::sqrt(-2.0 * std::log(std::min(1.0, std::hypot(sc, ss))));
      CircularQuantileScratch scratch(n);
      for (const auto& band : bands) {
        double out[4];
        const int missed = WeightedCircularTailQuantiles(cl.c.data(), cl.s.data(), cl.w.data(), n,
                                                         cl.cm, cl.sm, 1e-14, band[0] * sigma,
                                                         band[1] * sigma, probs, 4, out, &scratch);
        fallbacks += missed;
        fast += 4 - missed;
        for (int k = 0; k < 4; ++k) {
          const double ref = SortedQuantile(cl.c, cl.s, cl.w, cl.cm, cl.sm, 1e-14, probs[k]);
          EXPECT_NEAR(out[k], ref, 1e-12) << "n " << n << " variant " << variant << " band "
                                          << band[0] << " " << band[1] << " p " << probs[k];
        }
      }
    }
  }
  EXPECT_GT(fast, 0);       // the bands held some quantiles
  EXPECT_GT(fallbacks, 0);  // and missed others (at least p = 0.5)
}

INSTANTIATE_TEST_SUITE_P(SeedsAndSpreads, TailQuantilesTest,
                         ::testing::Combine(::testing::Values(1, 2, 3, 18),
                                            ::testing::Values(1e-6, 0.05, 0.5, 2.0)));

}  // namespace
}  // namespace flexbench::pf
