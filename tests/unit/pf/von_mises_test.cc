// The von Mises distribution [PF eqs. 3-6]: density normalisation, the Best-Fisher sampler
// against the density (moments, Kolmogorov-Smirnov, chi-square), the circular mean against the
// naive mean (Fig. 3), kappa estimation, the product over joints, bad parameters.
#include "estimators/pf/von_mises.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/error.h"

namespace flexbench::pf {
namespace {

// CDF of vM(kappa, 0) on [-pi, pi), tabulated by Simpson's rule on a fine grid (oracle
// independent of the sampler; uses only the density).
class VonMisesCdf {
 public:
  explicit VonMisesCdf(double kappa, int n = 40000) : n_(n), h_(2.0 * M_PI / n), cdf_(n + 1) {
    const VonMises vm(kappa);
    const auto f = [&](double x) { return vm.Density(x); };
    cdf_[0] = 0.0;
    for (int k = 0; k < n; ++k) {
      const double a = -M_PI + k * h_;
      cdf_[k + 1] = cdf_[k] + h_ / 6.0 * (f(a) + 4.0 * f(a + 0.5 * h_) + f(a + h_));
    }
  }
  double operator()(double x) const {
    const double u = (x + M_PI) / h_;
    const int k = std::clamp(static_cast<int>(u), 0, n_ - 1);
    return cdf_[k] + (u - k) * (cdf_[k + 1] - cdf_[k]);
  }
  double total() const { return cdf_[n_]; }

