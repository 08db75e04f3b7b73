// The pf_* estimators through the Estimator interface: registry names choose the sensor sets,
// Params set the numbers and are validated with clear messages; the interface's measurements
// reach the filter and the belief carries the joint means and the end-effector pose.
#include "estimators/pf/pf_estimator.h"

#include <gtest/gtest.h>

#include "estimators/error.h"
#include "estimators/estimator.h"
#include "estimators/imu/imu_orientations.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"
#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::estimators {
namespace {

struct Rig {
  pf::testing::JskLikeArm arm;
  EstimatorSetup Setup(std::map<std::string, std::vector<double>> params = {}) const {
    EstimatorSetup s;
    s.model = &arm.model;
    s.end_effector = arm.grasp;
    s.imus = {ImuSetup{arm.imu2}, ImuSetup{arm.imu3}};
    s.params = Params(std::move(params), "test.yaml:1");
    s.seed = 9;
    return s;
  }
};

std::string ErrorOf(const std::string& name, const EstimatorSetup& setup) {
  try {
    MakeEstimator(name, setup);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(PfEstimator, RegistryNamesChooseTheSensors) {
  Rig rig;
  const EstimatorSetup s = rig.Setup();
  const auto config = [&](const char* name) {
    return dynamic_cast<const PfEstimator&>(*MakeEstimator(name, s)).config();
  };
  EXPECT_TRUE(config("pf_encoders").orientation_frames.empty());
  EXPECT_TRUE(config("pf_encoders").position_frames.empty());
  EXPECT_EQ(config("pf_encoders_ee").position_frames, std::vector<FrameId>{rig.arm.grasp});
  EXPECT_EQ(config("pf_encoders_imu").orientation_frames.size(), 2u);
  EXPECT_EQ(config("pf_all").position_frames.size(), 1u);
  EXPECT_EQ(config("pf_all").orientation_frames.size(), 2u);
  EXPECT_EQ(config("pf_bingham_unimodal").bingham_lambda, Vec4(-800, -800, -800, 0));
  EXPECT_EQ(config("pf_bingham_axisym").bingham_lambda, Vec4(-800, -800, 0, 0));
  // Table I defaults.
  const pf::ParticleFilterConfig c = config("pf_all");
  EXPECT_EQ(c.num_particles, 2048);
  EXPECT_EQ(c.kappa_w, 15.0);
  EXPECT_EQ(c.kappa_v, 5.0);
  EXPECT_EQ(c.kappa_0, 0.1);
  EXPECT_TRUE(c.position_cov.isApprox(0.01 * Mat3::Identity()));
  EXPECT_EQ(c.proposal, pf::Proposal::kBootstrap);
  EXPECT_EQ(c.resampling, pf::ResamplingScheme::kStratified);
}

TEST(PfEstimator, ParametersAreValidatedWithClearMessages) {
  Rig rig;
  EXPECT_NE(
      ErrorOf("pf_all", rig.Setup({{"kappa_v", {0.0}}})).find("kappa_v must be finite and > 0"),
      std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"kappa_w", {-1.0}}})).find("kappa_w"), std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"bingham_lambda", {0, 0, -800, -800}}}))
                .find("sorted ascending"),
            std::string::npos);
  EXPECT_NE(
      ErrorOf("pf_all", rig.Setup({{"bingham_lambda", {-700, -700, 100, 100}}})).find("shifted"),
      std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"bingham_lambda", {-800, 0}}})).find("needs 4 value(s)"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"particles", {100.5}}})).find("must be an integer"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"ee_variance", {0.01, 0.01}}})).find("1 or 3 values"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"ee_variance", {-0.01}}})).find("ee_variance"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"imus", {2}}})).find("names IMU 2"), std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"conjugate_proposal", {2}}})).find("must be 0 or 1"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"laplace_proposal", {0.5}}})).find("must be 0 or 1"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"conjugate_proposal", {1}}, {"laplace_proposal", {1}}}))
                .find("exclude each other"),
            std::string::npos);
  EXPECT_NE(ErrorOf("pf_all", rig.Setup({{"ess_threshold", {0.0}}})).find("ess_threshold"),
            std::string::npos);
  const std::string typo = ErrorOf("pf_all", rig.Setup({{"kapa_v", {5.0}}}));
  EXPECT_NE(typo.find("unknown parameter 'kapa_v'"), std::string::npos) << typo;
  EXPECT_NE(typo.find("test.yaml:1"), std::string::npos) << typo;
  EstimatorSetup no_imu = rig.Setup();
  no_imu.imus.clear();
  EXPECT_NE(ErrorOf("pf_encoders_imu", no_imu).find("needs at least one IMU"), std::string::npos);
}

