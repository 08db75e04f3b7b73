#include "estimators/lie/se3.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <unsupported/Eigen/MatrixFunctions>

#include "estimators/lie/sampling.h"
#include "tests/unit/lie/lie_test_util.h"

namespace flexbench::lie {
namespace {

using testing::JacobianError;
using testing::kFdSteps;
using testing::NumericalJacobian;

// Independent oracle: the matrix exponential of the 4x4 hat [PPOE eq. 3] by Eigen's Pade scaling
// and squaring.
Mat4 ExpmOfHat(const Vec6& xi) { return SE3Hat(xi).exp(); }

double MaxAbs(const Mat4& A, const Mat4& B) { return (A - B).cwiseAbs().maxCoeff(); }

// ---------------------------------------------------------------------------------------------
// Exp / Log.

class SE3Tangent : public ::testing::TestWithParam<testing::TangentCase> {
 protected:
  const Vec6& xi() const { return GetParam().xi; }
};

TEST_P(SE3Tangent, ExpMatchesMatrixExponential) {
  EXPECT_LT(MaxAbs(SE3::Exp(xi()).Matrix(), ExpmOfHat(xi())), 1e-14);
}

TEST_P(SE3Tangent, HatVeeRoundTrip) { EXPECT_TRUE(SE3Vee(SE3Hat(xi())).isApprox(xi(), 0.0)); }

TEST_P(SE3Tangent, RightJacobianMatchesFiniteDifferences) {
  const auto f = [](const Vec6& v) { return SE3::Exp(v); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(SE3RightJacobian(xi()), NumericalJacobian(f, xi(), h)), 1e-7)
        << "h = " << h;
  }
}

TEST_P(SE3Tangent, LeftJacobianMatchesFiniteDifferences) {
  for (double h : kFdSteps) {
    Mat6 J_num;
    for (int k = 0; k < 6; ++k) {
      const Vec6 d = h * Vec6::Unit(k);
      J_num.col(k) = (SE3::Exp(xi() + d) * SE3::Exp(xi() - d).Inverse()).Log() / (2.0 * h);
    }
    EXPECT_LT(JacobianError(SE3LeftJacobian(xi()), J_num), 1e-7) << "h = " << h;
  }
}

TEST_P(SE3Tangent, InverseJacobiansAreInverses) {
  EXPECT_LT((SE3RightJacobian(xi()) * SE3RightJacobianInverse(xi()) - Mat6::Identity())
                .cwiseAbs()
                .maxCoeff(),
            1e-13);
  EXPECT_LT((SE3LeftJacobian(xi()) * SE3LeftJacobianInverse(xi()) - Mat6::Identity())
                .cwiseAbs()
                .maxCoeff(),
            1e-13);
}

TEST_P(SE3Tangent, RightJacobianInverseIsTheJacobianOfLog) {
  const SE3 X = SE3::Exp(xi());
  Mat6 J_xi_X;
  const Vec6 back = X.Log(&J_xi_X);
  EXPECT_LT((back - xi()).norm(), 1e-12 * (1.0 + xi().norm()));
  const auto f = [](const SE3& Y) { return Vec6(Y.Log()); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(J_xi_X, NumericalJacobian(f, X, h)), 1e-7) << "h = " << h;
    EXPECT_LT(JacobianError(SE3RightJacobianInverse(xi()), NumericalJacobian(f, X, h)), 1e-7);
  }
}

TEST_P(SE3Tangent, LeftJacobianIsAdjointTimesRightJacobian) {
  // Jl(xi) = Ad_{Exp(xi)} Jr(xi).
  EXPECT_LT((SE3LeftJacobian(xi()) - SE3::Exp(xi()).Adjoint() * SE3RightJacobian(xi()))
                .cwiseAbs()
                .maxCoeff(),
            1e-13);
}

