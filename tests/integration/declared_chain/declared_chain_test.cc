// The PPOE chain extracted from an MJCF equals MuJoCo's own kinematics (passive joints at their
// reference), for every model in models/ that has a declared-model file, and for inline models
// with the joint layouts MuJoCo allows (anchors off the body origin, several joints per body,
// slides, references, trees).
#include "sim/declared_chain.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <random>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::sim {
namespace {

namespace fs = std::filesystem;
using kinematics::FrameId;

// Largest pose difference (translation m + rotation rad) between every typed PPOE frame and
// MuJoCo's pose of the same object.
double MaxPoseError(const mjModel* m, const mjData* d, const DeclaredChain& chain,
                    const kinematics::PpoeData& data, int* compared) {
  // The PPOE base is the base body's frame.
  const lie::SE3 T_w_base(RotFromRowMajor(d->xmat + 9 * chain.base_body),
                          Eigen::Map<const Vec3>(d->xpos + 3 * chain.base_body));
  double worst = 0.0;
  *compared = 0;
  for (FrameId f = 1; f < chain.model.num_frames(); ++f) {
    const std::string& name = chain.model.frame(f).name;
    const std::string kind = name.substr(0, name.find('/'));
    const std::string object = name.substr(name.find('/') + 1);
    lie::SE3 truth;
    if (kind == "body") {
      const int b = BodyId(m, object);
      truth = lie::SE3(RotFromRowMajor(d->xmat + 9 * b), Eigen::Map<const Vec3>(d->xpos + 3 * b));
    } else if (kind == "site") {
      const int s = SiteId(m, object);
      truth = lie::SE3(RotFromRowMajor(d->site_xmat + 9 * s),
                       Eigen::Map<const Vec3>(d->site_xpos + 3 * s));
    } else if (kind == "geom") {
      const int g = GeomId(m, object);
      truth = lie::SE3(RotFromRowMajor(d->geom_xmat + 9 * g),
                       Eigen::Map<const Vec3>(d->geom_xpos + 3 * g));
    } else if (kind == "camera") {
      const Eigen::Isometry3d T = WorldFromOptical(d, CameraId(m, object));
      truth = lie::SE3(T.linear(), T.translation());
    } else {
      continue;  // joint frames sit at anchors; their bodies are compared
    }
    const lie::SE3 ppoe = T_w_base * data.T_base_frame[f];
    const double err = (ppoe.translation() - truth.translation()).norm() +
                       (ppoe.rotation() - truth.rotation()).norm();
    worst = std::max(worst, err);
    ++*compared;
  }
  return worst;
}

// Random actuated configurations; passive joints stay at qpos0.
void ExpectChainMatchesMujoco(const mjModel* m, const DeclaredChain& chain, int trials) {
  MjDataPtr data = MakeData(m);
  kinematics::PpoeData ppoe_data(chain.model);
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  for (int t = 0; t < trials; ++t) {
    mju_copy(data->qpos, m->qpos0, m->nq);
    Eigen::VectorXd q(chain.model.nq());
    for (int k = 0; k < q.size(); ++k) q[k] = t == 0 ? 0.0 : angle(rng);
    chain.WriteQpos(q, data->qpos);
    mj_kinematics(m, data.get());
    mj_comPos(m, data.get());
    mj_camlight(m, data.get());
    EXPECT_TRUE(chain.QFromQpos(data->qpos).isApprox(q, 1e-15) || q.isZero());
    kinematics::ForwardKinematics(chain.model, ppoe_data, q);
    int compared = 0;
    EXPECT_LT(MaxPoseError(m, data.get(), chain, ppoe_data, &compared), 1e-9) << "trial " << t;
    EXPECT_GT(compared, 1);
  }
}

TEST(DeclaredChain, EveryModelInModelsMatchesMujoco) {
  int models = 0;
  for (const auto& entry : fs::directory_iterator(testing::SourceDir() + "/models")) {
    const std::string path = entry.path().string();
    if (path.size() < 14 || path.substr(path.size() - 14) != ".declared.yaml") continue;
    SCOPED_TRACE(path);
    const DeclaredModel declared = LoadDeclaredModel(path);
    MjModelPtr m = LoadModel(declared.model_path);
    // A coupled joint is a chain variable as well (humanoid_upper_torso: the torso's fourth).
    const DeclaredChain chain =
        BuildDeclaredChain(m.get(), declared, /*with_couplings=*/!declared.coupled.empty());
    EXPECT_EQ(chain.model.nq(),
              static_cast<int>(declared.actuated_joints.size() + declared.coupled.size()));
    ExpectChainMatchesMujoco(m.get(), chain, 20);
    ++models;
  }
  EXPECT_GE(models, 1);
}

// Anchors away from the body origin, two hinges and a slide in one body, a reference angle, a
// passive joint (held at its reference), a tree with two branches and a camera.
constexpr char kAwkwardXml[] = R"(<mujoco><compiler angle="radian"/>
  <worldbody>
    <body name="torso" pos="0.1 0.2 0.3" euler="0.1 0.2 0.3">
      <joint name="waist" type="hinge" axis="0 0.6 0.8" pos="0.05 -0.02 0.1" ref="0.3"/>
      <geom type="box" size=".1 .1 .1"/>
      <body name="arm" pos="0.3 0 0" quat="0.9 0.1 0.3 0.2">
        <joint name="a1" type="hinge" axis="1 0 0" pos="0 0.1 0"/>
        <joint name="a2" type="hinge" axis="0 1 1" pos="0.02 0 0.03"/>
        <joint name="a3" type="slide" axis="1 1 0"/>
        <joint name="flex" type="hinge" axis="0 0 1" pos="0.1 0 0" stiffness="100"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
        <site name="tip" pos="0.3 0.01 -0.02" euler="0.3 0.2 0.1"/>
      </body>
      <body name="head" pos="0 0 0.2">
        <joint name="neck" type="hinge" axis="0 0 1"/>
        <geom name="visor" type="box" pos="0.05 0 0" euler="0 0.4 0" size=".02 .05 .03"/>
        <camera name="eye" pos="0.05 0 0.02" xyaxes="0 -1 0 0.2 0 1"/>
      </body>
    </body>
  </worldbody></mujoco>)";

