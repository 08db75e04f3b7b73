// The direct-fusion baseline (PF paper sec. IV-D): exact IMU orientations give the pitch angles
// back, whatever the IMUs' yaw, with 'yxz'; 'xyz' fails at its gimbal lock (a horizontal link).
#include "estimators/imu/direct_fusion.h"

#include <gtest/gtest.h>

#include "estimators/error.h"
#include "estimators/imu/imu_orientations.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::estimators {
namespace {

struct Rig {
  pf::testing::JskLikeArm arm;
  EstimatorSetup setup;
  Rig() {
    setup.model = &arm.model;
    setup.end_effector = arm.grasp;
    setup.imus = {ImuSetup{arm.imu2}, ImuSetup{arm.imu3}};
  }
};

// Feeds the encoders (with the pitch joints off by `offset`) and exact IMU orientations of the
// configuration q, pre-rotated by a yaw `drift`; returns the fused angles.
JointVector Fuse(Estimator& est, const Rig& rig, const Eigen::VectorXd& q, double offset,
                 double drift) {
  kinematics::PpoeData data(rig.arm.model);
  kinematics::ForwardKinematics(rig.arm.model, data, q);
  JointReading enc;
  enc.q = q;
  enc.q(1) += offset;
  enc.q(2) -= offset;
  enc.std = JointVector::Zero(4);
  EXPECT_EQ(est.Update(enc), UpdateStatus::kAccepted);
  const Quat yaw(Eigen::AngleAxisd(drift, Vec3::UnitZ()));
  for (FrameId f : {rig.arm.imu2, rig.arm.imu3}) {
    OrientationReading o;
    o.frame = f;
    o.q_base_frame = yaw * Quat(data.T_base_frame[f].rotation());
    EXPECT_EQ(est.Update(o), UpdateStatus::kAccepted);
  }
  return est.Estimate().q;
}

TEST(DirectFusion, RecoversPitchAnglesWithAnyYaw) {
  Rig rig;
  Eigen::VectorXd q(4);
  q << 0.5, 0.8, -0.4, 0.1;
  for (auto make : {MakeDirectFusionXyz, MakeDirectFusionYxz}) {
    auto est = make(rig.setup);
    const JointVector fused = Fuse(*est, rig, q, 0.05, 0.3);
    EXPECT_NEAR(fused(0), q(0), 1e-12);  // yaw joint: the encoder
    EXPECT_NEAR(fused(1), q(1), 1e-9);
    EXPECT_NEAR(fused(2), q(2), 1e-9);
    EXPECT_NEAR(fused(3), q(3), 1e-12);  // gripper: the encoder
    kinematics::PpoeData data(rig.arm.model);
    kinematics::ForwardKinematics(rig.arm.model, data, q);
    EXPECT_LT(
        (est->Estimate().T_base_ee.translation() - data.T_base_frame[rig.arm.grasp].translation())
            .norm(),
        1e-9);
  }
}

TEST(DirectFusion, XyzFailsAtGimbalLock) {
  Rig rig;
  Eigen::VectorXd q(4);
  q << 0.5, M_PI / 2, 0.3, 0.0;  // link2 horizontal: 'xyz' middle angle at 90 deg
  auto xyz = MakeDirectFusionXyz(rig.setup);
  auto yxz = MakeDirectFusionYxz(rig.setup);
  const JointVector a = Fuse(*xyz, rig, q, 0.0, 0.0);
  const JointVector b = Fuse(*yxz, rig, q, 0.0, 0.0);
  EXPECT_NEAR(b(1), q(1), 1e-9);
  EXPECT_NEAR(b(2), q(2), 1e-9);
  // The yaw stays in the x angle and adds to link2's rotation angle; link3's angle is then taken
  // against a wrong parent.
  EXPECT_GT(std::abs(a(1) - q(1)), 0.05);
  EXPECT_GT(std::abs(a(2) - q(2)), 0.05);
}

// Raw IMU readings run through the estimator's own Madgwick filters give the belief their
// orientations give as OrientationReadings (the same bits), and the fused angles follow the IMUs.
TEST(DirectFusion, RawImuReadingsGiveTheBeliefOfTheirOrientations) {
  Rig rig;
  rig.setup.imus[0].has_initial = true;
  rig.setup.imus[1].has_initial = true;
  Eigen::VectorXd q(4);
  q << 0.2, 0.6, -0.4, 0.0;
  kinematics::PpoeData data(rig.arm.model);
  kinematics::ForwardKinematics(rig.arm.model, data, q);
  const FrameId frames[2] = {rig.arm.imu2, rig.arm.imu3};
  // The filters start at the true orientations less the yaw the fusion cancels anyway.
  for (int k = 0; k < 2; ++k) {
    rig.setup.imus[k].q_base_frame_initial = Quat(data.T_base_frame[frames[k]].rotation());
  }
  auto raw = MakeDirectFusionYxz(rig.setup);
  auto given = MakeDirectFusionYxz(rig.setup);
  imu::ImuOrientations outside(rig.setup.imus);
  JointReading enc;
  enc.q = q;
  enc.q(1) += 0.1;  // encoders off: the fused pitch angles come from the IMUs
  enc.q(2) -= 0.1;
  enc.std = JointVector::Zero(4);
  for (int i = 1; i <= 200; ++i) {
    for (int k = 0; k < 2; ++k) {
      ImuReading z;
      z.t = 0.005 * i;
      z.imu = k;
      z.gyro = Vec3(0.01, -0.02, 0.005);  // a small bias
      z.accel = data.T_base_frame[frames[k]].rotation().transpose() * Vec3(0.0, 0.0, 9.81);
      ASSERT_EQ(raw->Update(z), UpdateStatus::kAccepted);
      ASSERT_EQ(outside.Feed(z), UpdateStatus::kAccepted);
      ASSERT_EQ(given->Update(outside.Take(k)), UpdateStatus::kAccepted);
    }
    if (i % 2 == 0) {
      enc.t = 0.005 * i;
      ASSERT_EQ(raw->Update(enc), UpdateStatus::kAccepted);
      ASSERT_EQ(given->Update(enc), UpdateStatus::kAccepted);
    }
    const Belief a = raw->Estimate(), b = given->Estimate();
    ASSERT_EQ(a.has_joints, b.has_joints);
    if (!a.has_joints) continue;
    ASSERT_TRUE(a.q == b.q) << "reading " << i;
    ASSERT_TRUE(a.cov == b.cov) << "reading " << i;
  }
  const JointVector fused = raw->Estimate().q;
  EXPECT_NEAR(fused(1), q(1), 0.01);
  EXPECT_NEAR(fused(2), q(2), 0.01);
}

TEST(DirectFusion, BadInput) {
  Rig rig;
  auto est = MakeDirectFusionYxz(rig.setup);
  OrientationReading o;
  o.frame = rig.arm.imu2;
  o.q_base_frame = Quat(2.0, 0.0, 0.0, 0.0);
  EXPECT_EQ(est->Update(o), UpdateStatus::kRejectedOutside);
  o.q_base_frame = Quat(NAN, 0.0, 0.0, 0.0);
  EXPECT_EQ(est->Update(o), UpdateStatus::kRejectedNonFinite);
  o.frame = rig.arm.grasp;
  o.q_base_frame = Quat::Identity();
  EXPECT_EQ(est->Update(o), UpdateStatus::kIgnored);
  JointReading j;
  j.q = JointVector::Zero(3);
  EXPECT_THROW(est->Update(j), InputError);
  EstimatorSetup no_imu = rig.setup;
  no_imu.imus.clear();
  EXPECT_THROW(MakeDirectFusionXyz(no_imu), InputError);
  EstimatorSetup with_params = rig.setup;
  with_params.params = Params({{"beta", {0.1}}});
  EXPECT_THROW(MakeDirectFusionXyz(with_params), InputError);
}

}  // namespace
}  // namespace flexbench::estimators