 private:
  int n_;
  double h_;
  std::vector<double> cdf_;
};

TEST(VonMises, DensityIntegratesToOne) {
  for (double kappa : {1e-6, 0.1, 1.0, 5.0, 15.0, 200.0, 2000.0}) {
    const VonMisesCdf cdf(kappa, kappa > 500 ? 400000 : 40000);
    EXPECT_NEAR(cdf.total(), 1.0, 1e-9) << kappa;
  }
}

TEST(VonMises, LogDensityIsStableForHugeKappa) {
  const VonMises vm(1e8, 0.3);
  // Near the mode the density ~ sqrt(kappa / 2 pi); log I0(1e8) alone is ~1e8.
  EXPECT_NEAR(vm.LogDensity(0.3), 0.5 * std::log(1e8 / (2.0 * M_PI)), 1e-6);
  EXPECT_TRUE(std::isfinite(vm.LogDensity(0.3 + M_PI)));
}

// Both exact samplers: Best-Fisher (VonMisesSampler) and the table sampler the filter uses.
enum class Kind { kBestFisher, kTable, kTableBatch };

struct AnySampler {
  AnySampler(Kind kind, double kappa) {
    if (kind == Kind::kBestFisher) {
      bf = std::make_unique<VonMisesSampler>(kappa);
    } else {
      table = std::make_unique<VonMisesTableSampler>(kappa);
      batch = kind == Kind::kTableBatch;
    }
  }
  UnitAngle SampleUnit(std::mt19937_64& rng) {
    if (bf) return bf->SampleUnit(rng);
    if (!batch) return table->SampleUnit(rng);
    // RotateByNoise applied to (1, 0) in batches of 1000.
    if (next == 1000) {
      std::fill(c.begin(), c.end(), 1.0);
      std::fill(s.begin(), s.end(), 0.0);
      table->RotateByNoise(rng, c.data(), s.data(), 1000, scratch.data());
      next = 0;
    }
    const UnitAngle a{c[next], s[next]};
    ++next;
    return a;
  }
  double Sample(std::mt19937_64& rng) {
    const UnitAngle a = SampleUnit(rng);
    const double x = std::atan2(a.s, a.c);
    return x >= M_PI ? -M_PI : x;
  }
  std::unique_ptr<VonMisesSampler> bf;
  std::unique_ptr<VonMisesTableSampler> table;
  bool batch = false;
  int next = 1000;
  std::vector<double> c = std::vector<double>(1000), s = std::vector<double>(1000);
  std::vector<std::uint64_t> scratch = std::vector<std::uint64_t>(1000);
};

class VonMisesSamplerTest : public ::testing::TestWithParam<std::tuple<Kind, double>> {};

TEST_P(VonMisesSamplerTest, MomentsMatch) {
  const double kappa = std::get<1>(GetParam());
  AnySampler sampler(std::get<0>(GetParam()), kappa);
  std::mt19937_64 rng(1234);
  const int n = 200000;
  double sc = 0.0, ss = 0.0, sc2 = 0.0, sx2 = 0.0;
  for (int i = 0; i < n; ++i) {
    const UnitAngle a = sampler.SampleUnit(rng);
    ASSERT_NEAR(a.c * a.c + a.s * a.s, 1.0, 1e-14);
    const double x = std::atan2(a.s, a.c);
    sc += a.c;
    ss += a.s;
    sc2 += a.c * a.c - a.s * a.s;  // cos 2x
    sx2 += x * x;
  }
  const double a1 = BesselRatioA1(kappa);
  const double a2 = 1.0 - 2.0 * a1 / kappa;  // I2 / I0
  const double var_cos = std::max(0.0, 0.5 * (1.0 + a2) - a1 * a1);
  const double var_sin = std::max(0.0, 0.5 * (1.0 - a2));
  EXPECT_NEAR(sc / n, a1, 5.0 * std::sqrt(var_cos / n) + 1e-12) << kappa;
  EXPECT_NEAR(ss / n, 0.0, 5.0 * std::sqrt(var_sin / n) + 1e-12) << kappa;
  if (kappa < 1e3) {
    EXPECT_NEAR(sc2 / n, a2, 5.0 * std::sqrt((1.0 - a2 * a2) / n) + 1e-12) << kappa;
  } else {
    // Concentrated: x ~ N(0, 1/kappa) [PF eq. 4] to O(1/kappa^2).
    EXPECT_NEAR(sx2 / n * kappa, 1.0, 0.02) << kappa;
  }
}

TEST_P(VonMisesSamplerTest, KolmogorovSmirnovAndChiSquare) {
  const double kappa = std::get<1>(GetParam());
  // The oracle CDF: the tabulated density, or for kappa >= 1e3 the Gaussian limit of [PF eq. 4]
  // (N(0, 1/kappa), whose CDF differs from the von Mises one by O(1/kappa)).
  const VonMisesCdf table(std::min(kappa, 1e3));
  const auto cdf = [&](double x) {
    return kappa < 1e3 ? table(x) : 0.5 * std::erfc(-x * std::sqrt(0.5 * kappa));
  };
  AnySampler sampler(std::get<0>(GetParam()), kappa);
  std::mt19937_64 rng(99);
  const int n = 50000;
  std::vector<double> x(n);
  for (double& v : x) v = sampler.Sample(rng);
  for (double v : x) ASSERT_TRUE(v >= -M_PI && v < M_PI) << v;
  std::sort(x.begin(), x.end());
  double d = 0.0;
  for (int i = 0; i < n; ++i) {
    const double f = cdf(x[i]);
    d = std::max({d, f - double(i) / n, double(i + 1) / n - f});
  }
  // Critical value at alpha = 0.001: 1.95 / sqrt(n).
  EXPECT_LT(d, 1.95 / std::sqrt(double(n))) << kappa;
  // Chi-square over 40 equiprobable-ish bins on the central 99.9% mass.
  const int bins = 40;
  std::vector<double> edges(bins + 1);
  for (int b = 0; b <= bins; ++b) {
    // Invert the CDF by bisection.
    const double p = double(b) / bins;
    double lo = -M_PI, hi = M_PI;
    for (int it = 0; it < 100; ++it) {
      const double mid = 0.5 * (lo + hi);
      (cdf(mid) < p ? lo : hi) = mid;
    }
    edges[b] = b == 0 ? -M_PI : (b == bins ? M_PI : 0.5 * (lo + hi));
  }
  double chi2 = 0.0;
  for (int b = 0; b < bins; ++b) {
    const double expected = n * (cdf(edges[b + 1]) - cdf(edges[b]));
    const auto count = std::count_if(x.begin(), x.end(),
                                     [&](double v) { return v >= edges[b] && v < edges[b + 1]; });
    chi2 += (count - expected) * (count - expected) / expected;
  }
  // chi^2(39) 0.999 quantile is 72.1.
  EXPECT_LT(chi2, 72.1) << kappa;
}

INSTANTIATE_TEST_SUITE_P(Kappas, VonMisesSamplerTest,
                         ::testing::Combine(::testing::Values(Kind::kBestFisher, Kind::kTable,
                                                              Kind::kTableBatch),
                                            ::testing::Values(1e-300, 1e-3, 0.1, 1.0, 5.0, 15.0,
                                                              100.0, 1e4, 1e8, 1e12)));

TEST(VonMises, SampleIsDeterministicAndWrapped) {
  const VonMises vm(0.5, 3.0);
  std::mt19937_64 a(7), b(7);
  for (int i = 0; i < 1000; ++i) {
    const double x = vm.Sample(a);
    EXPECT_EQ(x, vm.Sample(b));
    EXPECT_GE(x, -M_PI);
    EXPECT_LT(x, M_PI);
  }
}

TEST(VonMises, CircularMeanBeatsNaiveMeanNearPi) {
  // The paper's Fig. 3: theta0 = 3 pi / 4; samples wrap around +-pi.
  const VonMises vm(1.0, 3.0 * M_PI / 4.0);
  std::mt19937_64 rng(3);
  std::vector<double> x(20000);
  for (double& v : x) v = vm.Sample(rng);
  EXPECT_NEAR(CircularMean(x), 3.0 * M_PI / 4.0, 0.03);
  EXPECT_GT(std::abs(NaiveMean(x) - 3.0 * M_PI / 4.0), 0.5);
}

TEST(VonMises, KappaEstimateRecoversKappa) {
  for (double kappa : {0.5, 5.0, 15.0, 100.0}) {
    const VonMises vm(kappa, -2.0);
    std::mt19937_64 rng(11);
    std::vector<double> x(50000);
    for (double& v : x) v = vm.Sample(rng);
    const CircularSummary s = SummariseAngles(x);
    EXPECT_NEAR(s.mean, -2.0, 5.0 / std::sqrt(kappa * x.size()) + 1e-3);
    EXPECT_NEAR(s.kappa_mle / kappa, 1.0, 0.03) << kappa;
    EXPECT_NEAR(s.circular_std, vm.CircularStd(), 0.02 * vm.CircularStd());
  }
}

TEST(VonMises, WeightedSummary) {
  const std::vector<double> x = {M_PI - 0.1, -M_PI + 0.1, 0.0};
  const std::vector<double> w = {1.0, 1.0, 0.0};
  EXPECT_NEAR(std::abs(CircularMean(x, w)), M_PI, 1e-12);
  EXPECT_THROW(SummariseAngles(x, {1.0, -1.0, 1.0}), InputError);
  EXPECT_THROW(SummariseAngles(x, {0.0, 0.0, 0.0}), InputError);
  // Weights of another length are the caller's bug, not bad input.
  EXPECT_THROW(SummariseAngles(x, {1.0}), std::invalid_argument);
}

TEST(VonMises, ProductOverJoints) {
  const VonMisesProduct p({1.0, 15.0, 5.0}, {0.0, 1.0, -3.0});
  const std::vector<double> x = {0.2, 0.9, 3.1};
  double expected = 0.0;
  for (int j = 0; j < 3; ++j) expected += p.component(j).LogDensity(x[j]);
  EXPECT_DOUBLE_EQ(p.LogDensity(x), expected);
  EXPECT_NEAR(p.component(0).LogDensity(0.2),
              std::cos(0.2) - std::log(2.0 * M_PI * std::cyl_bessel_i(0.0, 1.0)), 1e-14);
  const VonMisesProduct iid = VonMisesProduct::Iid(4, 0.1);
  std::mt19937_64 rng(5);
  std::vector<double> s;
  iid.Sample(rng, &s);
  EXPECT_EQ(s.size(), 4u);
  EXPECT_THROW(p.LogDensity({0.0}), std::invalid_argument);
  EXPECT_THROW(VonMisesProduct({1.0}, {0.0, 1.0}), std::invalid_argument);
}

TEST(VonMises, BadKappaIsAClearError) {
  for (double kappa : {0.0, -1.0, double(NAN), double(INFINITY)}) {
    try {
      VonMises vm(kappa);
      FAIL() << kappa;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("kappa must be finite and > 0"), std::string::npos);
    }
    EXPECT_THROW(VonMisesSampler s(kappa), InputError);
  }
  EXPECT_THROW(VonMises(1.0, NAN), InputError);
}

}  // namespace
}  // namespace flexbench::pf

