// The particle filter's steps must not touch the heap once it is constructed (the benchmark's
// target and the guidance for estimators). This binary replaces the global operator new/delete
// with counting versions (forwarding to malloc/free).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "estimators/estimator.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/pf/circular_quantile.h"
#include "estimators/pf/particle_filter.h"
#include "tests/common/counting_new.h"
#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::pf {
namespace {

using flexbench::testing::CountAllocations;

class NoAllocationTest : public ::testing::TestWithParam<Proposal> {};

TEST_P(NoAllocationTest, FilterStepsDoNotAllocate) {
  testing::JskLikeArm arm;
  ParticleFilterConfig c;
  c.position_frames = {arm.grasp};
  c.orientation_frames = {arm.imu2, arm.imu3};
  c.end_effector = arm.grasp;
  c.proposal = GetParam();
  ParticleFilter pf(arm.model, c, 1);
  Eigen::VectorXd q(4);
  q << 0.3, 0.6, 0.2, 0.0;
  kinematics::PpoeData data(arm.model);
  kinematics::ForwardKinematics(arm.model, data, q);
  const Quat q2(data.T_base_frame[arm.imu2].rotation());
  const Quat q3(data.T_base_frame[arm.imu3].rotation());
  const Vec3 p = data.T_base_frame[arm.grasp].translation();
  const long n = CountAllocations([&] {
    for (int step = 0; step < 5; ++step) {
      pf.Predict();
      pf.UpdateReference(q.data(), 4);
      pf.UpdateOrientation(arm.imu2, q2);
      pf.UpdateOrientation(arm.imu3, q3);
      pf.UpdatePosition(arm.grasp, Vec3::Zero(), p);
      pf.CompleteStep();
      pf.Summary();
      pf.StepLogLikelihood();
    }
    pf.Reset();
  });
  EXPECT_EQ(n, 0);
}

// The summary's tail quantiles on every path: the bands hold the quantiles, miss and move, or
// miss until the histogram fallback (and p = 0.5, always the fallback).
TEST(NoAllocation, TailQuantilesOnEveryPath) {
  const int n = 1000;
  std::vector<double> c(n), s(n), w(n);
  double sc = 0.0, ss = 0.0;
  for (int i = 0; i < n; ++i) {
    const double a = 0.002 * (i - 500) + (i % 7 == 0 ? 0.05 * std::sin(i) : 0.0);
    c[i] = std::cos(3.1 + a);
    s[i] = std::sin(3.1 + a);
    w[i] = (1.0 + (i % 3)) / (2.0 * n);
    sc += w[i] * c[i];
    ss += w[i] * s[i];
  }
  const double r = std::hypot(sc, ss);
  const double sigma = std::sqrt(-2.0 * std::log(r));
  CircularQuantileScratch scratch(n);
  const double probs[3] = {0.025, 0.975, 0.5};
  double out[3];
  int fallbacks = 0;
  const long allocations = CountAllocations([&] {
    for (const double inner : {1.6, 0.2, 2.9}) {
      fallbacks += WeightedCircularTailQuantiles(c.data(), s.data(), w.data(), n, sc / r, ss / r,
                                                 1e-14, inner * sigma, (inner + 0.3) * sigma, probs,
                                                 3, out, &scratch);
    }
  });
  EXPECT_EQ(allocations, 0);
  EXPECT_GE(fallbacks, 3);  // at least the medians
}

TEST_P(NoAllocationTest, EstimatorInterfaceDoesNotAllocate) {
  // The same through estimators::Estimator: typed measurements in, Belief out.
  testing::JskLikeArm arm;
  estimators::EstimatorSetup setup;
  setup.model = &arm.model;
  setup.end_effector = arm.grasp;
  setup.imus = {estimators::ImuSetup{arm.imu2}, estimators::ImuSetup{arm.imu3}};
  setup.params = estimators::Params(
      {{"conjugate_proposal", {GetParam() == Proposal::kEncoderConjugate ? 1.0 : 0.0}},
       {"laplace_proposal", {GetParam() == Proposal::kLaplace ? 1.0 : 0.0}}});
  auto est = estimators::MakeEstimator("pf_all", setup);
  Eigen::VectorXd q(4);
  q << 0.3, 0.6, 0.2, 0.0;
  kinematics::PpoeData data(arm.model);
  kinematics::ForwardKinematics(arm.model, data, q);
  estimators::Measurement joints =
      estimators::JointReading{0.0, q, estimators::JointVector::Zero(4)};
  estimators::Measurement o2 =
      estimators::OrientationReading{0.0, arm.imu2, Quat(data.T_base_frame[arm.imu2].rotation())};
  estimators::Measurement o3 =
      estimators::OrientationReading{0.0, arm.imu3, Quat(data.T_base_frame[arm.imu3].rotation())};
  estimators::PositionReading pr;
  pr.frame = arm.grasp;
  pr.p_base = data.T_base_frame[arm.grasp].translation();
  estimators::Measurement p = pr;
  // Raw IMU readings, which run the filter's Madgwick filters and add their terms.
  estimators::Measurement imus[2];
  for (int k = 0; k < 2; ++k) {
    const FrameId f = k == 0 ? arm.imu2 : arm.imu3;
    imus[k] =
        estimators::ImuReading{0.0, k, Vec3(0.01, 0.0, 0.02),
                               data.T_base_frame[f].rotation().transpose() * Vec3(0.0, 0.0, 9.81)};
  }
  double sink = 0.0;
  const long n = CountAllocations([&] {
    for (int step = 1; step <= 5; ++step) {
      for (estimators::Measurement& z : imus) {
        std::get<estimators::ImuReading>(z).t = step - 0.5;
        sink += est->Update(z) == estimators::UpdateStatus::kAccepted;
      }
      est->Predict(step);
      est->Update(joints);
      est->Update(o2);
      est->Update(o3);
      est->Update(p);
      sink += est->Estimate().q[1];
    }
  });
  EXPECT_EQ(n, 0);
  EXPECT_TRUE(std::isfinite(sink));
}

// Identified effects cost no allocation either: the corrected model is updated in
// place at every joint reading (kinematics::EffectiveChain), the particle filter refolds its
// batch kinematics, fk and the EKF add the readings' noise to their prior.
TEST_P(NoAllocationTest, EstimatorsWithIdentifiedEffectsDoNotAllocate) {
  testing::JskLikeArm arm;
  kinematics::ModelEffects fx = kinematics::ModelEffects::None(arm.model);
  for (int k = 0; k < arm.model.nq(); ++k)
    fx.masses[arm.model.joint_frame(k)] = {1.0, Vec3(0.1, 0, 0)};
  fx.joints[0].offset = 0.01;
  fx.joints[1].compliance = -2e-3;
  fx.joints[1].harmonic[0] = 1e-3;
  const FrameId j3 = arm.model.joint_frame(2);
  fx.frames[j3].bend = 1e-3;
  fx.frames[j3].bend_start = arm.model.joint_frame(1);
  fx.frames[j3].bend_dir = Vec3::UnitX();
  fx.mount = arm.model.joint_frame(0);
  fx.mount_compliance = Eigen::Vector2d(1e-3, 1e-3);
  // The fit's uncertainty, re-evaluated as sources at every reading.
  fx.uncertainty.joints[0].offset = 1e-8;
  fx.uncertainty.joints[1].compliance = 1e-9;
  fx.uncertainty.joints[1].harmonic[0] = 1e-8;
  fx.uncertainty.bend[j3] = 1e-9;
  fx.uncertainty.mount_compliance = Eigen::Vector2d(1e-9, 1e-9);
  fx.uncertainty.thermal = 1e-10;
  Eigen::VectorXd q(4);
  q << 0.3, 0.6, 0.2, 0.0;
  estimators::Measurement joints =
      estimators::JointReading{0.0, q, estimators::JointVector::Constant(4, 1e-3)};
  for (const char* name : {"pf_encoders", "fk", "ppoe_ekf"}) {
    estimators::EstimatorSetup setup;
    setup.model = &arm.model;
    setup.effects = &fx;
    setup.end_effector = arm.grasp;
    if (std::string(name) == "pf_encoders") {
      setup.params = estimators::Params(
          {{"conjugate_proposal", {GetParam() == Proposal::kEncoderConjugate ? 1.0 : 0.0}},
           {"laplace_proposal", {GetParam() == Proposal::kLaplace ? 1.0 : 0.0}}});
    } else {
      setup.params = estimators::Params({{"reading_noise", {1.0}}});
    }
    auto est = estimators::MakeEstimator(name, setup);
    double sink = 0.0;
    const long n = CountAllocations([&] {
      for (int step = 1; step <= 5; ++step) {
        est->Predict(step);
        est->Update(joints);
        sink += est->Estimate().T_base_ee.translation().x();
      }
    });
    EXPECT_EQ(n, 0) << name;
    EXPECT_TRUE(std::isfinite(sink)) << name;
  }
}

INSTANTIATE_TEST_SUITE_P(Proposals, NoAllocationTest,
                         ::testing::Values(Proposal::kBootstrap, Proposal::kEncoderConjugate,
                                           Proposal::kLaplace));

}  // namespace
}  // namespace flexbench::pf
