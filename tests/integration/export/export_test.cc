// `flexbench export`: MuJoCo loads the written MJCF, and its bodies, sites and cameras stand where
// the declared chain with the identified effects applied puts them (EffectiveChain, code other
// than the writer's MJCF folding), to 1e-9 at random postures. Compliances become the gear
// annotations the truth's joint_compliance effect reads; what MJCF cannot hold is named in one
// warning line; an existing output is refused without --force; bad input is one line, exit 2.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>
#include <unistd.h>

#include <filesystem>
#include <random>
#include <sstream>
#include <string>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "scenarios/identify/effect_model.h"
#include "sim/config.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/test_arms.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;

constexpr char kArm4[] = R"(
<mujoco model="arm4">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1" pos="0.01 0 0"/>
      <geom type="cylinder" size="0.05 0.05" mass="2"/>
      <body name="upper" pos="0 0 0.1" euler="0.1 0 0.2">
        <joint name="j2" axis="0 1 0.1" ref="0.3"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="3"/>
        <body name="fore" pos="0.4 0 0" quat="0.99 0 0.1 0.05">
          <joint name="j3" axis="0 1 0" pos="0 0.02 0"/>
          <geom type="capsule" fromto="0 0 0 0.35 0 0" size="0.025" mass="2"/>
          <body name="hand" pos="0.35 0 0">
            <joint name="j4" axis="1 0 0"/>
            <geom name="pad" type="box" size="0.03 0.03 0.03" pos="0.03 0 0.01" mass="0.7"/>
            <site name="ee" pos="0.08 0.01 0.02" euler="0.3 0.2 0.1"/>
            <camera name="wrist_cam" pos="0.02 0.03 0" euler="0 1.2 0"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>)";

class Export : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("flexbench_export_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    testing::WriteFile(dir_ / "arm4.xml", kArm4);
  }
  void TearDown() override { fs::remove_all(dir_); }

  testing::CommandResult Run(const std::string& args) const {
    return testing::RunCommand(testing::Flexbench() + " export " + args);
  }

  fs::path dir_;
};

// Every geometric candidate of the identification at a random value of a realistic size.
std::vector<sim::IdentifiedEffect> GeometricEffects(const sim::DeclaredModel& d,
                                                    std::mt19937_64& rng) {
  sim::MjModelPtr m = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d);
  std::vector<kinematics::FrameId> points;
  for (const auto& [name, f] : chain.observed) points.push_back(f);
  const identify::EffectModel em(m.get(), chain, chain.end_effector, "", points);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<sim::IdentifiedEffect> out;
  using T = identify::EffectType;
  for (const identify::Candidate& c : em.candidates()) {
    double scale = 0.0;
    switch (c.type) {
      case T::kJointOffset:
      case T::kAxisTilt:
        scale = 0.01;
        break;
      case T::kLinkLength:
      case T::kLinkOffset:
        scale = 0.004;
        break;
      case T::kJointOrigin:
        scale = 0.006;
        break;
      case T::kThermalExpansion:
        scale = 4e-4;
        break;
      default:
        continue;
    }
    std::vector<double> v(c.num_params);
    for (double& x : v) x = scale * n(rng);
    out.push_back({c.Name(), v, {}, c.unit, "test:1", {}});
  }
  return out;
}

// Max distance between MuJoCo's poses of the exported model and the declared chain's with its
// identified effects, over bodies, sites and cameras of the chain, at random readings.
double MaxPoseError(const sim::DeclaredModel& d, const std::string& exported, int postures) {
  sim::MjModelPtr m0 = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m0.get(), d);
  sim::MjModelPtr m = sim::LoadModel(exported);
  sim::MjDataPtr data = sim::MakeData(m.get());
  kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
  kinematics::PpoeData pd(chain.model);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  double worst = 0.0;
  int compared = 0;
  for (int t = 0; t < postures; ++t) {
    Eigen::VectorXd q(chain.model.nq());
    for (int k = 0; k < q.size(); ++k) q[k] = u(rng);
    mju_copy(data->qpos, m->qpos0, m->nq);
    chain.WriteQpos(q, data->qpos);
    mj_kinematics(m.get(), data.get());
    mj_comPos(m.get(), data.get());
    mj_camlight(m.get(), data.get());  // cameras' poses
    kin.Update(q);
    kinematics::ForwardKinematics(kin.model(), pd, kin.q());
    const auto compare = [&](const std::string& typed, const double* p, const double* R) {
      if (!chain.model.HasFrame(typed)) return;
      const lie::SE3& T = pd.T_base_frame[chain.model.FindFrame(typed)];
      Mat3 Rm;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) Rm(r, c) = R[3 * r + c];
      }
      Mat3 R_chain = T.rotation();
      if (typed.rfind("camera/", 0) == 0) R_chain = R_chain * Vec3(1, -1, -1).asDiagonal();
      worst = std::max(worst, (T.translation() - Eigen::Map<const Vec3>(p)).norm());
      worst = std::max(worst, (R_chain - Rm).cwiseAbs().maxCoeff());
      ++compared;
    };
    for (int b = 1; b < m->nbody; ++b) {
      compare("body/" + sim::ObjectName(m.get(), mjOBJ_BODY, b), data->xpos + 3 * b,
              data->xmat + 9 * b);
    }
    for (int s = 0; s < m->nsite; ++s) {
      compare("site/" + sim::ObjectName(m.get(), mjOBJ_SITE, s), data->site_xpos + 3 * s,
              data->site_xmat + 9 * s);
    }
    for (int c = 0; c < m->ncam; ++c) {
      compare("camera/" + sim::ObjectName(m.get(), mjOBJ_CAMERA, c), data->cam_xpos + 3 * c,
              data->cam_xmat + 9 * c);
    }
  }
  EXPECT_GT(compared, postures * 3);
  return worst;
}