DeclaredModel AwkwardDeclared() {
  DeclaredModel d;
  d.file = "awkward.declared.yaml";
  d.model_path = "awkward.xml";
  d.actuated_joints = {"waist", "a1", "a2", "a3", "neck"};
  d.end_effector = "tip";
  d.observed_frames = {"eye", "visor"};
  DeclaredSource s;
  s.at = "flex";
  s.about_axis_rad = 0.05;
  s.where = "awkward.declared.yaml:9";
  d.sources.push_back(s);
  return d;
}

TEST(DeclaredChain, AwkwardJointLayoutsMatchMujoco) {
  MjModelPtr m = LoadModelFromString(kAwkwardXml);
  const DeclaredChain chain = BuildDeclaredChain(m.get(), AwkwardDeclared());
  EXPECT_EQ(chain.model.nq(), 5);
  EXPECT_EQ(chain.q_joints.front(), "waist");
  EXPECT_DOUBLE_EQ(chain.q_qpos0.front(), 0.3);
  // The passive joint carries its declared source about its own axis and no q.
  const auto& flex = chain.model.frame(chain.model.FindFrame("joint/flex"));
  EXPECT_EQ(flex.q_index, -1);
  EXPECT_NEAR(flex.source_cov(5, 5), 0.05 * 0.05, 1e-15);
  ExpectChainMatchesMujoco(m.get(), chain, 30);
}

