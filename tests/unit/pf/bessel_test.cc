// log I0 / log I1 / A1 against independent oracles: std::cyl_bessel_i for moderate arguments,
// the integral I0(x) = 1/pi int_0^pi exp(x cos t) dt for large ones, and the leading terms of
// the asymptotic series for huge ones.
#include "estimators/pf/bessel.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "estimators/error.h"

namespace flexbench::pf {
namespace {

// log I0(x) from the integral representation, log-scaled: x + log(1/pi int_0^pi
// exp(x (cos t - 1)) dt). The integrand is periodic and smooth, so the trapezoid rule converges
// exponentially once the peak at t = 0 (width ~ 1/sqrt(x)) spans many nodes.
double LogI0ByIntegral(double x) {
  const int n = 200000;
  const double h = M_PI / n;
  double sum = 0.5 * (1.0 + std::exp(-2.0 * x));
  for (int k = 1; k < n; ++k) sum += std::exp(x * (std::cos(k * h) - 1.0));
  return x + std::log(sum * h / M_PI);
}

TEST(Bessel, LogI0MatchesStdForModerateArguments) {
  for (double x : {0.0, 1e-8, 1e-3, 0.1, 0.5, 1.0, 2.5, 5.0, 10.0, 15.0, 19.999, 20.0, 20.001, 25.0,
                   50.0, 100.0, 300.0, 600.0, 700.0}) {
    const double expected = std::log(std::cyl_bessel_i(0.0, x));
    EXPECT_NEAR(LogBesselI0(x), expected, 2e-15 * std::max(1.0, std::abs(expected))) << x;
  }
}

TEST(Bessel, LogI1MatchesStdForModerateArguments) {
  for (double x : {1e-8, 1e-3, 0.1, 1.0, 5.0, 15.0, 19.999, 20.0, 20.001, 50.0, 300.0, 700.0}) {
    const double expected = std::log(std::cyl_bessel_i(1.0, x));
    EXPECT_NEAR(LogBesselI1(x), expected, 4e-15 * std::max(1.0, std::abs(expected))) << x;
  }
}

TEST(Bessel, LogI0MatchesIntegralBeyondDoubleRange) {
  // I0(800) ~ 1e346 overflows a double; its log does not.
  for (double x : {800.0, 2000.0, 1e4, 1e5, 1e6}) {
    const double expected = LogI0ByIntegral(x);
    EXPECT_NEAR(LogBesselI0(x), expected, 1e-12 * expected) << x;
  }
}

TEST(Bessel, LogI0MatchesAsymptoticSeriesForHugeArguments) {
  for (double x : {1e7, 1e9, 1e12, 1e100, 1e300}) {
    const double lead =
        x - 0.5 * std::log(2.0 * M_PI * x) + std::log1p(1.0 / (8.0 * x) + 9.0 / (128.0 * x * x));
    EXPECT_NEAR(LogBesselI0(x), lead, 1e-15 * x) << x;
    EXPECT_TRUE(std::isfinite(LogBesselI0(x)));
  }
  EXPECT_TRUE(std::isinf(LogBesselI0(INFINITY)));
}

TEST(Bessel, ScaledI0AndRatio) {
  for (double x : {0.0, 0.3, 3.0, 19.9, 20.0, 40.0, 500.0}) {
    EXPECT_NEAR(BesselI0Scaled(x), std::exp(-x) * std::cyl_bessel_i(0.0, x), 1e-15) << x;
    if (x > 0.0) {
      EXPECT_NEAR(BesselRatioA1(x), std::cyl_bessel_i(1.0, x) / std::cyl_bessel_i(0.0, x), 5e-15)
          << x;
    }
  }
  EXPECT_EQ(BesselRatioA1(0.0), 0.0);
  // A1(x) = 1 - 1/(2x) - 1/(8x^2) - ... for large x.
  EXPECT_NEAR(BesselRatioA1(1e6), 1.0 - 0.5e-6 - 1.25e-13, 3e-16);
}

TEST(Bessel, InverseRatioRoundTrips) {
  for (double k : {1e-6, 0.01, 0.5, 1.0, 2.0, 5.0, 15.0, 100.0, 1e4}) {
    EXPECT_NEAR(InverseBesselRatioA1(BesselRatioA1(k)), k, 1e-9 * k + 1e-12) << k;
  }
  EXPECT_EQ(InverseBesselRatioA1(0.0), 0.0);
  EXPECT_TRUE(std::isinf(InverseBesselRatioA1(1.0)));
}

TEST(Bessel, BadArgumentsThrow) {
  EXPECT_THROW(LogBesselI0(-1.0), InputError);
  EXPECT_THROW(LogBesselI0(NAN), InputError);
  EXPECT_THROW(LogBesselI1(-1e-300), InputError);
  EXPECT_THROW(InverseBesselRatioA1(-0.1), InputError);
  EXPECT_THROW(InverseBesselRatioA1(NAN), InputError);
}

}  // namespace
}  // namespace flexbench::pf

namespace flexbench::pf {
namespace {

TEST(Bessel, InterpolantMatchesLogI0) {
  for (const auto& [a, b] :
       {std::pair<double, double>{10.0, 20.0}, {0.1, 2.0}, {100.0, 200.0}, {0.0, 30.0}}) {
    const LogBesselI0Interpolant f(a, b);
    std::vector<double> x, acc;
    for (int i = 0; i <= 997; ++i) {
      x.push_back(a + (b - a) * i / 997.0);
      acc.push_back(1.0);
    }
    f.AddTo(x.data(), acc.data(), static_cast<int>(x.size()));
    for (size_t i = 0; i < x.size(); ++i) {
      const double exact = LogBesselI0(x[i]);
      EXPECT_NEAR(f.Evaluate(x[i]), exact, 2e-14 * std::max(1.0, exact)) << x[i];
      EXPECT_NEAR(acc[i] - 1.0, exact, 3e-14 * std::max(1.0, exact)) << x[i];
    }
    // Outside the range it is exact too.
    EXPECT_EQ(f.Evaluate(b + 1.0), LogBesselI0(b + 1.0));
  }
  EXPECT_THROW(LogBesselI0Interpolant(2.0, 1.0), InputError);
}

// The fast A1 against the standard library's I1 / I0 (an independent implementation) where
// those do not overflow, and against BesselRatioA1 beyond, on log-spaced points.
TEST(Bessel, RatioInterpolantMatchesI1OverI0) {
  const BesselRatioA1Interpolant a1;
  std::vector<double> xs = {0.0, 1.0, 7.0, 64.0};
  for (int i = 0; i <= 400; ++i) xs.push_back(std::pow(10.0, -6.0 + 10.0 * i / 400.0));
  for (double x : xs) {
    const double expected =
        x < 600.0 ? (x == 0.0 ? 0.0 : std::cyl_bessel_i(1.0, x) / std::cyl_bessel_i(0.0, x))
                  : BesselRatioA1(x);
    EXPECT_NEAR(a1.Evaluate(x), expected, 1e-13) << x;
    EXPECT_NEAR(a1.Evaluate(x), BesselRatioA1(x), 1e-13) << x;
  }
  EXPECT_LT(a1.max_error(), 1e-13);
  EXPECT_EQ(a1.Evaluate(INFINITY), 1.0);
  EXPECT_THROW(a1.Evaluate(-1.0), InputError);
  EXPECT_THROW(a1.Evaluate(NAN), InputError);
}

}  // namespace
}  // namespace flexbench::pf
