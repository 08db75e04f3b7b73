// The Bingham distribution on S^3 [PF eqs. 7-9, 27]: the normaliser against a direct
// three-dimensional quadrature over S^3, closed forms and the concentrated limit; the
// likelihood form against quaternion arithmetic; the sampler against the normaliser's
// derivatives; conventions (xyzw, sorted and shifted lambda, antipodal and axis symmetry); bad
// input.
#include "estimators/pf/bingham.h"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>
#include <random>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/error.h"

namespace flexbench::pf {
namespace {

// Gauss-Legendre nodes and weights on [-1, 1] (Newton on P_n).
void GaussLegendre(int n, std::vector<double>* x, std::vector<double>* w) {
  x->resize(n);
  w->resize(n);
  for (int i = 0; i < n; ++i) {
    double z = std::cos(M_PI * (i + 0.75) / (n + 0.5));
    double dp = 0.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = z;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (z * p1 - p0) / (z * z - 1.0);
      const double dz = p1 / dp;
      z -= dz;
      if (std::abs(dz) < 1e-16) break;
    }
    (*x)[i] = z;
    (*w)[i] = 2.0 / ((1.0 - z * z) * dp * dp);
  }
}

// int_{S^3} exp(x^T A x) dS by hyperspherical coordinates x = (sin p sin t cos f,
// sin p sin t sin f, sin p cos t, cos p), dS = sin^2 p sin t dp dt df: Gauss-Legendre in p and t,
// the trapezoid rule in the periodic f.
double SphereIntegral(const Mat4& A, int n = 160) {
  std::vector<double> gx, gw;
  GaussLegendre(n, &gx, &gw);
  const int nf = 2 * n;
  double total = 0.0;
  for (int a = 0; a < n; ++a) {
    const double p = 0.5 * M_PI * (gx[a] + 1.0), wp = 0.5 * M_PI * gw[a];
    for (int b = 0; b < n; ++b) {
      const double t = 0.5 * M_PI * (gx[b] + 1.0), wt = 0.5 * M_PI * gw[b];
      double inner = 0.0;
      for (int c = 0; c < nf; ++c) {
        const double f = 2.0 * M_PI * c / nf;
        const Vec4 x(std::sin(p) * std::sin(t) * std::cos(f),
                     std::sin(p) * std::sin(t) * std::sin(f), std::sin(p) * std::cos(t),
                     std::cos(p));
        inner += std::exp(x.dot(A * x));
      }
      total += wp * wt * std::sin(p) * std::sin(p) * std::sin(t) * inner * (2.0 * M_PI / nf);
    }
  }
  return total;
}

Mat4 RandomOrthogonal(std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  Mat4 G;
  for (int i = 0; i < 16; ++i) G(i / 4, i % 4) = n(rng);
  Eigen::HouseholderQR<Mat4> qr(G);
  return qr.householderQ();
}

Quat RandomQuat(std::mt19937_64& rng) {
  std::normal_distribution<double> n;
  Quat q(n(rng), n(rng), n(rng), n(rng));
  return q.normalized();
}

Vec4 Xyzw(const Quat& q) { return Vec4(q.x(), q.y(), q.z(), q.w()); }

TEST(Bingham, UniformNormaliserIsSphereArea) {
  EXPECT_NEAR(BinghamLogNormaliser(Vec4::Zero()), std::log(2.0 * M_PI * M_PI), 1e-14);
}

TEST(Bingham, NormaliserMatchesThreeDimensionalQuadrature) {
  const std::vector<Vec4> lambdas = {Vec4(-1.0, -0.5, -0.2, 0.0),  Vec4(-10.0, -10.0, 0.0, 0.0),
                                     Vec4(-30.0, -8.0, -2.0, 0.0), Vec4(-25.0, -25.0, -25.0, 0.0),
                                     Vec4(-40.0, 0.0, 0.0, 0.0),   Vec4(-3.0, -3.0, -3.0, 0.0)};
  std::mt19937_64 rng(17);
  for (const Vec4& l : lambdas) {
    const Mat4 M = RandomOrthogonal(rng);  // the normaliser does not depend on M
    const Mat4 A = M * l.asDiagonal() * M.transpose();
    const double oracle = std::log(SphereIntegral(A));
    EXPECT_NEAR(BinghamLogNormaliser(l), oracle, 1e-9) << l.transpose();
  }
}

TEST(Bingham, NormaliserClosedFormsAndShift) {
  // lambda = (a, a, 0, 0): x1^2 + x2^2 is uniform on [0, 1] on S^3, C = 2 pi^2 (e^a - 1) / a.
  for (double a : {-1e-3, -1.0, -50.0, -800.0, -1e6}) {
    EXPECT_NEAR(BinghamLogNormaliser(Vec4(a, a, 0.0, 0.0)),
                std::log(2.0 * M_PI * M_PI * std::expm1(a) / a), 1e-12)
        << a;
  }
  // lambda = (a, a, a, 0): the w marginal on S^3 is (2/pi) sqrt(1 - w^2), so
  // C = 2 pi^2 (2/pi) int sqrt(1 - w^2) exp(a (1 - w^2)) dw, by Gauss-Chebyshev (2nd kind).
  for (double a : {-0.5, -20.0, -800.0}) {
    const int n = 200000;
    double sum = 0.0;
    for (int k = 1; k <= n; ++k) {
      const double th = k * M_PI / (n + 1), w = std::cos(th);
      sum += M_PI / (n + 1) * std::sin(th) * std::sin(th) * std::exp(a * (1.0 - w * w));
    }
    EXPECT_NEAR(BinghamLogNormaliser(Vec4(a, a, a, 0.0)), std::log(4.0 * M_PI * sum), 1e-9) << a;
  }
  // [PF eq. 8]: C(lambda + c) = e^c C(lambda); order does not matter.
  const Vec4 l(-30.0, -8.0, -2.0, 0.0);
  EXPECT_NEAR(BinghamLogNormaliser(l + Vec4::Constant(7.5)), BinghamLogNormaliser(l) + 7.5, 1e-12);
  EXPECT_NEAR(BinghamLogNormaliser(Vec4(-2.0, 0.0, -30.0, -8.0)), BinghamLogNormaliser(l), 1e-13);
}

TEST(Bingham, NormaliserConcentratedLimit) {
  // Near +-e4 the sphere is flat: C ~ 2 pi^{3/2} / sqrt(abc) (1 + sum 1/(4 a_i)).
  for (const Vec4& l :
       {Vec4(-1e5, -4e4, -1e4, 0.0), Vec4(-8e4, -8e4, -8e4, 0.0), Vec4(-1e7, -1e6, -2e5, 0.0)}) {
    const double a = -l(0), b = -l(1), c = -l(2);
    const double approx = std::log(2.0 * std::pow(M_PI, 1.5) / std::sqrt(a * b * c)) +
                          std::log1p(0.25 * (1.0 / a + 1.0 / b + 1.0 / c));
    EXPECT_NEAR(BinghamLogNormaliser(l), approx, 1e-7) << l.transpose();
  }
}

TEST(Bingham, DensityConventions) {
  const Bingham b(Vec4(-800.0, -800.0, -800.0, 0.0));
  // xyzw: the mode of M = I4 is the identity quaternion, and q, -q have the same density.
  const Vec4 identity(0.0, 0.0, 0.0, 1.0);
  EXPECT_EQ(b.UnnormalisedLogDensity(identity), 0.0);
  EXPECT_EQ(b.Mode(), identity);
  std::mt19937_64 rng(1);
  for (int i = 0; i < 20; ++i) {
    const Vec4 x = Xyzw(RandomQuat(rng));
    EXPECT_NEAR(b.LogDensity(x), b.LogDensity(-x), 1e-12);
    EXPECT_LE(b.UnnormalisedLogDensity(x), 0.0);
  }
  EXPECT_FALSE(b.IsAxisSymmetric());
}

TEST(Bingham, AxisSymmetricIgnoresRotationsAboutItsAxis) {
  const Bingham b(Vec4(-800.0, -800.0, 0.0, 0.0));  // the paper's Table I
  EXPECT_TRUE(b.IsAxisSymmetric());
  std::mt19937_64 rng(2);
  for (int i = 0; i < 20; ++i) {
    const Quat q = RandomQuat(rng);
    const double yaw = 2.0 * M_PI * (i / 20.0) - M_PI;
    const Quat qz(Eigen::AngleAxisd(yaw, Vec3::UnitZ()));
    EXPECT_NEAR(b.LogDensity(Xyzw(qz * q)), b.LogDensity(Xyzw(q)), 1e-9);
  }
  // A pure yaw is as likely as the identity; a 5 deg tilt is not.
  const Quat yaw(Eigen::AngleAxisd(1.0, Vec3::UnitZ()));
  const Quat tilt(Eigen::AngleAxisd(5.0 * M_PI / 180.0, Vec3::UnitX()));
  EXPECT_NEAR(b.UnnormalisedLogDensity(Xyzw(yaw)), 0.0, 1e-12);
  EXPECT_NEAR(b.UnnormalisedLogDensity(Xyzw(tilt)),
              -800.0 * std::pow(std::sin(2.5 * M_PI / 180.0), 2), 1e-9);
  // Built about another axis.
  const Bingham bx = Bingham::AxisSymmetric(-500.0, Vec3(1.0, 1.0, 0.0));
  const Quat about(Eigen::AngleAxisd(0.7, Vec3(1.0, 1.0, 0.0).normalized()));
  EXPECT_NEAR(bx.UnnormalisedLogDensity(Xyzw(about)), 0.0, 1e-12);
  EXPECT_NEAR(bx.LogNormaliser(),
              b.LogNormaliser() + std::log(800.0 / 500.0) + std::log(-std::expm1(-500.0)) -
                  std::log(-std::expm1(-800.0)),
              1e-12);
}

TEST(Bingham, RotationFormMatchesQuaternionProduct) {
  std::mt19937_64 rng(4);
  for (int trial = 0; trial < 50; ++trial) {
    const Mat4 M = RandomOrthogonal(rng);
    const Bingham b(Vec4(-900.0, -120.0, -3.0, 0.0), M);
    const Quat q_obs = RandomQuat(rng);
    const Quat q_pred = RandomQuat(rng);
    const BinghamRotationForm form = b.RotationForm(q_obs);
    const Vec4 err = Xyzw(q_obs * q_pred.inverse());  // q_obs (.) Rot(F; x)^-1, [PF eq. 27]
    EXPECT_NEAR(form.Evaluate(q_pred.toRotationMatrix()), b.UnnormalisedLogDensity(err),
                1e-10 * 900.0);
    // The sign of either quaternion does not matter.
    const Quat neg(-q_obs.w(), -q_obs.x(), -q_obs.y(), -q_obs.z());
    EXPECT_NEAR(b.RotationForm(neg).Evaluate(q_pred.toRotationMatrix()),
                form.Evaluate(q_pred.toRotationMatrix()), 1e-9);
  }
}

TEST(Bingham, SamplerMatchesNormaliserDerivatives) {
  // For M = I: E[x_i^2] = d log C / d lambda_i.
  for (const Vec4& l : {Vec4(-20.0, -5.0, -1.0, 0.0), Vec4(-800.0, -800.0, 0.0, 0.0),
                        Vec4(-800.0, -800.0, -800.0, 0.0)}) {
    const Bingham b(l);
    BinghamSampler sampler(b);
    std::mt19937_64 rng(8);
    const int n = 100000;
    Vec4 m2 = Vec4::Zero();
    for (int i = 0; i < n; ++i) {
      const Vec4 x = sampler.Sample(rng);
      ASSERT_NEAR(x.norm(), 1.0, 1e-12);
      ASSERT_GE(x(3), 0.0);
      m2 += x.cwiseProduct(x);
    }
    m2 /= n;
    for (int i = 0; i < 4; ++i) {
      const double h = 1e-4 * std::max(1.0, std::abs(l(i)));
      Vec4 lp = l, lm = l;
      lp(i) += h;
      lm(i) -= h;
      const double d = (BinghamLogNormaliser(lp) - BinghamLogNormaliser(lm)) / (2.0 * h);
      const double sd = std::sqrt(std::max(d * (1.0 - d), 1e-12) / n);
      EXPECT_NEAR(m2(i), d, 6.0 * sd + 1e-6) << l.transpose() << " i=" << i;
    }
    EXPECT_GT(sampler.AcceptanceRate(), 0.2);
  }
}

TEST(Bingham, BadInputIsAClearError) {
  const auto message = [](const auto& f) {
    try {
      f();
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message([] { Bingham b(Vec4(0.0, -800.0, -800.0, 0.0)); }).find("sorted ascending"),
            std::string::npos);
  EXPECT_NE(message([] { Bingham b(Vec4(-810.0, -810.0, -10.0, -10.0)); }).find("shifted"),
            std::string::npos);
  EXPECT_NE(
      message([] { Bingham b(Vec4(-810.0, -810.0, -10.0, -10.0)); }).find("[-800, -800, 0, 0]"),
      std::string::npos);
  EXPECT_THROW(Bingham(Vec4(NAN, -1.0, 0.0, 0.0)), InputError);
  Mat4 bad = Mat4::Identity();
  bad(0, 1) = 0.1;
  EXPECT_THROW(Bingham(Vec4(-1.0, -1.0, 0.0, 0.0), bad), InputError);
  const Bingham b(Vec4(-800.0, -800.0, 0.0, 0.0));
  EXPECT_NE(message([&] { b.LogDensity(Vec4(0.0, 0.0, 0.0, 1.1)); }).find("not unit length"),
            std::string::npos);
  EXPECT_THROW(b.LogDensity(Vec4(0.0, NAN, 0.0, 1.0)), InputError);
  EXPECT_THROW(b.RotationForm(Quat(2.0, 0.0, 0.0, 0.0)), InputError);
  EXPECT_THROW(Bingham::AxisSymmetric(0.0), InputError);
  EXPECT_THROW(BinghamLogNormaliser(Vec4(INFINITY, 0.0, 0.0, 0.0)), InputError);
}

}  // namespace
}  // namespace flexbench::pf
