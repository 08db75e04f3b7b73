// lie::SinCos against libm: relative error within 2 ulp on [-pi/4, pi/4] (no reduction: this is
// what keeps 1 - cos q = 2 sin^2(q/2) accurate for small joint angles), absolute error <= 2^-52
// after the reduction, the quadrant signs, and the libm fallback for huge and non-finite input.
#include "estimators/lie/sincos.h"

#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace flexbench::lie {
namespace {

double UlpsApart(double a, double b) {
  if (a == b) return 0.0;
  const double ulp = std::nextafter(std::fabs(b), INFINITY) - std::fabs(b);
  return std::fabs(a - b) / ulp;
}

TEST(SinCos, WithinTwoUlpWithoutReduction) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-M_PI / 4, M_PI / 4);
  std::uniform_real_distribution<double> e(-30.0, 0.0);
  double worst = 0.0;
  for (int i = 0; i < 200000; ++i) {
    // Half the samples log-uniform down to 1e-30: tiny angles must keep full relative precision.
    const double x = i % 2 == 0 ? u(rng) : std::copysign(std::pow(10.0, e(rng)), u(rng));
    double s, c;
    SinCos(x, &s, &c);
    worst = std::max({worst, UlpsApart(s, std::sin(x)), UlpsApart(c, std::cos(x))});
  }
  EXPECT_LE(worst, 2.0);
  double s, c;
  SinCos(0.0, &s, &c);
  EXPECT_EQ(s, 0.0);
  EXPECT_EQ(c, 1.0);
}

TEST(SinCos, AbsoluteErrorAfterReduction) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-1000.0, 1000.0);
  double worst = 0.0;
  auto check = [&](double x) {
    double s, c;
    SinCos(x, &s, &c);
    worst = std::max({worst, std::fabs(s - std::sin(x)), std::fabs(c - std::cos(x))});
  };
  for (int i = 0; i < 200000; ++i) check(u(rng));
  // Next to every multiple of pi/4 up to +-100 (quadrant boundaries and the reduction's worst
  // cancellation), a few ulps either side.
  for (int k = -130; k <= 130; ++k) {
    double x = k * M_PI / 4;
    for (int step = 0; step < 4; ++step) {
      check(x);
      check(-x);
      x = std::nextafter(x, INFINITY);
    }
  }
  EXPECT_LE(worst, DBL_EPSILON);
}

TEST(SinCos, QuadrantsHaveTheRightSigns) {
  for (int k = -8; k <= 8; ++k) {
    const double x = 0.3 + k * M_PI / 2;
    double s, c;
    SinCos(x, &s, &c);
    EXPECT_NEAR(s, std::sin(x), 1e-15) << "k=" << k;
    EXPECT_NEAR(c, std::cos(x), 1e-15) << "k=" << k;
  }
}

TEST(SinCos, FallsBackToLibmOutsideTheReductionRange) {
  for (double x : {kSinCosMaxArg, -kSinCosMaxArg * 3.0, 1e300}) {
    double s, c;
    SinCos(x, &s, &c);
    EXPECT_EQ(s, std::sin(x));
    EXPECT_EQ(c, std::cos(x));
  }
  double s, c;
  SinCos(std::numeric_limits<double>::quiet_NaN(), &s, &c);
  EXPECT_TRUE(std::isnan(s) && std::isnan(c));
  SinCos(std::numeric_limits<double>::infinity(), &s, &c);
  EXPECT_TRUE(std::isnan(s) && std::isnan(c));
}

TEST(SinCos4, SameBitsAsSinCosInEveryLane) {
  // The kinematics takes its joints' trigonometry four at a time: every lane must be SinCos's
  // result bit for bit (quadrant selects, signed zeros, the libm fallback), or the FK would
  // change with the frames' grouping.
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-40.0, 40.0);
  std::uniform_real_distribution<double> e(-30.0, 5.0);
  std::vector<double> xs = {0.0,
                            -0.0,
                            M_PI / 4,
                            -M_PI / 4,
                            M_PI / 2,
                            -M_PI / 2,
                            M_PI,
                            -M_PI,
                            3e4,
                            -3e4,
                            kSinCosMaxArg,
                            -kSinCosMaxArg * 2.0,
                            1e300,
                            std::numeric_limits<double>::infinity(),
                            std::numeric_limits<double>::quiet_NaN()};
  for (int k = -9; k <= 9; ++k) xs.push_back(0.3 + k * M_PI / 2);
  for (int i = 0; i < 100000; ++i) {
    xs.push_back(i % 2 == 0 ? u(rng) : std::copysign(std::pow(10.0, e(rng)), u(rng)));
  }
  while (xs.size() % 4 != 0) xs.push_back(1.0);
  const auto bits = [](double v) {
    std::uint64_t b;
    std::memcpy(&b, &v, sizeof b);
    return b;
  };
  for (size_t i = 0; i < xs.size(); i += 4) {
    const internal::V4 x = {xs[i], xs[i + 1], xs[i + 2], xs[i + 3]};
    internal::V4 s4, c4;
    internal::SinCos4(x, &s4, &c4);
    for (int l = 0; l < 4; ++l) {
      double s, c;
      SinCos(x[l], &s, &c);
      EXPECT_EQ(bits(s4[l]), bits(s)) << "sin " << x[l];
      EXPECT_EQ(bits(c4[l]), bits(c)) << "cos " << x[l];
    }
  }
}

}  // namespace
}  // namespace flexbench::lie