namespace flexbench::pf {
namespace {

// The family sampler of the encoder-conjugate proposal: exact for every k of its range, at bin
// edges, inside bins, below the first table (k_min = 0) and just outside the range.
TEST(VonMisesFamily, EveryConcentrationIsExact) {
  const VonMisesFamilySampler narrow(10.0, 20.0);
  const VonMisesFamilySampler wide(0.0, 30.0);
  struct Case {
    const VonMisesFamilySampler* sampler;
    double k;
  };
  const Case cases[] = {{&narrow, 10.0},  {&narrow, 10.3}, {&narrow, 12.5},         {&narrow, 15.0},
                        {&narrow, 19.99}, {&narrow, 20.0}, {&narrow, 20.0 + 1e-13}, {&wide, 0.01},
                        {&wide, 1.0},     {&wide, 29.0}};
  for (const Case& c : cases) {
    std::mt19937_64 rng(21);
    const int n = 40000;
    std::vector<double> x(n);
    double sc = 0.0;
    for (double& v : x) {
      const UnitAngle a = c.sampler->SampleUnit(c.k, rng);
      ASSERT_NEAR(a.c * a.c + a.s * a.s, 1.0, 1e-14);
      v = std::atan2(a.s, a.c);
      sc += a.c;
    }
    const double a1 = BesselRatioA1(c.k);
    const double a2 = 1.0 - 2.0 * a1 / c.k;
    EXPECT_NEAR(sc / n, a1, 5.0 * std::sqrt(std::max(0.0, 0.5 * (1.0 + a2) - a1 * a1) / n) + 1e-12)
        << c.k;
    const VonMisesCdf cdf(c.k);
    std::sort(x.begin(), x.end());
    double d = 0.0;
    for (int i = 0; i < n; ++i) {
      const double f = cdf(x[i]);
      d = std::max({d, f - double(i) / n, double(i + 1) / n - f});
    }
    EXPECT_LT(d, 1.95 / std::sqrt(double(n))) << c.k;
  }
  // The batch form rotates given unit vectors by such draws.
  std::vector<double> k(1000, 14.0), cs(1000, 0.0), sn(1000, 1.0);
  std::mt19937_64 rng(3);
  narrow.RotateBatch(k.data(), cs.data(), sn.data(), 1000, rng);
  double mean_sin = 0.0;
  for (int i = 0; i < 1000; ++i) {
    EXPECT_NEAR(cs[i] * cs[i] + sn[i] * sn[i], 1.0, 1e-15);
    mean_sin += sn[i] / 1000;  // e^{i pi/2} rotated: E[sin] = A1(14)
  }
  EXPECT_NEAR(mean_sin, BesselRatioA1(14.0), 0.01);
  EXPECT_THROW(VonMisesFamilySampler(5.0, 5.0), InputError);
}

}  // namespace
}  // namespace flexbench::pf