TEST_P(SE3Tangent, CurlyWedgeExponentiatesToTheAdjoint) {
  // Ad_{Exp(xi)} = exp(ad_xi) with ad from [PPOE eq. 13].
  const Mat6 expm = CurlyWedge(xi()).exp();
  EXPECT_LT((SE3::Exp(xi()).Adjoint() - expm).cwiseAbs().maxCoeff(), 1e-13);
}

TEST_P(SE3Tangent, CurlyWedgeIsTheLieBracket) {
  // hat(ad_a b) = hat(a) hat(b) - hat(b) hat(a).
  const Vec6 b = (Vec6() << 0.3, -0.1, 0.7, -0.4, 0.2, 0.9).finished();
  const Mat4 bracket = SE3Hat(xi()) * SE3Hat(b) - SE3Hat(b) * SE3Hat(xi());
  EXPECT_LT((SE3Hat(CurlyWedge(xi()) * b) - bracket).cwiseAbs().maxCoeff(), 1e-14);
}

INSTANTIATE_TEST_SUITE_P(Tangents, SE3Tangent, ::testing::ValuesIn(testing::StandardTangentCases()),
                         [](const auto& info) { return info.param.name; });

// Round trips near 0 and near pi: relative precision near 0, absolute near pi.
class SE3RoundTrip : public ::testing::TestWithParam<double> {};

TEST_P(SE3RoundTrip, LogOfExpAndExpOfLog) {
  const double angle = GetParam();
  std::mt19937_64 rng(21);
  for (int i = 0; i < 50; ++i) {
    // Translation of the same small size near 0, of order 1 otherwise.
    const double rho_norm = angle < 1e-3 ? angle : 1.7;
    const Vec6 xi = testing::TangentWithAngle(rng, angle, rho_norm);
    const SE3 X = SE3::Exp(xi);
    const Vec6 back = X.Log();
    if (angle < 1e-3) {
      EXPECT_LE((back - xi).norm(), 1e-13 * xi.norm()) << "angle " << angle;
    } else if (angle < M_PI) {
      EXPECT_LE((back - xi).norm(), 1e-12) << "angle " << angle;
    } else {
      EXPECT_NEAR(back.segment<3>(kRotIdx).norm(), M_PI, 1e-13);
    }
    EXPECT_LT(MaxAbs(SE3::Exp(back).Matrix(), X.Matrix()), 1e-14) << "angle " << angle;
  }
}

INSTANTIATE_TEST_SUITE_P(Angles, SE3RoundTrip,
                         ::testing::Values(1e-12, 1e-9, 1e-6, 0.3, 1.0, 2.4, 3.0, M_PI - 1e-3,
                                           M_PI - 1e-6, M_PI - 1e-9, M_PI));

// ---------------------------------------------------------------------------------------------
// Group operations and their Jacobians at identity, near identity, random and near-pi poses.

class SE3AtPose : public ::testing::TestWithParam<testing::PoseCase> {
 protected:
  const SE3& X() const { return GetParam().X; }
  // A second, fixed pose to compose with.
  static SE3 Y() { return SE3::Exp((Vec6() << 0.4, -1.1, 0.25, 0.9, -0.3, 1.7).finished()); }
};

TEST_P(SE3AtPose, InverseAndCompose) {
  EXPECT_LT(MaxAbs((X() * X().Inverse()).Matrix(), Mat4::Identity()), 1e-14);
  EXPECT_LT(MaxAbs((X() * Y()).Matrix(), X().Matrix() * Y().Matrix()), 1e-14);
  EXPECT_LT(MaxAbs(X().Inverse().Matrix(), X().Matrix().inverse()), 1e-13);
  EXPECT_LT(MaxAbs(X().Between(Y()).Matrix(), (X().Inverse() * Y()).Matrix()), 1e-14);
  const Vec3 p(0.3, -2.0, 1.1);
  EXPECT_TRUE((X() * p).isApprox((X().Matrix() * p.homogeneous()).head<3>(), 1e-14));
}

