// Dynamic effects in the calibrated model: the MJCF `flexbench export` writes from a declared file
// carrying dynamic identification's effects moves as identification's rollouts of the declared
// MJCF with those effects (sim::ApplyDynamic on the loaded model, not the writer's text), and a
// released link mode sags, settled by MuJoCo, as the declared chain's standing part of the mode
// predicts (a link bending model written separately, estimators/kinematics).
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>
#include <unistd.h>

#include <filesystem>
#include <random>
#include <string>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "scenarios/identify/dynamic/rollout.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/export_model.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;
namespace dyn = identify::dynamic;

class DynamicExport : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("flexbench_dynexport_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    declared_ =
        sim::LoadDeclaredModel(std::string(FLEXBENCH_SOURCE_DIR) + "/models/jsk_arm.declared.yaml");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // `declared_` with `effects` written as dynamic identification writes them, exported.
  std::string Export(const std::vector<sim::IdentifiedEffect>& effects,
                     std::vector<std::string>* skipped = nullptr) {
    sim::DeclaredModel d = declared_;
    d.identified_effects = effects;
    const sim::ExportedModel out = sim::ExportMjcf(d);
    if (skipped) *skipped = out.skipped;
    const fs::path path = dir_ / "calibrated.xml";
    testing::WriteFile(path, out.text);
    return path.string();
  }

  fs::path dir_;
  sim::DeclaredModel declared_;
};

sim::IdentifiedEffect Effect(const std::string& name, std::vector<double> v) {
  return {name, std::move(v), {}, "", "test:1", {}};
}

// Every fitted family at once, at values of a realistic size, each a different joint.
const std::vector<sim::IdentifiedEffect>& AllFamilies() {
  static const std::vector<sim::IdentifiedEffect> effects = {
      Effect("joint_damping@link2_pitch_joint", {0.3}),
      Effect("joint_friction@link3_pitch_joint", {0.08}),
      Effect("joint_armature@link2_pitch_joint", {0.012}),
      Effect("servo_gain@link1_yaw_joint", {1.3}),
      Effect("link_mode@link2_b", {1.2, 1.6}),
      Effect("payload_mass@gripper_link", {0.15}),
  };
  return effects;
}

TEST_F(DynamicExport, TheExportedModelMovesAsTheIdentificationsRollout) {
  std::vector<std::string> skipped;
  std::vector<sim::IdentifiedEffect> effects = AllFamilies();
  effects.push_back(Effect("servo_delay@link3_pitch_joint", {0.02}));
  const std::string path = Export(effects, &skipped);
  ASSERT_EQ(skipped.size(), 1u);
  EXPECT_NE(skipped[0].find("servo_delay@link3_pitch_joint"), std::string::npos) << skipped[0];

  // The identification's model: the declared MJCF with the same terms, delay left out (the MJCF
  // has no form for it).
  std::vector<dyn::DynamicTerm> terms;
  for (const sim::DeclaredDynamic& e : sim::DynamicEntries(AllFamilies())) {
    terms.push_back({e.row->kind, e.location, {e.values[0], e.values[1]}});
  }
  const dyn::RolloutModel model(sim::LoadModel(declared_.model_path), declared_.model_path, {});
  std::unique_ptr<sim::Simulation> fitted = model.Make(terms);
  std::unique_ptr<sim::Simulation> exported = sim::Simulation::Load(path);
  ASSERT_EQ(fitted->model()->nq, exported->model()->nq);
  const int n = fitted->num_actuated();
  Eigen::VectorXd cmd(n);
  double worst = 0.0, moved = 0.0;
  for (int k = 0; k <= 1000; ++k) {  // 2 s of a swinging command at 500 Hz
    const double t = k * 0.002;
    for (int j = 0; j < n; ++j) cmd[j] = 0.4 * std::sin(2.0 * M_PI * (0.7 + 0.3 * j) * t);
    cmd[1] += 0.6;
    for (sim::Simulation* s : {fitted.get(), exported.get()}) {
      s->SetCommand(cmd);
      if (k == 0) s->Settle();
      s->Step(1);
    }
    for (int i = 0; i < fitted->model()->nq; ++i) {
      worst = std::max(worst, std::abs(fitted->data()->qpos[i] - exported->data()->qpos[i]));
      moved = std::max(moved, std::abs(fitted->data()->qpos[i] - fitted->model()->qpos0[i]));
    }
  }
  EXPECT_GT(moved, 0.3);
  EXPECT_LT(worst, 1e-9);
}

