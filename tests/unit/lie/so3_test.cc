#include "estimators/lie/so3.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "tests/unit/lie/lie_test_util.h"

namespace flexbench::lie {
namespace {

using testing::JacobianError;
using testing::kFdSteps;
using testing::NumericalJacobian;

TEST(SO3, HatVeeAndCrossProduct) {
  const Vec3 a(0.3, -1.2, 2.5);
  const Vec3 b(-0.7, 0.1, 0.4);
  EXPECT_TRUE((Skew(a) * b).isApprox(a.cross(b), 1e-15));
  EXPECT_TRUE((Skew(a) + Skew(a).transpose()).isZero(0.0));
  EXPECT_TRUE(Vee(Skew(a)).isApprox(a, 1e-15));
}

TEST(SO3, ExpMatchesAngleAxis) {
  std::mt19937_64 rng(3);
  for (int i = 0; i < 20; ++i) {
    const Vec3 axis = testing::RandomUnit(rng);
    const double angle = 0.3 * i - 3.0;
    const Mat3 expected = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
    EXPECT_LT((SO3Exp(angle * axis) - expected).cwiseAbs().maxCoeff(), 1e-15) << angle;
  }
}

TEST(SO3, ExpIsOrthonormal) {
  std::mt19937_64 rng(4);
  for (double angle : {1e-12, 1e-5, 0.2, 1.0, 3.0, M_PI}) {
    const Mat3 R = SO3Exp(angle * testing::RandomUnit(rng));
    EXPECT_LT((R.transpose() * R - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-15);
  }
}

// Round trips keep *relative* precision near 0 (an acos-based Log returns ~1e-8 absolute error
// at 1e-9 rad) and absolute precision near pi (a Log through vee(R - R^T) / (2 sin) loses
// digits like 1e-16 / (pi - |theta|)).
class SO3RoundTrip : public ::testing::TestWithParam<double> {};

TEST_P(SO3RoundTrip, LogOfExp) {
  const double angle = GetParam();
  std::mt19937_64 rng(11);
  for (int i = 0; i < 50; ++i) {
    const Vec3 theta = angle * testing::RandomUnit(rng);
    const Vec3 back = SO3Log(SO3Exp(theta));
    if (angle < 1.0) {
      EXPECT_LE((back - theta).norm(), 1e-13 * angle) << "angle " << angle;
    } else if (angle < M_PI) {
      EXPECT_LE((back - theta).norm(), 1e-13) << "angle " << angle;
    } else {
      // At exactly pi both signs are correct.
      EXPECT_LE(std::min((back - theta).norm(), (back + theta).norm()), 1e-13);
    }
  }
}

TEST_P(SO3RoundTrip, ExpOfLog) {
  const double angle = GetParam();
  std::mt19937_64 rng(12);
  for (int i = 0; i < 50; ++i) {
    const Mat3 R = SO3Exp(angle * testing::RandomUnit(rng));
    const Vec3 theta = SO3Log(R);
    EXPECT_LE(theta.norm(), M_PI + 1e-15);
    EXPECT_LT((SO3Exp(theta) - R).cwiseAbs().maxCoeff(), 2e-15) << "angle " << angle;
  }
}

INSTANTIATE_TEST_SUITE_P(Angles, SO3RoundTrip,
                         ::testing::Values(1e-12, 1e-9, 1e-6, 0.99e-4, 1.01e-4, 1e-3, 0.3, 1.0, 2.0,
                                           2.4, 3.0, M_PI - 1e-3, M_PI - 1e-6, M_PI - 1e-9, M_PI));

TEST(SO3, LogAtZeroIsZero) { EXPECT_TRUE(SO3Log(Mat3::Identity()).isZero(0.0)); }

TEST(SO3, LogNearPiFromSlightlyNonOrthogonalInput) {
  // Rotation matrices read from files are orthonormal only to ~1e-9; Log must stay finite and
  // close.
  const Vec3 theta = (M_PI - 1e-7) * Vec3(1.0, 2.0, -0.5).normalized();
  Mat3 R = SO3Exp(theta);
  R(0, 1) += 1e-10;
  const Vec3 back = SO3Log(R);
  ASSERT_TRUE(back.allFinite());
  EXPECT_LT((back - theta).norm(), 1e-8);
}

class SO3Jacobians : public ::testing::TestWithParam<testing::TangentCase> {
 protected:
  Vec3 theta() const { return GetParam().xi.segment<3>(kRotIdx); }
};

TEST_P(SO3Jacobians, RightJacobianMatchesFiniteDifferences) {
  // Exp(theta + d) = Exp(theta) Exp(Jr d).
  const auto f = [](const Vec3& v) { return SO3Exp(v); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(SO3RightJacobian(theta()), NumericalJacobian(f, theta(), h)), 1e-7)
        << "h = " << h;
  }
}

TEST_P(SO3Jacobians, LeftJacobianMatchesFiniteDifferences) {
  // Exp(theta + d) = Exp(Jl d) Exp(theta): the left difference Log(Y X^-1).
  for (double h : kFdSteps) {
    Mat3 J_num;
    for (int k = 0; k < 3; ++k) {
      const Vec3 d = h * Vec3::Unit(k);
      J_num.col(k) = SO3Log(SO3Exp(theta() + d) * SO3Exp(theta() - d).transpose()) / (2.0 * h);
    }
    EXPECT_LT(JacobianError(SO3LeftJacobian(theta()), J_num), 1e-7) << "h = " << h;
  }
}

TEST_P(SO3Jacobians, InverseJacobiansAreInverses) {
  EXPECT_LT((SO3RightJacobian(theta()) * SO3RightJacobianInverse(theta()) - Mat3::Identity())
                .cwiseAbs()
                .maxCoeff(),
            1e-13);
  EXPECT_LT((SO3LeftJacobian(theta()) * SO3LeftJacobianInverse(theta()) - Mat3::Identity())
                .cwiseAbs()
                .maxCoeff(),
            1e-13);
}

TEST_P(SO3Jacobians, RightJacobianInverseIsTheJacobianOfLog) {
  // Log(R Exp(d)) = Log(R) + Jr^-1 d: the Jacobian of Log on the manifold.
  const Mat3 R = SO3Exp(theta());
  const auto f = [](const Mat3& X) { return Vec3(SO3Log(X)); };
  for (double h : kFdSteps) {
    EXPECT_LT(JacobianError(SO3RightJacobianInverse(theta()), NumericalJacobian(f, R, h)), 1e-7)
        << "h = " << h;
  }
}

TEST_P(SO3Jacobians, LeftAndRightJacobiansAreRelatedByR) {
  // Jl(theta) = R Jr(theta) = Jr(-theta).
  const Mat3 R = SO3Exp(theta());
  EXPECT_LT((SO3LeftJacobian(theta()) - R * SO3RightJacobian(theta())).cwiseAbs().maxCoeff(),
            1e-14);
  EXPECT_LT((SO3LeftJacobian(theta()) - SO3RightJacobian(-theta())).cwiseAbs().maxCoeff(), 1e-15);
}

INSTANTIATE_TEST_SUITE_P(Tangents, SO3Jacobians,
                         ::testing::ValuesIn(testing::StandardTangentCases()),
                         [](const auto& info) { return info.param.name; });

TEST(SO3, ProjectRestoresOrthonormality) {
  Mat3 R = SO3Exp(Vec3(0.4, -1.0, 0.3));
  const Mat3 noisy = R + 1e-6 * Mat3::Ones();
  const Mat3 P = SO3Project(noisy);
  EXPECT_LT((P.transpose() * P - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_NEAR(P.determinant(), 1.0, 1e-14);
  EXPECT_LT((P - R).cwiseAbs().maxCoeff(), 1e-5);
}

}  // namespace
}  // namespace flexbench::lie