TEST_P(SE3AtPose, InverseJacobian) {
  Mat6 J;
  X().Inverse(&J);
  const auto f = [](const SE3& Z) { return Z.Inverse(); };
  for (double h : kFdSteps) EXPECT_LT(JacobianError(J, NumericalJacobian(f, X(), h)), 1e-7);
}

TEST_P(SE3AtPose, ComposeJacobians) {
  Mat6 J_XY_X, J_XY_Y;
  X().Compose(Y(), &J_XY_X, &J_XY_Y);
  const SE3 Yc = Y();
  const SE3 Xc = X();
  const auto f_x = [&](const SE3& Z) { return Z * Yc; };
  const auto f_y = [&](const SE3& Z) { return Xc * Z; };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(J_XY_X, NumericalJacobian(f_x, Xc, h)), 1e-7);
    EXPECT_LT(JacobianError(J_XY_Y, NumericalJacobian(f_y, Yc, h)), 1e-7);
  }
}

TEST_P(SE3AtPose, BetweenJacobians) {
  Mat6 J_out_X, J_out_Y;
  X().Between(Y(), &J_out_X, &J_out_Y);
  const SE3 Yc = Y();
  const SE3 Xc = X();
  const auto f_x = [&](const SE3& Z) { return Z.Between(Yc); };
  const auto f_y = [&](const SE3& Z) { return Xc.Between(Z); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(J_out_X, NumericalJacobian(f_x, Xc, h)), 1e-7);
    EXPECT_LT(JacobianError(J_out_Y, NumericalJacobian(f_y, Yc, h)), 1e-7);
  }
}

TEST_P(SE3AtPose, ActJacobians) {
  const Vec3 p(0.3, -2.0, 1.1);
  Eigen::Matrix<double, 3, 6> J_pa_X;
  Mat3 J_pa_pb;
  X().Act(p, &J_pa_X, &J_pa_pb);
  const SE3 Xc = X();
  const auto f_x = [&](const SE3& Z) { return Vec3(Z * p); };
  const auto f_p = [&](const Vec3& v) { return Vec3(Xc * v); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(J_pa_X, NumericalJacobian(f_x, Xc, h)), 1e-7);
    EXPECT_LT(JacobianError(J_pa_pb, NumericalJacobian(f_p, p, h)), 1e-7);
  }
}

TEST_P(SE3AtPose, PlusAndMinusJacobians) {
  const Vec6 tau = (Vec6() << 0.2, 0.1, -0.3, 0.5, -0.2, 0.4).finished();
  Mat6 J_out_X, J_out_tau;
  const SE3 Z = X().Plus(tau, &J_out_X, &J_out_tau);
  EXPECT_LT(MaxAbs(Z.Matrix(), (X() * SE3::Exp(tau)).Matrix()), 1e-14);
  const SE3 Xc = X();
  const auto f_x = [&](const SE3& W) { return W.Plus(tau); };
  const auto f_tau = [&](const Vec6& t) { return Xc.Plus(t); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(J_out_X, NumericalJacobian(f_x, Xc, h)), 1e-7);
    EXPECT_LT(JacobianError(J_out_tau, NumericalJacobian(f_tau, tau, h)), 1e-7);
  }

  Mat6 J_d_Z, J_d_X;
  const Vec6 d = Z.Minus(X(), &J_d_Z, &J_d_X);
  EXPECT_LT((d - tau).norm(), 1e-13);
  const auto g_z = [&](const SE3& W) { return Vec6(W.Minus(Xc)); };
  const auto g_x = [&](const SE3& W) { return Vec6(Z.Minus(W)); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(J_d_Z, NumericalJacobian(g_z, Z, h)), 1e-7);
    EXPECT_LT(JacobianError(J_d_X, NumericalJacobian(g_x, Xc, h)), 1e-7);
  }
}

