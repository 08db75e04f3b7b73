// The Lie-group EKF: analytic against numeric Jacobians on the manifold, the first iteration is
// [PPOE eqs. 20-23], Monte-Carlo consistency (NEES within chi-square bounds), bad input, no heap.
#include <gtest/gtest.h>

#include <random>

#include "estimators/ekf/lg_ekf.h"
#include "estimators/ekf/measurement_model.h"
#include "estimators/lie/sampling.h"
#include "estimators/stats/chi_square.h"
#include "tests/common/counting_new.h"

namespace flexbench::estimators {
namespace {

using lie::SE3;

PinholeCamera Camera() {
  PinholeCamera c;
  c.fx = c.fy = 580.0;
  c.cx = 320.0;
  c.cy = 240.0;
  c.width = 640;
  c.height = 480;
  return c;
}

// The camera 1.2 m in front of the base looking back at it (optical z toward -x of the base).
SE3 CameraPose() {
  Mat3 R;
  R << 0, 0, -1,  //
      1, 0, 0,    //
      0, -1, 0;
  return SE3(R.transpose().transpose(), Vec3(1.2, 0.0, 0.3));
}

// Test poses: identity, near identity, random (fixed seed), all in front of the camera.
std::vector<SE3> TestPoses() {
  std::vector<SE3> poses = {SE3::Identity(),
                            SE3::Exp((Vec6() << 1e-4, -2e-4, 1e-4, 1e-5, 2e-5, -3e-5).finished())};
  std::mt19937_64 rng(7);
  for (int i = 0; i < 4; ++i) {
    SE3 X = lie::RandomSE3(rng, 0.1);
    poses.push_back(SE3::Exp((Vec6() << 0, 0, 0, 0.3 * (i - 2), 0.2, 0.1).finished()) *
                    SE3(Mat3::Identity(), X.translation()));
  }
  return poses;
}

std::vector<std::unique_ptr<MeasurementModel>> Models() {
  std::vector<std::unique_ptr<MeasurementModel>> m;
  const Vec3 p_ee(0.02, -0.03, 0.05);
  m.push_back(std::make_unique<PixelPointModel>(
      Camera(), CameraPose(), p_ee, Eigen::Vector2d(300, 250), Eigen::Matrix2d::Identity() * 0.25));
  std::array<Vec3, 4> corners = {Vec3(-0.03, 0.03, 0.06), Vec3(0.03, 0.03, 0.06),
                                 Vec3(0.03, -0.03, 0.06), Vec3(-0.03, -0.03, 0.06)};
  std::array<Eigen::Vector2d, 4> uv = {Eigen::Vector2d(300, 250), Eigen::Vector2d(330, 250),
                                       Eigen::Vector2d(330, 220), Eigen::Vector2d(300, 220)};
  m.push_back(std::make_unique<TagCornersModel>(Camera(), CameraPose(), corners, uv,
                                                Eigen::Matrix<double, 8, 8>::Identity() * 0.25));
  Mat6 plane_cov = Mat6::Zero();
  plane_cov.diagonal() << 0.5, 0.5, 0.001, 0.017, 0.017, 0.17;
  m.push_back(std::make_unique<PlaneDistanceModel>(
      SE3(lie::SO3Exp(Vec3(0.1, -0.2, 0.3)), Vec3(0.3, 0.1, -0.2)), plane_cov, 1e-3, p_ee, 0.01));
  m.push_back(std::make_unique<PositionModel>(p_ee, Vec3(0.1, 0.0, 0.05), Mat3::Identity() * 1e-4));
  m.push_back(std::make_unique<PoseModel>(SE3(lie::SO3Exp(Vec3(0.3, 0.0, 0.1)), p_ee),
                                          SE3(lie::SO3Exp(Vec3(0.2, 0.1, 0.0)), Vec3(0.1, 0, 0)),
                                          Mat6::Identity() * 1e-4));
  return m;
}

class JacobianTest : public ::testing::TestWithParam<int> {};

TEST_P(JacobianTest, AnalyticMatchesNumericOnTheManifold) {
  const auto models = Models();
  const MeasurementModel& model = *models[GetParam()];
  for (const SE3& X : TestPoses()) {
    MeasJac Ja, Jn;
    NoiseJac Ma, Mn;
    ASSERT_TRUE(model.AnalyticJacobians(X, &Ja, &Ma));
    for (double eps : {1e-6, 1e-5, 1e-4}) {
      ASSERT_TRUE(NumericJacobians(model, X, &Jn, &Mn, eps));
      const double scale = 1.0 + Ja.cwiseAbs().maxCoeff();
      EXPECT_LT((Ja - Jn).cwiseAbs().maxCoeff(), 1e-5 * scale) << "eps " << eps << "\n"
                                                               << Ja << "\n\n"
                                                               << Jn;
      EXPECT_LT((Ma - Mn).cwiseAbs().maxCoeff(), 1e-5 * (1.0 + Ma.cwiseAbs().maxCoeff()));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Models, JacobianTest, ::testing::Range(0, 5));

TEST(LgEkf, FirstIterationIsEquations20To23) {
  const PositionModel model(Vec3(0.0, 0.0, 0.3), Vec3(0.01, -0.02, 0.31), Mat3::Identity() * 1e-4);
  SE3 X = SE3::Identity();
  Mat6 P = Mat6::Identity() * 1e-3;
  P(3, 3) = 4e-3;
  const Mat6 P0 = P;
  LgEkfOptions o;
  o.max_iterations = 1;
  ASSERT_EQ(LgEkfUpdate(model, o, &X, &P).status, UpdateStatus::kAccepted);
  MeasJac J;
  NoiseJac M;
  model.AnalyticJacobians(SE3::Identity(), &J, &M);
  const Eigen::Matrix<double, 3, 6> H = -J;
  const Mat3 S = H * P0 * H.transpose() + Mat3::Identity() * 1e-4;
  const Eigen::Matrix<double, 6, 3> K = P0 * H.transpose() * S.inverse();  // [PPOE eq. 20]
  MeasVec r;
  model.Residual(SE3::Identity(), NoiseVec::Zero(3), &r);
  const Vec6 m = K * r;                                                           // [PPOE eq. 21]
  EXPECT_TRUE(X.IsApprox(SE3::Exp(m), 1e-12));                                    // [PPOE eq. 22]
  EXPECT_LT((P - (Mat6::Identity() - K * H) * P0).cwiseAbs().maxCoeff(), 1e-12);  // [PPOE eq. 23]
}

// GTSAM-style Monte-Carlo consistency: truth drawn from the prior, a measurement drawn from
// the model, the posterior's NEES averaged over many runs lies in the chi-square bounds.
void ExpectConsistent(int model_index, double prior_scale, int runs) {
  std::mt19937_64 rng(1234 + model_index);
  Mat6 P0 = Mat6::Identity() * prior_scale;
  P0.block<3, 3>(3, 3) *= 0.1;
  lie::GaussianSampler<6> prior(P0);
  double nees_sum = 0.0;
  const auto models = Models();
  for (int run = 0; run < runs; ++run) {
    const SE3 X_bar = TestPoses()[2 + run % 4];
    const SE3 X_true = X_bar.Plus(prior.Sample(rng));
    // A measurement of the truth: residual 0 at the truth with noise drawn from Sigma_v.
    const MeasurementModel& proto = *models[model_index];
    lie::GaussianSampler<kMaxNoiseDim> noise([&] {
      Eigen::Matrix<double, kMaxNoiseDim, kMaxNoiseDim> S =
          Eigen::Matrix<double, kMaxNoiseDim, kMaxNoiseDim>::Identity() * 1e-300;
      S.topLeftCorner(proto.NoiseDim(), proto.NoiseDim()) = proto.Sigma_v();
      return S;
    }());
    const NoiseVec v = noise.Sample(rng).head(proto.NoiseDim());
    std::unique_ptr<MeasurementModel> model;
    if (model_index == 3) {
      const Vec3 p_ee(0.02, -0.03, 0.05);
      model = std::make_unique<PositionModel>(p_ee, X_true * p_ee + v.head<3>(),
                                              Mat3::Identity() * 1e-4);
    } else {
      const Vec3 p_ee(0.02, -0.03, 0.05);
      const SE3 T_base_cam = CameraPose();
      Eigen::Vector2d uv;
      Camera().Project(T_base_cam.Inverse() * (X_true * p_ee), &uv);
      model = std::make_unique<PixelPointModel>(Camera(), T_base_cam, p_ee, uv + v.head<2>(),
                                                Eigen::Matrix2d::Identity() * 0.25);
    }
    SE3 X = X_bar;
    Mat6 P = P0;
    ASSERT_EQ(LgEkfUpdate(*model, LgEkfOptions{}, &X, &P).status, UpdateStatus::kAccepted);
    const Vec6 e = X.Between(X_true).Log();
    nees_sum += e.dot(P.ldlt().solve(e));
  }
  const auto bounds = stats::MeanChiSquareBounds(6, runs, 0.01);
  const double nees = nees_sum / runs;
  EXPECT_GT(nees, bounds.lower);
  EXPECT_LT(nees, bounds.upper);
}

TEST(LgEkf, MonteCarloConsistencyPosition) { ExpectConsistent(3, 1e-4, 2000); }
TEST(LgEkf, MonteCarloConsistencyPixel) { ExpectConsistent(0, 1e-4, 2000); }

TEST(LgEkf, IteratingConvergesToTheMapEstimate) {
  // A strongly nonlinear case: large rotational prior, precise pixel. The iterated estimate
  // must satisfy the MAP optimality condition better than a single step.
  const Vec3 p_ee(0.0, 0.0, 0.4);
  const SE3 T_base_cam = CameraPose();
  const SE3 X_true = SE3::Exp((Vec6() << 0, 0, 0, 0.0, 0.25, 0.0).finished());
  Eigen::Vector2d uv;
  Camera().Project(T_base_cam.Inverse() * (X_true * p_ee), &uv);
  const PixelPointModel model(Camera(), T_base_cam, p_ee, uv, Eigen::Matrix2d::Identity() * 0.01);
  Mat6 P0 = Mat6::Identity() * 1e-6;
  P0(4, 4) = 0.09;
  auto residual_after = [&](int iterations) {
    SE3 X;
    Mat6 P = P0;
    LgEkfOptions o;
    o.max_iterations = iterations;
    LgEkfUpdate(model, o, &X, &P);
    MeasVec r;
    model.Residual(X, NoiseVec::Zero(2), &r);
    return r.norm();
  };
  EXPECT_LT(residual_after(10), 0.1 * residual_after(1));
}

TEST(LgEkf, NonFiniteMeasurementIsRejectedAndStateUntouched) {
  const PositionModel model(Vec3::Zero(), Vec3(NAN, 0, 0), Mat3::Identity());
  SE3 X;
  Mat6 P = Mat6::Identity();
  EXPECT_EQ(LgEkfUpdate(model, LgEkfOptions{}, &X, &P).status, UpdateStatus::kRejectedNonFinite);
  EXPECT_TRUE(X.IsApprox(SE3::Identity()));
  EXPECT_TRUE(P.isApprox(Mat6::Identity()));
}

TEST(LgEkf, PointBehindTheCameraIsRejected) {
  const PixelPointModel model(Camera(), CameraPose(), Vec3(2.0, 0, 0), Eigen::Vector2d(320, 240),
                              Eigen::Matrix2d::Identity());
  SE3 X;
  Mat6 P = Mat6::Identity() * 1e-4;
  EXPECT_EQ(LgEkfUpdate(model, LgEkfOptions{}, &X, &P).status, UpdateStatus::kRejectedOutside);
}

TEST(LgEkf, GateRejectsOutliers) {
  const PositionModel model(Vec3::Zero(), Vec3(1.0, 0, 0), Mat3::Identity() * 1e-6);
  SE3 X;
  Mat6 P = Mat6::Identity() * 1e-6;
  LgEkfOptions o;
  o.gate_nis = stats::ChiSquareQuantile(0.999, 3);
  EXPECT_EQ(LgEkfUpdate(model, o, &X, &P).status, UpdateStatus::kRejectedGating);
}

TEST(LgEkf, RepairCovarianceClampsNegativeEigenvalues) {
  Mat6 P = Mat6::Identity();
  P(0, 0) = -1.0;
  EXPECT_TRUE(RepairCovariance(&P, 1e-9));
  EXPECT_GE(Eigen::SelfAdjointEigenSolver<Mat6>(P).eigenvalues().minCoeff(), 1e-9 * 0.999);
  Mat6 Q = Mat6::Identity();
  EXPECT_FALSE(RepairCovariance(&Q, 1e-9));
}

TEST(LgEkf, UpdateDoesNotAllocate) {
  const auto models = Models();
  for (const auto& model : models) {
    SE3 X = TestPoses()[3];
    Mat6 P = Mat6::Identity() * 1e-4;
    for (bool numeric : {false, true}) {
      LgEkfOptions o;
      o.numeric_jacobians = numeric;
      EXPECT_EQ(testing::CountAllocations([&] { LgEkfUpdate(*model, o, &X, &P); }), 0)
          << "numeric " << numeric;
    }
  }
}

TEST(ChiSquare, QuantilesMatchKnownValues) {
  EXPECT_NEAR(stats::ChiSquareQuantile(0.95, 1), 3.841458820694124, 1e-9);
  EXPECT_NEAR(stats::ChiSquareQuantile(0.80, 2), 3.218875824868201, 1e-9);
  EXPECT_NEAR(stats::ChiSquareQuantile(0.99, 6), 16.81189383, 1e-6);
  // Large dof: the Wilson-Hilferty approximation is accurate to ~1e-2 at 600 dof.
  const double wh = 600 * std::pow(1 - 2.0 / 5400 - 1.959963985 * std::sqrt(2.0 / 5400), 3);
  EXPECT_NEAR(stats::ChiSquareQuantile(0.025, 600), wh, 0.05);
  EXPECT_NEAR(stats::ChiSquareCdf(stats::ChiSquareQuantile(0.3, 4.5), 4.5), 0.3, 1e-12);
}

}  // namespace
}  // namespace flexbench::estimators