// The same for the URDF through the project's URDF loader: a body's link stands at its last
// joint's anchor with the body's axes, sites and cameras are links of their own names.
double MaxUrdfPoseError(const sim::DeclaredModel& d, const std::string& urdf, int postures) {
  sim::MjModelPtr m0 = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m0.get(), d);
  sim::MjModelPtr m = sim::LoadModel(urdf);
  sim::MjDataPtr data = sim::MakeData(m.get());
  kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
  kinematics::PpoeData pd(chain.model);
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  double worst = 0.0;
  int compared = 0;
  for (int t = 0; t < postures; ++t) {
    Eigen::VectorXd q(chain.model.nq());
    for (int k = 0; k < q.size(); ++k) q[k] = u(rng);
    mju_copy(data->qpos, m->qpos0, m->nq);
    for (int k = 0; k < q.size(); ++k) {
      const int j = mj_name2id(m.get(), mjOBJ_JOINT, chain.q_joints[k].c_str());
      if (j < 0) {
        ADD_FAILURE() << "no joint " << chain.q_joints[k] << " in " << urdf;
        return 1.0;
      }
      data->qpos[m->jnt_qposadr[j]] = q[k];  // URDF has no ref: the reading itself
    }
    mj_kinematics(m.get(), data.get());
    kin.Update(q);
    kinematics::ForwardKinematics(kin.model(), pd, kin.q());
    const auto pose = [&](const std::string& typed) {
      return pd.T_base_frame[chain.model.FindFrame(typed)];
    };
    for (int b = 1; b < m->nbody; ++b) {
      const std::string name = sim::ObjectName(m.get(), mjOBJ_BODY, b);
      std::string typed = sim::TypedFrameName(m0.get(), name);
      if (typed.empty() || !chain.model.HasFrame(typed)) continue;
      Mat3 R = pose(typed).rotation();
      Vec3 p = pose(typed).translation();
      if (typed.rfind("camera/", 0) == 0) R = R * Vec3(1, -1, -1).asDiagonal();
      if (typed.rfind("body/", 0) == 0) {
        const int b0 = mj_name2id(m0.get(), mjOBJ_BODY, name.c_str());
        const int nj = m0->body_jntnum[b0];
        if (nj > 0) {
          const int j = m0->body_jntadr[b0] + nj - 1;
          p = pose("joint/" + sim::ObjectName(m0.get(), mjOBJ_JOINT, j)).translation();
        }
      }
      Mat3 Rm;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) Rm(r, c) = data->xmat[9 * b + 3 * r + c];
      }
      worst = std::max(worst, (p - Eigen::Map<const Vec3>(data->xpos + 3 * b)).norm());
      worst = std::max(worst, (R - Rm).cwiseAbs().maxCoeff());
      ++compared;
    }
  }
  EXPECT_GT(compared, postures * 3);
  return worst;
}