std::string BuildError(DeclaredModel d) {
  MjModelPtr m = LoadModelFromString(kAwkwardXml);
  try {
    BuildDeclaredChain(m.get(), d);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(DeclaredChain, BadNamesAreReportedWithTheFile) {
  DeclaredModel d = AwkwardDeclared();
  d.actuated_joints.push_back("elbow");
  EXPECT_NE(BuildError(d).find("awkward.declared.yaml: actuated_joints: no joint named 'elbow'"),
            std::string::npos)
      << BuildError(d);
  d = AwkwardDeclared();
  d.end_effector = "gripper";
  EXPECT_NE(BuildError(d).find("end_effector: no site, geom, camera or body named 'gripper'"),
            std::string::npos);
  d = AwkwardDeclared();
  d.sources[0].at = "wrist";
  EXPECT_NE(BuildError(d).find("awkward.declared.yaml:9: source at 'wrist': no joint or body"),
            std::string::npos);
}

TEST(DeclaredChain, ActuatedJointsOffTheChainsStillGetTheirBranch) {
  MjModelPtr m = LoadModelFromString(kAwkwardXml);
  DeclaredModel d = AwkwardDeclared();
  d.end_effector = "visor";  // the arm's joints move nothing declared, yet stay in q
  d.observed_frames = {};
  const DeclaredChain chain = BuildDeclaredChain(m.get(), d);
  EXPECT_EQ(chain.model.nq(), 5);
  EXPECT_NO_THROW(chain.QIndex("a2"));
  ExpectChainMatchesMujoco(m.get(), chain, 5);
}

// Lateral compliance hinges (sim::LateralHingeOf's convention) at an anchor off the body origin
// in a turned body: held at their reference they add no frame, and the chain still matches
// MuJoCo; a source there is refused with the joint to put it at.
constexpr char kLateralXml[] = R"(<mujoco><compiler angle="radian"/>
  <worldbody>
    <body name="torso" pos="0.1 0.2 0.3" euler="0.1 0.2 0.3">
      <joint name="waist" type="hinge" axis="0 0 1"/>
      <geom type="box" size=".1 .1 .1"/>
      <body name="arm" pos="0.3 0 0" quat="0.9 0.1 0.3 0.2">
        <joint name="a1_lateral_a" type="hinge" axis="0 1 0" pos="0 0.1 0.02"/>
        <joint name="a1_lateral_b" type="hinge" axis="0 0 1" pos="0 0.1 0.02"/>
        <joint name="a1" type="hinge" axis="1 0 0" pos="0 0.1 0.02"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
        <site name="tip" pos="0.3 0.01 -0.02" euler="0.3 0.2 0.1"/>
      </body>
    </body>
  </worldbody></mujoco>)";

TEST(DeclaredChain, LateralHingesAddNoFrameAndStayAtTheirReference) {
  MjModelPtr m = LoadModelFromString(kLateralXml);
  DeclaredModel d;
  d.file = "lateral.declared.yaml";
  d.model_path = "lateral.xml";
  d.actuated_joints = {"waist", "a1"};
  d.end_effector = "tip";
  const DeclaredChain chain = BuildDeclaredChain(m.get(), d);
  EXPECT_FALSE(chain.model.HasFrame("joint/a1_lateral_a"));
  EXPECT_FALSE(chain.model.HasFrame("joint/a1_lateral_b"));
  EXPECT_TRUE(chain.model.HasFrame("joint/a1"));
  ExpectChainMatchesMujoco(m.get(), chain, 20);
  DeclaredSource s;
  s.at = "a1_lateral_b";
  s.about_axis_rad = 0.01;
  s.where = "lateral.declared.yaml:7";
  d.sources.push_back(s);
  try {
    BuildDeclaredChain(m.get(), d);
    ADD_FAILURE() << "a source at a lateral hinge was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("lateral.declared.yaml:7: source at 'a1_lateral_b'"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("'a1'"), std::string::npos) << e.what();
  }
}

TEST(DeclaredModelFile, FormatErrorsNameFileLineAndKey) {
  testing::TempDir tmp;
  const auto path = tmp.path() / "x.declared.yaml";
  testing::WriteFile(path,
                     "model: planar3.xml\nactuated_joints: [j1]\nend_effector: ee\n"
                     "sources:\n  - {at: j1, std_rot_deg: [1, 2]}\n");
  try {
    LoadDeclaredModel(path.string());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string() + ":5: key 'sources[0].std_rot_deg'"),
              std::string::npos)
        << e.what();
  }
  testing::WriteFile(path, "model: " + testing::SourceDir() +
                               "/models/planar3.xml\nactuated_joints: [j1]\nend_effector: ee\n"
                               "colour: red\n");
  try {
    LoadDeclaredModel(path.string());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(":4: unknown key 'colour'"), std::string::npos)
        << e.what();
  }
}