TEST(PfEstimator, MeasurementsReachTheFilter) {
  Rig rig;
  auto est =
      MakeEstimator("pf_all", rig.Setup({{"particles", {512}}, {"conjugate_proposal", {1}}}));
  Eigen::VectorXd q(4);
  q << 0.2, 0.7, 0.4, 0.1;
  kinematics::PpoeData data(rig.arm.model);
  kinematics::ForwardKinematics(rig.arm.model, data, q);
  for (int step = 0; step < 20; ++step) {
    est->Predict(step);
    JointReading j;
    j.q = q;
    EXPECT_EQ(est->Update(j), UpdateStatus::kAccepted);
    for (FrameId f : {rig.arm.imu2, rig.arm.imu3}) {
      OrientationReading o;
      o.frame = f;
      o.q_base_frame = Quat(data.T_base_frame[f].rotation());
      EXPECT_EQ(est->Update(o), UpdateStatus::kAccepted);
    }
    PositionReading p;
    p.frame = rig.arm.grasp;
    p.p_base = data.T_base_frame[rig.arm.grasp].translation();
    EXPECT_EQ(est->Update(p), UpdateStatus::kAccepted);
    // A first IMU reading of zero specific force: no "up" to start its filter from.
    EXPECT_EQ(est->Update(ImuReading{}), UpdateStatus::kRejectedOutside);
    OrientationReading bad;
    bad.frame = rig.arm.imu2;
    bad.q_base_frame = Quat(1.5, 0.0, 0.0, 0.0);
    EXPECT_EQ(est->Update(bad), UpdateStatus::kRejectedOutside);
  }
  // What a scenario asks instead of the name: a particle filter's particles, after the step.
  ASSERT_NE(est->Particles(), nullptr);
  EXPECT_EQ(est->Particles(), &dynamic_cast<const PfEstimator&>(*est).filter().Summary());
  EXPECT_GT(est->Particles()->ess, 1.0);
  EXPECT_TRUE(est->FusesExternalMeasurements());
  EXPECT_FALSE(est->HasConfigurationPrior());
  const Belief b = est->Estimate();
  ASSERT_TRUE(b.has_joints);
  ASSERT_EQ(b.q.size(), 4);
  EXPECT_NEAR(b.q(1), q(1), 0.02);
  EXPECT_NEAR(b.q(2), q(2), 0.02);
  EXPECT_GT(b.q_std(0), 0.0);
  EXPECT_LT((b.T_base_ee.translation() - data.T_base_frame[rig.arm.grasp].translation()).norm(),
            0.03);
  EXPECT_TRUE(b.cov.allFinite());
  // Predict at the same time does not step again; Reset starts over with the same stream.
  const Belief again = est->Estimate();
  est->Predict(19);
  EXPECT_EQ(est->Estimate().q(0), again.q(0));
}

// Raw IMU readings reach the particle filter through its own Madgwick filters: the bits of the
// orientations of the same filters run outside and given as OrientationReadings after the step's
// joint reading, with either proposal. A step without joint reading gets its terms when the next
// step opens. The terms move the belief (against pf_encoders on the same readings).
TEST(PfEstimator, RawImuReadingsGiveTheBitsOfTheirFiltersOrientations) {
  Rig rig;
  const auto q_at = [](double t) {
    Eigen::VectorXd q(4);
    q << 0.3 * std::sin(t), 0.5 + 0.3 * std::sin(0.7 * t), 0.4 + 0.2 * std::cos(t), 0.1;
    return q;
  };
  kinematics::PpoeData data(rig.arm.model);
  const auto R_at = [&](double t, FrameId f) {
    kinematics::ForwardKinematics(rig.arm.model, data, q_at(t));
    return Mat3(data.T_base_frame[f].rotation());
  };
  const FrameId frames[2] = {rig.arm.imu2, rig.arm.imu3};
  for (int conjugate : {0, 1}) {
    EstimatorSetup setup =
        rig.Setup({{"particles", {256}}, {"conjugate_proposal", {1.0 * conjugate}}});
    setup.imus[0].filter_beta = 0.08;
    setup.imus[1].has_initial = true;
    setup.imus[1].q_base_frame_initial = Quat(R_at(0.0, frames[1]));
    auto raw = MakeEstimator("pf_encoders_imu", setup);
    auto given = MakeEstimator("pf_encoders_imu", setup);
    auto none = MakeEstimator("pf_encoders", setup);
    imu::ImuOrientations outside(setup.imus);
    const double dt = 0.005;
    int reading = 0;
    bool pending = false;  // `given` owes the terms of a step without joint reading
    for (int step = 1; step <= 40; ++step) {
      const double t_step = 0.1 * step;
      for (; (reading + 1) * dt <= t_step + 1e-12; ++reading) {
        const double t = (reading + 1) * dt;
        for (int k = 0; k < 2; ++k) {
          const Mat3 R = R_at(t, frames[k]);
          ImuReading z;
          z.t = t;
          z.imu = k;
          z.gyro = lie::SO3Log(R_at(t - dt, frames[k]).transpose() * R) / dt;
          z.accel = R.transpose() * Vec3(0.0, 0.0, 9.81);
          ASSERT_EQ(raw->Update(z), UpdateStatus::kAccepted);
          EXPECT_EQ(none->Update(z), UpdateStatus::kIgnored);
          outside.Feed(z);
        }
      }
      if (pending) {
        for (int k = 0; k < 2; ++k) {
          ASSERT_EQ(given->Update(outside.Take(k)), UpdateStatus::kAccepted);
        }
        pending = false;
      }
      for (Estimator* e : {raw.get(), given.get(), none.get()}) e->Predict(t_step);
      if (step == 20) {
        pending = true;
        continue;
      }
      JointReading j;
      j.t = t_step;
      j.q = q_at(t_step);
      j.q(1) += 0.05;
      j.q(2) -= 0.05;
      for (Estimator* e : {raw.get(), given.get(), none.get()}) {
        ASSERT_EQ(e->Update(j), UpdateStatus::kAccepted);
      }
      for (int k = 0; k < 2; ++k) {
        if (outside.fresh(k)) ASSERT_EQ(given->Update(outside.Take(k)), UpdateStatus::kAccepted);
      }
      const Belief a = raw->Estimate(), b = given->Estimate();
      ASSERT_TRUE(a.q == b.q) << "step " << step << " conjugate " << conjugate;
      ASSERT_TRUE(a.cov == b.cov) << "step " << step;
    }
    const Eigen::VectorXd d = raw->Estimate().q - none->Estimate().q;
    EXPECT_GT(d.cwiseAbs().maxCoeff(), 0.01) << "the IMU terms moved the estimate";
  }
}