TEST_F(Export, MujocoPosesOfTheWrittenMjcfAreTheCalibratedChains) {
  for (const std::string robot : {"arm4", "rover_arm"}) {
    sim::DeclaredModel d;
    if (robot == "arm4") {
      d.file = (dir_ / "arm4.declared.yaml").string();
      d.model_path = (dir_ / "arm4.xml").string();
      d.actuated_joints = {"j1", "j2", "j3", "j4"};
      d.end_effector = "ee";
      d.observed_frames = {"wrist_cam", "pad", "hand"};
    } else {
      d = sim::LoadDeclaredModel(testing::SourceDir() + "/models/rover_arm.declared.yaml");
      d.model_path = fs::absolute(d.model_path).string();
    }
    std::mt19937_64 rng(34);
    d.identified_effects = GeometricEffects(d, rng);
    ASSERT_GE(d.identified_effects.size(), 10u) << robot;
    // A marker offset moves its site with the rest.
    d.marker_offsets.push_back({d.end_effector, Vec3(0.01, -0.02, 0.005), Mat3::Zero(), ""});
    const fs::path yaml = dir_ / (robot + ".aug.yaml");
    testing::WriteFile(yaml, sim::EmitDeclaredModel(d, ""));
    const fs::path out = dir_ / (robot + ".calibrated.xml");
    const fs::path urdf = dir_ / (robot + ".calibrated.urdf");
    const testing::CommandResult r =
        Run(yaml.string() + " --mjcf " + out.string() + " --urdf " + urdf.string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err, "") << robot;  // geometry only: nothing left out
    const sim::DeclaredModel reread = sim::LoadDeclaredModel(yaml.string());
    EXPECT_LT(MaxPoseError(reread, out.string(), 20), 1e-9) << robot;
    EXPECT_LT(MaxUrdfPoseError(reread, urdf.string(), 20), 1e-9) << robot;
    // The nominal model is millimetres away: the comparison would see a missing effect.
    sim::DeclaredModel nominal = reread;
    nominal.identified_effects.clear();
    nominal.marker_offsets.clear();
    testing::WriteFile(dir_ / "nominal.yaml", sim::EmitDeclaredModel(nominal, ""));
    EXPECT_GT(MaxPoseError(reread,
                           sim::LoadDeclaredModel((dir_ / "nominal.yaml").string()).model_path, 5),
              1e-3)
        << robot;
  }
}

// A gear compliance becomes the annotation the truth's joint_compliance effect reads (k = -1/c,
// over the model's own entries); a backlash and a bending link, which MJCF cannot hold, are
// named in one warning line.
TEST_F(Export, CompliancesBecomeGearAnnotationsAndTheRestIsNamed) {
  const std::string yaml =
      "model: " + (dir_ / "arm4.xml").string() +
      "\nactuated_joints: [j1, j2, j3, j4]\nend_effector: ee\nidentified_effects:\n"
      "  - {effect: joint_compliance@j2, value: [-0.002]}\n"
      "  - {effect: stiffening_spring@j3, value: [-0.0004, 0.0001]}\n"
      "  - {effect: backlash@j3, value: [0.001]}\n"
      "  - {effect: link_bending@j3, value: [0.0001]}\n";
  testing::WriteFile(dir_ / "c.yaml", yaml);
  const fs::path out = dir_ / "c.xml";
  const testing::CommandResult r = Run((dir_ / "c.yaml").string() + " --mjcf " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(testing::CountLines(r.err), 1) << r.err;
  for (const char* name : {"backlash@j3", "link_bending@j3", "stiffening_spring@j3"}) {
    EXPECT_NE(r.err.find(name), std::string::npos) << r.err;
  }
  EXPECT_EQ(r.err.find("joint_compliance"), std::string::npos) << r.err;
  sim::MjModelPtr m = sim::LoadModel(out.string());
  const int t = mj_name2id(m.get(), mjOBJ_TEXT, "effect:joint_compliance");
  const int n = mj_name2id(m.get(), mjOBJ_NUMERIC, "effect:joint_compliance:stiffness");
  ASSERT_GE(t, 0);
  ASSERT_GE(n, 0);
  EXPECT_EQ(std::string(m->text_data + m->text_adr[t]), "j2 j3");
  ASSERT_EQ(m->numeric_size[n], 2);
  EXPECT_NEAR(m->numeric_data[m->numeric_adr[n]], 500.0, 1e-9);
  EXPECT_NEAR(m->numeric_data[m->numeric_adr[n] + 1], 2500.0, 1e-9);
  // URDF has no spring: the compliances are named too, in the URDF's own line.
  const fs::path urdf = dir_ / "c.urdf";
  const testing::CommandResult u = Run((dir_ / "c.yaml").string() + " --urdf " + urdf.string());
  ASSERT_EQ(u.exit_code, 0) << u.err;
  EXPECT_EQ(testing::CountLines(u.err), 1) << u.err;
  for (const char* name : {"joint_compliance@j2", "stiffening_spring@j3", "backlash@j3"}) {
    EXPECT_NE(u.err.find(name), std::string::npos) << u.err;
  }
  EXPECT_NE(u.err.find("c.urdf"), std::string::npos) << u.err;
}

// Where MJCF holds a load-driven effect (a gear compliance, as the truth's annotation), the
// truth settled with the exported file deflects as the calibrated chain predicts: the chain
// takes the torque at the reading, MuJoCo at the deflected posture, so they agree to second
// order (a few percent of the deflection), not to 1e-9.
TEST_F(Export, TheTruthReadsTheExportedGearSpringsAndSagsAsTheChainPredicts) {
  testing::WriteFile(dir_ / "servo3.xml", testing::Arm3Mjcf(/*servos=*/true));
  testing::WriteFile(dir_ / "s.yaml",
                     "model: servo3.xml\nactuated_joints: [j1, j2, j3]\n"
                     "end_effector: ee\nidentified_effects:\n"
                     "  - {effect: joint_compliance@j2, value: [-0.0005]}\n"
                     "  - {effect: joint_compliance@j3, value: [-0.0008]}\n");
  const fs::path out = dir_ / "s.xml";
  const testing::CommandResult r = Run((dir_ / "s.yaml").string() + " --mjcf " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const sim::EffectList effects =
      sim::ParseEffects(ConfigNode::LoadString("joint_compliance: {}\n", "effects"));
  std::unique_ptr<sim::Simulation> truth = sim::Simulation::Load(out.string(), effects);
  const sim::DeclaredModel d = sim::LoadDeclaredModel((dir_ / "s.yaml").string());
  sim::MjModelPtr m0 = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m0.get(), d);
  kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
  kinematics::PpoeData pd(chain.model), rigid(chain.model);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int t = 0; t < 5; ++t) {
    Eigen::VectorXd q(3);
    for (int k = 0; k < 3; ++k) q[k] = u(rng);
    for (int k = 0; k < 3; ++k) truth->SetCommand(chain.q_joints[k], q[k]);
    truth->Settle();
    const Vec3 p_truth = truth->SitePose("ee").translation();
    kin.Update(q);
    kinematics::ForwardKinematics(kin.model(), pd, kin.q());
    kinematics::ForwardKinematics(chain.model, rigid, q);
    const double sag = (rigid.T_base_frame[chain.end_effector].translation() - p_truth).norm();
    const double left = (pd.T_base_frame[chain.end_effector].translation() - p_truth).norm();
    EXPECT_GT(sag, 1e-3) << t;
    EXPECT_LT(left, 0.03 * sag) << t << ": sag " << sag;
  }
}