// Absurd standard deviations (NaN metrics later) and a model path naming nothing.
TEST(DeclaredModelFile, RangesAndTheModelPathAreChecked) {
  testing::TempDir tmp;
  const auto path = tmp.path() / "x.declared.yaml";
  const std::string model = "model: " + testing::SourceDir() + "/models/planar3.xml\n";
  const auto error = [&](const std::string& text) {
    testing::WriteFile(path, text);
    try {
      LoadDeclaredModel(path.string());
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  const std::string head = "actuated_joints: [joint1]\nend_effector: ee\nsources:\n";
  EXPECT_NE(error(model + head + "  - {at: joint1, about_axis_deg: 1e6}\n").find("at most 90"),
            std::string::npos);
  EXPECT_NE(error(model + head + "  - {at: joint1, std_rot_deg: [1, 1e6, 1]}\n").find("at most 90"),
            std::string::npos);
  EXPECT_NE(error(model + head + "  - {at: joint1, std_trans_m: [0, 0, 1e3]}\n").find("at most 10"),
            std::string::npos);
  EXPECT_EQ(error(model + head + "  - {at: joint1, about_axis_deg: 2}\n"), "");
  const std::string e =
      error("model: /nonexistent/robot.xml\n" + head + "  - {at: joint1, about_axis_deg: 2}\n");
  EXPECT_NE(e.find(":1: key 'model': model file /nonexistent/robot.xml not found"),
            std::string::npos)
      << e;
}

// The writer next to the reader: every model's declared file, with what closed_loop
// adds (identified effects, an equivalence set, a source with both an axis std and a full
// covariance) and a coupling, comes back from EmitDeclaredModel through LoadDeclaredModel: bit
// for bit with every digit, to the digits asked for otherwise.
TEST(DeclaredModelFile, WhatTheWriterWritesTheReaderReads) {
  testing::TempDir tmp;
  int models = 0;
  for (const auto& f : fs::directory_iterator(testing::SourceDir() + "/models")) {
    const std::string name = f.path().filename().string();
    if (name.size() < 14 || name.substr(name.size() - 14) != ".declared.yaml") continue;
    ++models;
    DeclaredModel d = LoadDeclaredModel(f.path().string());
    d.identified_effects.push_back({"joint_offset@" + d.actuated_joints[0],
                                    {-0.00524114, 1.0 / 3.0},
                                    {1e-5, 2e-7},
                                    "rad",
                                    "",
                                    {}});
    d.identified_effects.push_back(
        {"payload@ee", {0.5}, {}, "kg", "", {"payload@ee", "link_length@j1"}});
    d.coupled.push_back({"follower", {{d.actuated_joints[0], -1.0 / 3.0}}, {}, false, ""});
    d.coupled.push_back({"wrist", {}, {}, true, ""});
    DeclaredSource both;
    both.at = d.actuated_joints[0];
    both.about_axis_rad = 0.0123;
    both.cov.diagonal() << 1e-6, 2e-6, 3e-6, 1e-4, 2e-4, M_PI / 1e4;
    both.cov(3, 4) = both.cov(4, 3) = 1e-5;
    d.sources.push_back(both);
    const fs::path out = tmp.path() / name;
    const std::string model = d.model_path;
    d.model_path = fs::relative(model, tmp.path()).generic_string();
    for (int digits : {17, 6}) {
      const std::string text = EmitDeclaredModel(d, "a header\nof two lines", digits);
      EXPECT_EQ(text, EmitDeclaredModel(d, "a header\nof two lines", digits));
      EXPECT_EQ(text.rfind("# a header\n# of two lines\n", 0), 0u) << text;
      testing::WriteFile(out, text);
      const DeclaredModel r = LoadDeclaredModel(out.string());
      const double tol = digits == 17 ? 0.0 : 5e-6;  // relative
      const auto near = [&](double a, double b) { return std::abs(a - b) <= tol * std::abs(b); };
      EXPECT_EQ(fs::path(r.model_path).lexically_normal(), fs::path(model).lexically_normal());
      EXPECT_EQ(r.base, d.base);
      EXPECT_EQ(r.actuated_joints, d.actuated_joints);
      EXPECT_EQ(r.end_effector, d.end_effector);
      EXPECT_EQ(r.observed_frames, d.observed_frames);
      ASSERT_EQ(r.sources.size(), d.sources.size()) << name;
      for (size_t i = 0; i < d.sources.size(); ++i) {
        EXPECT_EQ(r.sources[i].at, d.sources[i].at);
        // Degrees on the page: deg -> rad -> deg may move the last bit, whatever the digits.
        EXPECT_NEAR(r.sources[i].about_axis_rad, d.sources[i].about_axis_rad,
                    std::max(tol, 4e-16) * d.sources[i].about_axis_rad)
            << name << i;
        for (int k = 0; k < 36; ++k) {
          EXPECT_TRUE(near(r.sources[i].cov(k), d.sources[i].cov(k))) << name << " source " << i;
        }
      }
      ASSERT_EQ(r.identified_effects.size(), d.identified_effects.size());
      for (size_t i = 0; i < d.identified_effects.size(); ++i) {
        const IdentifiedEffect &a = r.identified_effects[i], &b = d.identified_effects[i];
        EXPECT_EQ(a.effect, b.effect);
        EXPECT_EQ(a.equivalent, b.equivalent);
        EXPECT_EQ(a.unit, b.unit);
        ASSERT_EQ(a.value.size(), b.value.size());
        ASSERT_EQ(a.std.size(), b.std.size());
        for (size_t k = 0; k < b.value.size(); ++k) EXPECT_TRUE(near(a.value[k], b.value[k]));
        for (size_t k = 0; k < b.std.size(); ++k) EXPECT_TRUE(near(a.std[k], b.std[k]));
      }
      ASSERT_EQ(r.coupled.size(), d.coupled.size());
      for (size_t i = 0; i < d.coupled.size(); ++i) {
        EXPECT_EQ(r.coupled[i].joint, d.coupled[i].joint);
        EXPECT_EQ(r.coupled[i].from_mjcf, d.coupled[i].from_mjcf);
        EXPECT_EQ(r.coupled[i].drivers, d.coupled[i].drivers);  // geometry: every digit
      }
    }
  }
  EXPECT_GE(models, 4);
}

// What the reader accepts the writer can write: a source of zero comes back as one; a NaN is
// refused before anything is written.
TEST(DeclaredModelFile, TheWriterWritesZeroSourcesAndRefusesNaN) {
  testing::TempDir tmp;
  DeclaredModel d;
  d.model_path = testing::SourceDir() + "/models/planar3.xml";
  d.actuated_joints = {"joint1"};
  d.end_effector = "ee";
  DeclaredSource zero;
  zero.at = "joint1";
  d.sources.push_back(zero);
  testing::WriteFile(tmp.path() / "z.yaml", EmitDeclaredModel(d, ""));
  const DeclaredModel r = LoadDeclaredModel((tmp.path() / "z.yaml").string());
  ASSERT_EQ(r.sources.size(), 1u);
  EXPECT_EQ(r.sources[0].about_axis_rad, 0.0);
  EXPECT_TRUE(r.sources[0].cov.isZero(0.0));
  d.identified_effects.push_back({"joint_offset@joint1", {std::nan("")}, {}, "rad", "", {}});
  try {
    EmitDeclaredModel(d, "");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("identified effect 'joint_offset@joint1' is not finite"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace flexbench::sim

namespace flexbench::sim {
namespace {

constexpr char kUrdf[] = R"(<?xml version="1.0"?>
<robot name="two">
  <link name="base"><visual><geometry><mesh filename="missing/base.dae"/></geometry></visual></link>
  <link name="l1"/>
  <link name="tool"><visual><geometry><sphere radius="0.01"/></geometry></visual></link>
  <joint name="j1" type="revolute"><origin xyz="0 0 0.3" rpy="0.1 0 0"/><parent link="base"/>
    <child link="l1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="fixed_tool" type="fixed"><origin xyz="0.2 0 0.05" rpy="0 0.3 0"/>
    <parent link="l1"/><child link="tool"/></joint>
</robot>)";

TEST(UrdfImport, UnreadableMeshesAreDroppedWithAWarningAndFixedLinksStay) {
  testing::TempDir tmp;
  testing::WriteFile(tmp.path() / "two.urdf", kUrdf);
  std::vector<std::string> warnings;
  MjModelPtr m = LoadModel((tmp.path() / "two.urdf").string(), &warnings);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("missing/base.dae"), std::string::npos) << warnings[0];
  EXPECT_GE(mj_name2id(m.get(), mjOBJ_BODY, "tool"), 0) << "fixed link fused away";
  DeclaredModel d;
  d.file = "two.declared";
  d.actuated_joints = {"j1"};
  d.end_effector = "tool";
  const DeclaredChain chain = BuildDeclaredChain(m.get(), d);
  ExpectChainMatchesMujoco(m.get(), chain, 10);
}

TEST(UrdfImport, MukcaPandaChainMatchesMujoco) {
  const std::string path = testing::SourceDir() + "/../shared/data/mukca/urdf/panda.urdf";
  if (!fs::exists(path)) GTEST_SKIP() << "MUKCa data not found at " << path;
  MjModelPtr m = LoadModel(path);
  DeclaredModel d;
  d.file = "panda.declared";
  for (int k = 1; k <= 7; ++k) d.actuated_joints.push_back("panda_joint" + std::to_string(k));
  d.end_effector = "ball_link";
  const DeclaredChain chain = BuildDeclaredChain(m.get(), d);
  EXPECT_EQ(chain.model.nq(), 7);
  ExpectChainMatchesMujoco(m.get(), chain, 20);
}

}  // namespace
}  // namespace flexbench::sim