TEST_F(DynamicExport, TheExportedMjcfReleasesTheModeAndLeavesTheOtherLinksList) {
  const std::string path = Export({Effect("link_mode@link2_b", {1.2, 1.6})});
  const std::string text = testing::ReadFile(path);
  EXPECT_NE(text.find("effect:link_bending\" data=\"link3_bend_y link3_bend_x\""),
            std::string::npos);
  sim::MjModelPtr m = sim::LoadModel(path);
  const int j = mj_name2id(m.get(), mjOBJ_JOINT, "link2_bend_y");
  ASSERT_GE(j, 0);
  EXPECT_DOUBLE_EQ(m->jnt_stiffness[j], 1.2 * 220.0);
  EXPECT_DOUBLE_EQ(m->dof_damping[m->jnt_dofadr[j]], 1.6 * 0.3);
}

// MuJoCo settles the exported arm (its modes released, their springs the fitted ones); the
// declared chain with the same file's effects (the modes' standing part: a bend of compliance
// 1 / (scale k) at mid-link under the load) predicts the grasp point. The chain takes the load
// of its frames' masses about the link's middle (the link's own near half included) at the
// reading, MuJoCo the bending joint's at the bent posture: they agree to about a tenth of the
// sag, not to rounding.
TEST_F(DynamicExport, TheReleasedModesSagAsTheAugmentedChainPredicts) {
  const std::vector<sim::IdentifiedEffect> effects = {Effect("link_mode@link2_b", {0.6, 1.0}),
                                                      Effect("link_mode@link3_b", {0.5, 1.0})};
  const std::string path = Export(effects);
  std::unique_ptr<sim::Simulation> truth = sim::Simulation::Load(path);
  sim::DeclaredModel d = declared_;
  d.identified_effects = effects;
  sim::MjModelPtr m0 = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m0.get(), d);
  const sim::DeclaredChain rigid_chain = sim::BuildDeclaredChain(m0.get(), declared_);
  kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
  kinematics::PpoeData pd(chain.model), rigid(rigid_chain.model);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  double sag_sum = 0.0, left_sum = 0.0;
  for (int t = 0; t < 8; ++t) {
    Eigen::VectorXd q(chain.model.nq());
    q << u(rng), 0.8 + 0.6 * u(rng), 0.8 * u(rng), 0.3;
    for (int k = 0; k < q.size(); ++k) truth->SetCommand(chain.q_joints[k], q[k]);
    truth->Settle();
    const Vec3 p_truth = truth->SitePose("grasp_point").translation();
    kin.Update(q);
    kinematics::ForwardKinematics(kin.model(), pd, kin.q());
    kinematics::ForwardKinematics(rigid_chain.model, rigid, q);
    const double sag =
        (rigid.T_base_frame[rigid_chain.end_effector].translation() - p_truth).norm();
    const double left = (pd.T_base_frame[chain.end_effector].translation() - p_truth).norm();
    std::printf("posture %d: sag %.3f mm, left %.3f mm\n", t, 1e3 * sag, 1e3 * left);
    EXPECT_LT(left, 0.2 * sag + 1e-4) << t << ": sag " << sag;
    sag_sum += sag;
    left_sum += left;
  }
  std::printf("mean sag %.3f mm, left by the augmented chain %.3f mm\n", 1e3 * sag_sum / 8,
              1e3 * left_sum / 8);
  EXPECT_GT(sag_sum / 8, 2e-3);
  EXPECT_LT(left_sum, 0.12 * sag_sum);
}

TEST_F(DynamicExport, BadDynamicEntriesAreOneLineNamingThem) {
  const auto fails = [&](const sim::IdentifiedEffect& e, const std::string& says) {
    sim::DeclaredModel d = declared_;
    d.identified_effects = {e};
    try {
      sim::MjModelPtr m = sim::LoadModel(d.model_path);
      sim::BuildDeclaredChain(m.get(), d);
      sim::ExportMjcf(d);
      ADD_FAILURE() << e.effect << " accepted";
    } catch (const InputError& err) {
      const std::string what = err.what();
      EXPECT_NE(what.find(e.effect.substr(0, 12)), std::string::npos) << what;
      EXPECT_NE(what.find(says), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
  };
  fails(Effect("link_mode@link9_b", {1.0, 1.0}), "link2_b, link3_b");
  fails(Effect("joint_friction@link2_pitch_joint", {-0.1}), "outside");
  fails(Effect("link_mode@link2_b", {1.0}), "needs 2 values");
  fails(Effect("stribeck_friction@link2_pitch_joint", {0.5, 0.2}), "truth only");
  fails(Effect("servo_gain@link2_bend_y", {1.1}), "has no");
}

}  // namespace
}  // namespace flexbench