TEST_F(Export, AnExistingFileNeedsForceAndBadInputIsOneLine) {
  testing::WriteFile(dir_ / "d.yaml",
                     "model: " + (dir_ / "arm4.xml").string() +
                         "\nactuated_joints: [j1, j2, j3, j4]\nend_effector: ee\n");
  const std::string d = (dir_ / "d.yaml").string();
  const fs::path out = dir_ / "d.xml";
  testing::WriteFile(out, "keep me");
  testing::CommandResult r = Run(d + " --mjcf " + out.string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(testing::CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--force"), std::string::npos) << r.err;
  EXPECT_EQ(testing::ReadFile(out), "keep me");
  r = Run(d + " --mjcf " + out.string() + " --force");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(testing::ReadFile(out).find("<mujoco"), std::string::npos);
  const auto bad = [&](const std::string& args, const std::string& says) {
    const testing::CommandResult b = Run(args);
    EXPECT_EQ(b.exit_code, 2) << args << ": " << b.err;
    EXPECT_EQ(testing::CountLines(b.err), 1) << b.err;
    EXPECT_NE(b.err.find(says), std::string::npos) << b.err;
  };
  bad((dir_ / "missing.yaml").string() + " --mjcf " + (dir_ / "x.xml").string(), "missing.yaml");
  testing::WriteFile(dir_ / "broken.yaml", "model: [unclosed\n");
  bad((dir_ / "broken.yaml").string() + " --mjcf " + (dir_ / "x.xml").string(), "broken.yaml");
  testing::WriteFile(dir_ / "effect.yaml", testing::ReadFile(dir_ / "d.yaml") +
                                               "identified_effects:\n"
                                               "  - {effect: joint_offset@j9, value: [0.1]}\n");
  bad((dir_ / "effect.yaml").string() + " --mjcf " + (dir_ / "x.xml").string(), "effect.yaml:5");
  bad(d + " --mjcf " + dir_.string(), "folder");
  bad(d, "--mjcf");
  EXPECT_FALSE(fs::exists(dir_ / "x.xml"));
}

}  // namespace
}  // namespace flexbench
