// The truth's joint_origin (sim/effects/effects.cc: MuJoCo's body moved so that the joint's
// frame becomes T Exp(xi)) against identification's joint_origin@J (scenarios/identify/
// effect_model.h: the PPOE chain's fixed transform times Exp(xi)): two independent codes, one
// meaning. On the humanoid with its torso (a coupled joint among them), the markers' poses that
// MuJoCo's kinematics give with the effect equal EffectModel's prediction with joint_origin@J =
// xi to 1e-9 at random postures; a sign or frame slip errs by millimetres.
#include <gtest/gtest.h>

#include <random>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "scenarios/identify/effect_model.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

TEST(JointOriginTruth, MujocoPosesEqualTheIdentifiedEffectModel) {
  const sim::DeclaredModel d =
      sim::LoadDeclaredModel(testing::SourceDir() + "/models/humanoid_upper_torso.declared.yaml");
  const sim::MjModelPtr m = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d, /*with_couplings=*/true);
  const kinematics::FrameId left = chain.ObservedFrame("left_marker");
  const EffectModel em(m.get(), chain, chain.end_effector, "", {left});

  // Errors of the scenario's size and larger, at a read joint of the torso, the coupled one, a
  // shoulder and an elbow (pos_mm, rot_deg).
  const std::vector<std::pair<std::string, Vec6>> errors = {
      {"torso_pitch_1", (Vec6() << 1.5, -0.8, 2.0, 0.3, -0.4, 0.2).finished()},
      {"torso_pitch_3", (Vec6() << -1.0, 0.6, 0.5, -0.2, 0.5, 0.1).finished()},
      {"shoulder_pitch", (Vec6() << 0.7, 1.9, -1.2, 0.45, 0.15, -0.3).finished()},
      {"l_elbow", (Vec6() << -2.0, -0.5, 1.1, -0.1, -0.35, 0.25).finished()}};
  std::string yaml = "{errors: {";
  std::vector<int> active;
  std::vector<double> theta;
  for (const auto& [joint, e] : errors) {
    char buf[256];
    std::snprintf(buf, sizeof(buf),
                  "%s: {pos_mm: [%.17g, %.17g, %.17g], rot_deg: [%.17g, %.17g, %.17g]}, ",
                  joint.c_str(), e[0], e[1], e[2], e[3], e[4], e[5]);
    yaml += buf;
    active.push_back(em.FindCandidate("joint_origin@" + joint));
    ASSERT_GE(active.back(), 0) << joint;
    for (int k = 0; k < 6; ++k) theta.push_back(e[k] * (k < 3 ? 1e-3 : kDeg));
  }
  yaml += "}}";
  sim::EffectList effects;
  effects.push_back(sim::MakeEffect("joint_origin", yaml));
  auto truth = sim::Simulation::Load(d.model_path, effects);

  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  EffectModel::Workspace ws = em.MakeWorkspace();
  double worst = 0.0, moved = 0.0;
  for (int trial = 0; trial < 8; ++trial) {
    Eigen::VectorXd cmd = Eigen::VectorXd::Zero(truth->num_actuated());
    Eigen::VectorXd q = Eigen::VectorXd::Zero(chain.model.nq());
    for (int k = 0; k < chain.model.nq(); ++k) {
      if (chain.IsCoupled(k)) continue;
      const auto& names = truth->actuated_joints();
      const int i = static_cast<int>(std::find(names.begin(), names.end(), chain.q_joints[k]) -
                                     names.begin());
      cmd[i] = q[k] = 0.8 * u(rng);
    }
    chain.ApplyCouplings(&q);
    truth->SetCommand(cmd);
    truth->Settle();
    const ConfigLoads loads = em.Loads(q);
    for (int point = 0; point < 2; ++point) {
      const lie::SE3 T = em.PredictPose(q, loads, active, theta.data(), ws, point);
      const lie::SE3 N = em.PredictPose(q, loads, {}, nullptr, ws, point);
      const Eigen::Isometry3d M = truth->Pose(point == 0 ? "right_marker" : "left_marker");
      worst = std::max({worst, (T.translation() - M.translation()).cwiseAbs().maxCoeff(),
                        (T.rotation() - M.linear()).cwiseAbs().maxCoeff()});
      moved = std::max(moved, (N.translation() - M.translation()).norm());
    }
  }
  std::printf(
      "joint_origin: truth vs identification's model %.3g (the errors move a hand by %.3g m)\n",
      worst, moved);
  EXPECT_LT(worst, 1e-9);
  EXPECT_GT(moved, 2e-3);  // the comparison is not of two nominal models
}

TEST(JointOriginTruth, BadInputIsOneLine) {
  const std::string model = testing::SourceDir() + "/models/humanoid_upper.xml";
  const auto message = [&](const std::string& yaml) -> std::string {
    try {
      sim::EffectList effects;
      effects.push_back(sim::MakeEffect("joint_origin", yaml));
      sim::Simulation::Load(model, effects);
    } catch (const InputError& e) {
      return e.what();
    }
    return "accepted";
  };
  const std::string unknown = message("{errors: {shoulder_pich: {pos_mm: [1, 0, 0]}}}");
  EXPECT_NE(unknown.find("has no joint named 'shoulder_pich'"), std::string::npos) << unknown;
  EXPECT_EQ(unknown.find('\n'), std::string::npos) << unknown;
  const std::string nan = message("{errors: {elbow: {rot_deg: [0, .nan, 0]}}}");
  EXPECT_NE(nan.find("expected a finite number"), std::string::npos) << nan;
  const std::string size = message("{errors: {elbow: {pos_mm: [1, 2]}}}");
  EXPECT_NE(size.find("expected [x, y, z]"), std::string::npos) << size;
  // neck_1_roll sits after neck_1_pitch in one body: its origin is not a body's pose.
  const std::string second = message("{errors: {neck_1_roll: {pos_mm: [1, 0, 0]}}}");
  EXPECT_NE(second.find("is not the first joint of body 'neck_1'"), std::string::npos) << second;
}

}  // namespace
}  // namespace flexbench::identify
