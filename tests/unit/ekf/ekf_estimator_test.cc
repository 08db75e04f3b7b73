// Bad input through the estimators themselves (ppoe_ekf, naive_ekf), not only the update
// function: NaN, infinite and out-of-image readings are rejected with their status and leave
// the belief untouched, and no sequence of finite readings, however extreme, produces a NaN.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <random>

#include "estimators/estimator.h"
#include "estimators/kinematics/ppoe_model.h"

namespace flexbench::estimators {
namespace {

using kinematics::Joint;
using kinematics::PpoeModel;
using lie::SE3;

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// A 3-joint arm with PPOE sources at its base and joints, a tag frame on the hand and a camera
// 1 m in front of it looking back (optical z along -x of the base).
struct Rig {
  Rig() {
    Mat6 base = Mat6::Zero();
    base.diagonal() << 0, 0, 0, 1e-3, 1e-3, 1e-4;
    const auto l1 = model.AddLink(kinematics::kBaseFrame, "l1", SE3::Identity(),
                                  Joint::Revolute(Vec3::UnitZ()), base);
    Mat6 joint = Mat6::Zero();
    joint(5, 5) = 1e-4;
    const auto l2 = model.AddLink(l1, "l2", SE3(Mat3::Identity(), Vec3(0, 0, 0.3)),
                                  Joint::Revolute(Vec3::UnitY()), joint);
    const auto l3 = model.AddLink(l2, "l3", SE3(Mat3::Identity(), Vec3(0.3, 0, 0)),
                                  Joint::Revolute(Vec3::UnitY()), joint);
    ee = model.AddFrame(l3, "ee", SE3(Mat3::Identity(), Vec3(0.2, 0, 0)));
    Mat3 R;         // columns: optical x, y, z in the base frame
    R << 0, 0, -1,  //
        1, 0, 0,    //
        0, -1, 0;
    R = R.transpose().eval();
    camera = model.AddFrame(kinematics::kBaseFrame, "camera", SE3(R, Vec3(1.5, 0, 0.3)));
  }
  EstimatorSetup Setup(const std::string& name) const {
    EstimatorSetup s;
    s.model = &model;
    s.end_effector = ee;
    CameraSetup cam;
    cam.intrinsics.fx = cam.intrinsics.fy = 600.0;
    cam.intrinsics.cx = 320.0;
    cam.intrinsics.cy = 240.0;
    cam.intrinsics.width = 640;
    cam.intrinsics.height = 480;
    cam.frame = camera;
    s.cameras.push_back(cam);
    if (name == "naive_ekf") {
      s.params = Params({{"std_trans_m", {0.07, 0.07, 0.03}}, {"std_rot_deg", {5, 5, 15}}});
    }
    return s;
  }
  JointReading Joints(double a, double b, double c) const {
    JointReading j;
    j.q.resize(3);
    j.q << a, b, c;
    j.std = JointVector::Constant(3, 1e-3);
    return j;
  }
  PpoeModel model{"bad_input_rig"};
  kinematics::FrameId ee = -1;
  kinematics::FrameId camera = -1;
};

bool SameBelief(const Belief& a, const Belief& b) {
  return a.T_base_ee.rotation() == b.T_base_ee.rotation() &&
         a.T_base_ee.translation() == b.T_base_ee.translation() && a.cov == b.cov;
}

bool Finite(const Belief& b) {
  return b.T_base_ee.rotation().allFinite() && b.T_base_ee.translation().allFinite() &&
         b.cov.allFinite();
}

PixelPoint Pixel(kinematics::FrameId frame, double u, double v) {
  PixelPoint m;
  m.frame = frame;
  m.uv << u, v;
  m.cov = Mat2::Identity() * 0.25;
  return m;
}

// The capability query a scenario asks instead of the name, against what each estimator does:
// a configuration-dependent prior changes with the joints, a static one does not, and fk
// ignores what is not a joint reading.
TEST(EstimatorCapabilities, AnswersMatchBehaviour) {
  const Rig rig;
  for (const char* name : {"fk", "ppoe_ekf", "naive_ekf"}) {
    SCOPED_TRACE(name);
    auto est = MakeEstimator(name, rig.Setup(name));
    EXPECT_EQ(est->Particles(), nullptr);
    const auto prior = [&](double b) {
      est->Reset();
      EXPECT_EQ(est->Update(rig.Joints(0.1, b, 0.3)), UpdateStatus::kAccepted);
      return est->Estimate().cov;
    };
    const bool varies = !prior(0.2).isApprox(prior(1.1), 1e-6);
    EXPECT_EQ(est->HasConfigurationPrior(), varies);
    PositionReading p;
    p.frame = rig.ee;
    p.p_base = Vec3(0.5, 0.0, 0.3);
    p.cov = 1e-6 * Mat3::Identity();
    const UpdateStatus st = est->Update(p);
    EXPECT_EQ(est->FusesExternalMeasurements(), st != UpdateStatus::kIgnored) << ToString(st);
  }
}

class EkfEstimatorBadInput : public ::testing::TestWithParam<const char*> {};

TEST_P(EkfEstimatorBadInput, NonFiniteAndOutOfImageReadingsAreRejectedAndChangeNothing) {
  const Rig rig;
  std::unique_ptr<Estimator> est = MakeEstimator(GetParam(), rig.Setup(GetParam()));
  EXPECT_EQ(est->Update(rig.Joints(kNan, 0.2, 0.3)), UpdateStatus::kRejectedNonFinite);
  EXPECT_EQ(est->Update(Pixel(rig.ee, 320, 240)), UpdateStatus::kIgnored);  // no prior yet
  ASSERT_EQ(est->Update(rig.Joints(0.1, 0.2, 0.3)), UpdateStatus::kAccepted);
  const Belief prior = est->Estimate();
  ASSERT_TRUE(Finite(prior));

  struct Case {
    const char* what;
    Measurement z;
    UpdateStatus expected;
  };
  TagCorners tag;
  tag.frame = rig.ee;
  for (int k = 0; k < 4; ++k) {
    tag.p_frame[k] = Vec3(0.0, 0.02 * (k % 2 ? 1 : -1), 0.02 * (k / 2 ? 1 : -1));
    tag.uv[k] << 320 + 5 * k, 240;
  }
  tag.cov *= 0.25;
  TagCorners tag_nan = tag;
  tag_nan.uv[2].x() = kNan;
  TagCorners tag_inf_cov = tag;
  tag_inf_cov.cov(3, 3) = kInf;
  TagCorners tag_outside = tag;
  tag_outside.uv[1] << 700, 240;
  PlaneContact plane;
  plane.frame = rig.ee;
  plane.plane_cov = Mat6::Identity() * 1e-4;
  plane.distance = kInf;
  PositionReading position;
  position.frame = rig.ee;
  position.p_base << kNan, 0, 0;
  PoseReading pose;
  pose.frame = rig.ee;
  pose.cov = Mat6::Identity() * 1e-4;
  pose.cov(0, 0) = kNan;
  PixelPoint pixel_cov = Pixel(rig.ee, 320, 240);
  pixel_cov.cov(1, 1) = kInf;
  const Case cases[] = {
      {"pixel NaN", Pixel(rig.ee, kNan, 240), UpdateStatus::kRejectedNonFinite},
      {"pixel inf", Pixel(rig.ee, 320, kInf), UpdateStatus::kRejectedNonFinite},
      {"pixel covariance inf", pixel_cov, UpdateStatus::kRejectedNonFinite},
      {"pixel left of the image", Pixel(rig.ee, -3, 240), UpdateStatus::kRejectedOutside},
      {"pixel below the image", Pixel(rig.ee, 320, 481), UpdateStatus::kRejectedOutside},
      {"tag corner NaN", tag_nan, UpdateStatus::kRejectedNonFinite},
      {"tag covariance inf", tag_inf_cov, UpdateStatus::kRejectedNonFinite},
      {"tag corner outside", tag_outside, UpdateStatus::kRejectedOutside},
      {"contact distance inf", plane, UpdateStatus::kRejectedNonFinite},
      {"position NaN", position, UpdateStatus::kRejectedNonFinite},
      {"pose covariance NaN", pose, UpdateStatus::kRejectedNonFinite},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(est->Update(c.z), c.expected) << c.what;
    EXPECT_TRUE(SameBelief(est->Estimate(), prior)) << c.what << " changed the belief";
  }
}

TEST_P(EkfEstimatorBadInput, ExtremeFiniteReadingsNeverGiveNan) {
  const Rig rig;
  std::unique_ptr<Estimator> est = MakeEstimator(GetParam(), rig.Setup(GetParam()));
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> pixel(0.0, 639.0), angle(-1.0, 1.0);
  const double scales[] = {1e-300, 1e-12, 0.25, 1e6, 1e300};
  int accepted = 0;
  for (int round = 0; round < 40; ++round) {
    ASSERT_NE(est->Update(rig.Joints(angle(rng), angle(rng), angle(rng))),
              UpdateStatus::kRejectedNonFinite);
    for (int k = 0; k < 5; ++k) {
      PixelPoint p = Pixel(rig.ee, pixel(rng), 0.75 * pixel(rng));
      p.cov = Mat2::Identity() * scales[(round + k) % 5];
      accepted += est->Update(p) == UpdateStatus::kAccepted;
      PositionReading pos;
      pos.frame = rig.ee;
      pos.p_base = Vec3(1e150 * angle(rng), 0.5 * angle(rng), 1e-150);
      pos.cov = Mat3::Identity() * scales[(round + 2 * k) % 5];
      accepted += est->Update(pos) == UpdateStatus::kAccepted;
      PlaneContact c;
      c.frame = rig.ee;
      c.T_base_plane = SE3(lie::SO3Exp(Vec3(angle(rng), angle(rng), angle(rng))), Vec3::Zero());
      c.plane_cov = Mat6::Identity() * scales[(round + k + 1) % 5];
      c.distance = 1e100 * angle(rng);
      c.std = 1e-3;
      accepted += est->Update(c) == UpdateStatus::kAccepted;
      ASSERT_TRUE(Finite(est->Estimate())) << "round " << round << ", reading " << k;
    }
  }
  EXPECT_GT(accepted, 0);  // the storm did reach the filter
}

INSTANTIATE_TEST_SUITE_P(Estimators, EkfEstimatorBadInput,
                         ::testing::Values("ppoe_ekf", "naive_ekf"),
                         [](const ::testing::TestParamInfo<const char*>& i) {
                           return std::string(i.param);
                         });

}  // namespace
}  // namespace flexbench::estimators