// The IMUs that enter are chosen by index: of two IMUs on one frame, `imus: [0]` takes the
// first one's readings and ignores the second's.
TEST(PfEstimator, ImusEnterByIndexNotByFrame) {
  Rig rig;
  EstimatorSetup setup = rig.Setup({{"particles", {64}}, {"imus", {0}}});
  setup.imus = {ImuSetup{rig.arm.imu2}, ImuSetup{rig.arm.imu2}};
  auto est = MakeEstimator("pf_encoders_imu", setup);
  ImuReading z;
  z.accel = Vec3(0.0, 0.0, 9.81);
  z.imu = 0;
  EXPECT_EQ(est->Update(z), UpdateStatus::kAccepted);
  z.imu = 1;
  EXPECT_EQ(est->Update(z), UpdateStatus::kIgnored);
}

// On an augmented model whose identified offset of joint 1 has a standard deviation, the belief's
// covariance is the particles' plus that offset's through the kinematics. The particles are the
// same bits with and without the std (it changes no kinematics), so the difference is the
// parameter's part alone; the oracle is plain FK with joint 1 turned one std either way.
TEST(PfEstimator, IdentifiedParametersStdWidensTheBelief) {
  Rig rig;
  const double sigma = 2e-3;
  kinematics::ModelEffects exact = kinematics::ModelEffects::None(rig.arm.model);
  exact.joints[1].offset = 0.01;
  kinematics::ModelEffects uncertain = exact;
  uncertain.uncertainty.joints[1].offset = sigma * sigma;
  Eigen::VectorXd q(4);
  q << 0.2, 0.7, 0.4, 0.1;
  Mat6 cov[2];
  lie::SE3 T[2];
  for (int k = 0; k < 2; ++k) {
    EstimatorSetup setup = rig.Setup({{"particles", {256}},
                                      {"conjugate_proposal", {1}},
                                      {"kappa_w", {1e6}},
                                      {"kappa_v", {1e4}},
                                      {"kappa_0", {1e6}},
                                      {"initial_at_first_reading", {1}}});
    setup.effects = k == 0 ? &exact : &uncertain;
    auto est = MakeEstimator("pf_encoders", setup);
    for (int step = 0; step < 5; ++step) {
      est->Predict(step);
      JointReading j;
      j.q = q;
      ASSERT_EQ(est->Update(j), UpdateStatus::kAccepted);
    }
    cov[k] = est->Estimate().cov;
    T[k] = est->Estimate().T_base_ee;
  }
  EXPECT_EQ(T[0].translation(), T[1].translation());
  // The corrected joint 1 one std either way, through the plain kinematics.
  kinematics::PpoeData data(rig.arm.model);
  Eigen::VectorXd qc = q;
  qc[1] += 0.01;
  kinematics::ForwardKinematics(rig.arm.model, data, qc);
  const lie::SE3 T_0 = data.T_base_frame[rig.arm.grasp];
  Vec6 g = Vec6::Zero();
  for (const double sign : {1.0, -1.0}) {
    Eigen::VectorXd qs = qc;
    qs[1] += sign * sigma;
    kinematics::ForwardKinematics(rig.arm.model, data, qs);
    g += 0.5 * sign * T_0.Between(data.T_base_frame[rig.arm.grasp]).Log();
  }
  const Mat6 expected = g * g.transpose();
  EXPECT_LT((cov[1] - cov[0] - expected).norm(), 1e-3 * expected.norm())
      << (cov[1] - cov[0]) << "\n\n"
      << expected;
  EXPECT_GT(expected.norm(), 1e-2 * cov[0].norm());  // the std changes the belief measurably
}

}  // namespace
}  // namespace flexbench::estimators