TEST_P(SE3AtPose, AdjointMatchesEquation7) {
  const Mat3& R = X().rotation();
  const Vec3& t = X().translation();
  Mat6 expected = Mat6::Zero();
  expected.topLeftCorner<3, 3>() = R;
  expected.topRightCorner<3, 3>() = Skew(t) * R;
  expected.bottomRightCorner<3, 3>() = R;
  EXPECT_TRUE(X().Adjoint().isApprox(expected, 0.0));
  const Vec6 xi = (Vec6() << 1.0, -2.0, 0.5, 0.3, 0.2, -0.1).finished();
  EXPECT_LT((X().AdjointTimes(xi) - X().Adjoint() * xi).norm(), 1e-14);
  // Ad_{X^-1} = Ad_X^-1 and Ad_{XY} = Ad_X Ad_Y.
  EXPECT_LT((X().Inverse().Adjoint() * X().Adjoint() - Mat6::Identity()).cwiseAbs().maxCoeff(),
            1e-13);
  EXPECT_LT(((X() * Y()).Adjoint() - X().Adjoint() * Y().Adjoint()).cwiseAbs().maxCoeff(), 1e-13);
}

TEST_P(SE3AtPose, Equations5And6LocalAndGlobalIncrements) {
  // Y = Exp(E_xi) X = X Exp(X_xi) with E_xi = Ad_X X_xi.
  std::mt19937_64 rng(5);
  for (int i = 0; i < 10; ++i) {
    const Vec6 xi_local = testing::TangentWithAngle(rng, 0.1 * (i + 1), 0.5);
    const SE3 local = X() * SE3::Exp(xi_local);
    const SE3 global = SE3::Exp(X().AdjointTimes(xi_local)) * X();
    EXPECT_LT(MaxAbs(local.Matrix(), global.Matrix()), 1e-13);
  }
}

TEST_P(SE3AtPose, CovarianceTransformsMatchTheAdjointCongruence) {
  std::mt19937_64 rng(6);
  Eigen::Matrix<double, 6, 6> A;
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < 36; ++i) A(i) = n(rng);
  const Mat6 Sigma = A * A.transpose();
  const Mat6 Ad = X().Adjoint();
  const Mat6 Ad_inv = X().Inverse().Adjoint();
  EXPECT_LT((TransformCovariance(X(), Sigma) - Ad * Sigma * Ad.transpose()).cwiseAbs().maxCoeff(),
            1e-12 * (1.0 + (Ad * Sigma * Ad.transpose()).cwiseAbs().maxCoeff()));
  EXPECT_LT(
      (TransportCovariance(X(), Sigma) - Ad_inv * Sigma * Ad_inv.transpose()).cwiseAbs().maxCoeff(),
      1e-12 * (1.0 + (Ad_inv * Sigma * Ad_inv.transpose()).cwiseAbs().maxCoeff()));
}

TEST_P(SE3AtPose, CongruenceIsSymmetricAndMayAlias) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  Mat6 A;
  for (int i = 0; i < 36; ++i) A(i) = n(rng);
  Mat6 Sigma = A * A.transpose();
  const Mat6 expected = TransportCovariance(X(), Sigma);
  EXPECT_TRUE(expected.isApprox(expected.transpose(), 0.0));  // exactly symmetric
  TransportCovariance(X(), Sigma, &Sigma);                    // in place
  EXPECT_TRUE(Sigma.isApprox(expected, 0.0));
  // The fused sum form equals transporting the sum.
  for (int i = 0; i < 36; ++i) A(i) = n(rng);
  const Mat6 Sigma2 = A * A.transpose();
  const Mat6 Ad_inv = X().Inverse().Adjoint();
  const Mat6 sum_expected = Ad_inv * (Sigma + Sigma2) * Ad_inv.transpose();
  Mat6 sum;
  TransportCovarianceSum(X(), Sigma, Sigma2, &sum);
  EXPECT_LT((sum - sum_expected).cwiseAbs().maxCoeff(),
            1e-12 * (1.0 + sum_expected.cwiseAbs().maxCoeff()));
  EXPECT_TRUE(sum.isApprox(sum.transpose(), 0.0));
  // In place on either input (everything is read before the first store).
  Mat6 in1 = Sigma, in2 = Sigma2;
  TransportCovarianceSum(X(), in1, Sigma2, &in1);
  TransportCovarianceSum(X(), Sigma, in2, &in2);
  EXPECT_TRUE(in1 == sum);
  EXPECT_TRUE(in2 == sum);
}

TEST_P(SE3AtPose, Sse2TransportHasTheVectorTransportsBits) {
  // The baseline-CPU path of the covariance recursion uses the two-lane twin; "same seed, same
  // bytes" across machines needs every bit equal, with and without the summed source, in place.
  std::mt19937_64 rng(8);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    Mat6 A;
    for (int i = 0; i < 36; ++i) A(i) = n(rng);
    const Mat6 S1 = A * A.transpose();
    for (int i = 0; i < 36; ++i) A(i) = n(rng);
    const Mat6 S2 = A * A.transpose();
    const Mat3 R = X().rotation();
    const Vec3 t = X().translation();
    Mat6 vec, scal;
    internal::TransportBlocks(R, t, S1, nullptr, &vec);
    internal::TransportBlocksSse2(R, t, S1, nullptr, &scal);
    EXPECT_TRUE(vec == scal) << "trial " << trial;
    internal::TransportBlocks(R, t, S1, &S2, &vec);
    internal::TransportBlocksSse2(R, t, S1, &S2, &scal);
    EXPECT_TRUE(vec == scal) << "sum, trial " << trial;
    Mat6 in1 = S1, in2 = S2;
    internal::TransportBlocksSse2(R, t, in1, &S2, &in1);
    internal::TransportBlocksSse2(R, t, S1, &in2, &in2);
    EXPECT_TRUE(in1 == vec && in2 == vec) << "in place, trial " << trial;
  }
}

INSTANTIATE_TEST_SUITE_P(Poses, SE3AtPose, ::testing::ValuesIn(testing::StandardPoseCases()),
                         [](const auto& info) { return info.param.name; });

// [PPOE eq. 10] by Monte Carlo: samples X = Xbar Exp(xi_local), xi_local ~ N(0, Sigma); their
// global perturbations Log(X Xbar^-1) have covariance Ad Sigma Ad^T (to first order in Sigma: small
// Sigma so the BCH residue is far below the sampling error).
TEST(SE3MonteCarlo, GlobalCovarianceIsAdjointCongruence) {
  std::mt19937_64 rng(99);
  const SE3 Xbar = RandomSE3(rng, 3.0);
  Vec6 sd;
  sd << 0.01, 0.02, 0.005, 0.002, 0.004, 0.003;
  const Mat6 Sigma = sd.cwiseAbs2().asDiagonal();
  GaussianSampler<6> sampler(Sigma);
  const int n = 200000;
  Mat6 S = Mat6::Zero();
  for (int i = 0; i < n; ++i) {
    const SE3 X = Xbar * SE3::Exp(sampler.Sample(rng));
    const Vec6 xi_global = (X * Xbar.Inverse()).Log();
    S += xi_global * xi_global.transpose();
  }
  S /= n;
  const Mat6 expected = TransformCovariance(Xbar, Sigma);
  // Sampling error of a second moment ~ sqrt(2/n) ~ 0.3% of the diagonal scale.
  const Eigen::Matrix<double, 6, 1> scale = expected.diagonal().cwiseSqrt();
  const Mat6 normalized_err =
      scale.cwiseInverse().asDiagonal() * (S - expected) * scale.cwiseInverse().asDiagonal();
  EXPECT_LT(normalized_err.cwiseAbs().maxCoeff(), 0.015) << "MC\n"
                                                         << S << "\nexpected\n"
                                                         << expected;
  // And the plain (local) covariance would be wrong: the check has teeth.
  const Mat6 wrong_err =
      scale.cwiseInverse().asDiagonal() * (S - Sigma) * scale.cwiseInverse().asDiagonal();
  EXPECT_GT(wrong_err.cwiseAbs().maxCoeff(), 0.1);
}

}  // namespace
}  // namespace flexbench::lie
