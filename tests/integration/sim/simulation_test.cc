// The truth side on the real models: loading, the static solve against MuJoCo's own dynamic
// equilibrium, g(q) against the potential energy, every effect off = nominal (and on = not),
// deflection against reach and load, divergence and non-convergence errors.
#include "sim/simulation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <regex>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/sensors/sensor.h"
#include "sim/trajectory.h"
#include "tests/common/test_util.h"

namespace flexbench::sim {
namespace {

std::string ModelPath(const std::string& name) {
  return std::string(FLEXBENCH_SOURCE_DIR) + "/models/" + name + ".xml";
}

EffectList Effects(const std::vector<std::pair<std::string, std::string>>& list) {
  EffectList out;
  for (const auto& [name, params] : list) out.push_back(MakeEffect(name, params));
  return out;
}

std::unique_ptr<Simulation> Rover(const std::vector<std::pair<std::string, std::string>>& fx = {}) {
  return Simulation::Load(ModelPath("rover_arm"), Effects(fx));
}

// Actuated command from {joint: degrees}; others 0.
Eigen::VectorXd Command(const Simulation& sim, const std::map<std::string, double>& deg) {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(sim.num_actuated());
  for (const auto& [j, v] : deg) {
    const auto& names = sim.actuated_joints();
    const auto it = std::find(names.begin(), names.end(), j);
    EXPECT_NE(it, names.end()) << j;
    q[it - names.begin()] = v * kDeg;
  }
  return q;
}

const std::map<std::string, double> kOutstretched = {{"j2", 90}};
const std::map<std::string, double> kFolded = {{"j2", 0}, {"j3", 150}, {"j5", -90}};
const std::map<std::string, double> kSideways = {{"j1", 90}, {"j2", 90}};

double Deflection(Simulation& sim, const std::string& frame) {
  return (sim.Pose(frame).translation() - sim.NominalPose(frame, sim.command()).translation())
      .norm();
}

// Every body, site and camera of the truth against the nominal model: equal to `tol`.
void ExpectAllFramesNominal(Simulation& sim, double tol) {
  const mjModel* m = sim.model();
  std::vector<FrameRef> frames;
  for (int b = 1; b < m->nbody; ++b) frames.push_back({FrameType::kBody, b, ""});
  for (int s = 0; s < m->nsite; ++s) frames.push_back({FrameType::kSite, s, ""});
  for (int c = 0; c < m->ncam; ++c) frames.push_back({FrameType::kCamera, c, ""});
  for (const FrameRef& f : frames) {
    const Eigen::Isometry3d T = sim.Pose(f);
    const Eigen::Isometry3d N = sim.NominalPose(f, sim.command());
    EXPECT_LE((T.translation() - N.translation()).cwiseAbs().maxCoeff(), tol)
        << "frame type " << static_cast<int>(f.type) << " id " << f.id;
    EXPECT_LE((T.linear() - N.linear()).cwiseAbs().maxCoeff(), tol);
  }
}

TEST(Models, LoadWithoutWarningsWithTheExpectedJoints) {
  struct Expect {
    std::string name;
    int actuated;
    int passive;
    int coupled;
  };
  for (const Expect& e : {Expect{"rover_arm", 8, 7, 0}, Expect{"humanoid_upper", 22, 14, 3},
                          Expect{"jsk_arm", 4, 4, 0}}) {
    std::vector<std::string> warnings;
    MjModelPtr m = LoadModel(ModelPath(e.name), &warnings);
    EXPECT_TRUE(warnings.empty()) << e.name << ": " << (warnings.empty() ? "" : warnings[0]);
    const ModelCatalog c = ModelCatalog::Build(m.get(), e.name);
    int passive = 0, coupled = 0;
    for (const JointEntry& j : c.joints) {
      passive += j.role == JointRole::kPassive;
      coupled += j.role == JointRole::kCoupled;
      // A linkage without an effect is the model's own mechanism (the humanoid's torso).
      if (j.role == JointRole::kPassive ||
          (j.role == JointRole::kCoupled && j.effect.empty() && j.driver_slopes.empty())) {
        EXPECT_FALSE(j.effect.empty())
            << e.name << ": passive joint " << j.name << " has no effect";
      }
    }
    EXPECT_EQ(static_cast<int>(c.actuated.size()), e.actuated) << e.name;
    EXPECT_EQ(passive, e.passive) << e.name;
    EXPECT_EQ(coupled, e.coupled) << e.name;
  }
}

TEST(Models, JskArmHasTheNamedJointsImusAndGripperFrame) {
  auto sim = Simulation::Load(ModelPath("jsk_arm"));
  EXPECT_EQ(sim->actuated_joints(),
            (std::vector<std::string>{"link1_yaw_joint", "link2_pitch_joint", "link3_pitch_joint",
                                      "gripper_joint"}));
  EXPECT_EQ(sim->catalog().imu_sites, (std::vector<std::string>{"imu_link2", "imu_link3"}));
  // IMUs sit on the links after the pitch joints.
  const mjModel* m = sim->model();
  const auto after = [&](const char* site, const char* joint) {
    int b = m->site_bodyid[SiteId(m, site)];
    const int jb = m->jnt_bodyid[JointId(m, joint)];
    for (; b > 0; b = m->body_parentid[b]) {
      if (b == jb) return true;
    }
    return false;
  };
  EXPECT_TRUE(after("imu_link2", "link2_pitch_joint"));
  EXPECT_FALSE(after("imu_link2", "link3_pitch_joint"));
  EXPECT_TRUE(after("imu_link3", "link3_pitch_joint"));
  EXPECT_NO_THROW(sim->Frame("grasp_point"));
}

TEST(GravityTorque, IsTheGradientOfThePotentialEnergy) {
  for (const std::string name : {"rover_arm", "jsk_arm", "humanoid_upper"}) {
    auto sim = Simulation::Load(ModelPath(name));
    const mjModel* m = sim->nominal_model();
    MjDataPtr data = MakeData(m);
    mjData* d = data.get();
    const auto potential = [&](const Eigen::VectorXd& q) {
      mju_copy(d->qpos, m->qpos0, m->nq);
      for (int i = 0; i < sim->num_actuated(); ++i) {
        d->qpos[m->jnt_qposadr[sim->catalog().actuated[i]]] = q[i];
      }
      for (const JointEntry& j : sim->catalog().joints) {  // the humanoid's torso linkage
        if (j.role != JointRole::kCoupled || !j.effect.empty()) continue;
        double dq;
        std::vector<double> slopes;
        CoupledValue(m, j, d->qpos, &dq, &slopes);
        d->qpos[j.qpos_adr] = m->qpos0[j.qpos_adr] + dq;
      }
      mj_kinematics(m, d);
      double v = 0.0;
      for (int b = 1; b < m->nbody; ++b) {
        for (int k = 0; k < 3; ++k) v -= m->body_mass[b] * m->opt.gravity[k] * d->xipos[3 * b + k];
      }
      return v;
    };
    for (int trial = 0; trial < 4; ++trial) {
      Eigen::VectorXd q(sim->num_actuated());
      for (int i = 0; i < q.size(); ++i) q[i] = 0.7 * std::sin(1.3 * i + 2.1 * trial + 0.4);
      const Eigen::VectorXd g = sim->GravityTorque(q);
      for (int i = 0; i < q.size(); ++i) {
        const double h = 1e-6;
        Eigen::VectorXd a = q, b = q;
        a[i] += h;
        b[i] -= h;
        const double fd = (potential(a) - potential(b)) / (2 * h);
        EXPECT_NEAR(g[i], fd, 1e-6 * (1.0 + std::abs(fd))) << name << " joint " << i;
      }
    }
  }
}

TEST(Settle, StaticSolveEqualsMujocosDynamicEquilibrium) {
  struct Case {
    std::string model;
    std::vector<std::pair<std::string, std::string>> effects;
    std::map<std::string, double> pose;
    std::string frame;
    double tol;
    // Compared in this body's frame ("" world): below it a soft constraint gives a little.
    std::string relative_to = "";
  };
  const std::vector<Case> cases = {
      {"rover_arm",
       {{"base_compliance", ""}, {"link_bending", ""}, {"camera_mount_sag", ""}},
       {{"j1", 30}, {"j2", 80}, {"j3", 20}, {"j5", -30}, {"mast_tilt", 20}},
       "ee",
       1e-6},
      {"jsk_arm",
       {{"link_bending", ""}, {"joint_compliance", ""}},
       {{"link1_yaw_joint", 20}, {"link2_pitch_joint", 70}, {"link3_pitch_joint", 30}},
       "grasp_point",
       1e-6},
      // The wrist linkage is an equality constraint: MuJoCo's soft constraint gives a little
      // under load.
      {"humanoid_upper",
       {{"neck_elasticity", ""}, {"nonlinear_wrist", ""}},
       {{"neck_pitch", 25},
        {"shoulder_pitch", -8},
        {"elbow", -67},
        {"wrist_pitch", 28},
        {"wrist_yaw", 15}},
       "index_tip",
       1e-4},
      // Bearing and housing compliance: the hinges' springs and their damping. In the chest's
      // frame: the torso linkage below it is MuJoCo's soft equality constraint
      // (Settle.TorsoLinkageKeepsTheChestUpright).
      {"humanoid_upper",
       {{"lateral_compliance",
         "{stiffness_Nm_per_rad: {shoulder_pitch: [3000, 5000], elbow: 800}}"}},
       {{"shoulder_roll", -60}, {"shoulder_pitch", -30}, {"elbow", -40}},
       "right_marker",
       1e-6,
       "torso"},
  };
  for (const Case& c : cases) {
    auto sim = Simulation::Load(ModelPath(c.model), Effects(c.effects));
    const Eigen::VectorXd q = Command(*sim, c.pose);
    sim->SetCommand(q);
    const SettleReport rep = sim->Settle();
    EXPECT_LT(rep.residual, 1e-9);
    const auto pose = [&] {
      return c.relative_to.empty() ? sim->Pose(c.frame)
                                   : sim->BodyPose(c.relative_to).inverse() * sim->Pose(c.frame);
    };
    const Eigen::Isometry3d T_static = pose();
    // Move away, come back, and let the dynamics come to rest.
    sim->SetCommand(Eigen::VectorXd::Zero(q.size()));
    sim->Step(300);
    sim->SetCommand(q);
    sim->SettleDynamic(30.0, 1e-8);
    EXPECT_LT((pose().translation() - T_static.translation()).norm(), c.tol) << c.model;
    EXPECT_GT(Deflection(*sim, c.frame), 1e-3) << c.model << ": effects on, but no deflection";
  }
}

TEST(Settle, NoEffectsMeansTheNominalModelExactly) {
  for (const std::string name : {"rover_arm", "jsk_arm", "humanoid_upper"}) {
    auto sim = Simulation::Load(ModelPath(name));
    for (int trial = 0; trial < 3; ++trial) {
      Eigen::VectorXd q(sim->num_actuated());
      for (int i = 0; i < q.size(); ++i) q[i] = 0.6 * std::cos(0.9 * i + 1.7 * trial);
      sim->SetCommand(q);
      sim->Settle();
      ExpectAllFramesNominal(*sim, 1e-12);
    }
  }
}

// The humanoid's torso (DLR Justin's): torso_pitch_3 = -(torso_pitch_1 + torso_pitch_2) through a
// fixed tendon held at its length, so the chest stays upright whatever the two pitches. The static
// solve sets the linkage from its drivers; MuJoCo's dynamics, left to come to rest, must agree
// (its soft tendon constraint and the servos with their feed-forward, an independent path).
TEST(Settle, TorsoLinkageKeepsTheChestUpright) {
  auto sim = Simulation::Load(ModelPath("humanoid_upper"));
  const auto qpos = [&](const char* joint) { return sim->JointPosition(joint); };
  const Eigen::VectorXd q = Command(*sim, {{"torso_yaw", 20},
                                           {"torso_pitch_1", 25},
                                           {"torso_pitch_2", 15},
                                           {"shoulder_pitch", -60},
                                           {"l_shoulder_pitch", -30},
                                           {"l_elbow", -40}});
  sim->SetCommand(q);
  sim->Settle();
  EXPECT_NEAR(qpos("torso_pitch_3"), -40 * kDeg, 1e-12);
  // Upright: the chest turned about the vertical by the yaw alone, but 0.43 m further forward.
  const Eigen::Isometry3d T_chest = sim->BodyPose("torso");
  const Eigen::Matrix3d R_yaw = Eigen::AngleAxisd(20 * kDeg, Vec3::UnitZ()).toRotationMatrix();
  EXPECT_LT((T_chest.linear() - R_yaw).cwiseAbs().maxCoeff(), 1e-12);
  const double forward = 0.3 * std::sin(25 * kDeg) + 0.25 * std::sin(40 * kDeg);
  EXPECT_NEAR(T_chest.translation().head<2>().norm(), forward, 1e-12);
  // The rigid nominal model knows its own mechanism.
  EXPECT_LT(
      (sim->NominalPose("right_marker", q).translation() - sim->Pose("right_marker").translation())
          .norm(),
      1e-12);
  const Vec3 p_static = sim->Pose("left_marker").translation();
  sim->SetCommand(Eigen::VectorXd::Zero(q.size()));
  sim->Step(300);
  sim->SetCommand(q);
  sim->SettleDynamic(30.0, 1e-8);
  // MuJoCo's soft constraint gives a little under the chest's weight (2e-5 rad measured).
  EXPECT_NEAR(qpos("torso_pitch_3"), -40 * kDeg, 5e-5);
  EXPECT_LT((sim->Pose("left_marker").translation() - p_static).norm(), 2e-5);
}

TEST(Settle, ATendonLinkageNeedsOneFollowerAndActuatedDrivers) {
  const std::string xml = R"(
<mujoco><worldbody><body><joint name="a" axis="0 1 0"/><geom size="0.1" mass="1"/>
  <body pos="0 0 0.3"><joint name="b" axis="0 1 0"/><geom size="0.1" mass="1"/>
  <body pos="0 0 0.3"><joint name="c" axis="0 1 0"/><geom size="0.1" mass="1"/>
  </body></body></body></worldbody>
  <tendon><fixed name="link"><joint joint="a" coef="1"/><joint joint="b" coef="2"/>
    <joint joint="c" coef="1"/></fixed></tendon>
  <equality><tendon tendon1="link"/></equality>
  <actuator><position joint="a" kp="100"/>ACTUATOR_B</actuator></mujoco>)";
  const auto with = [&](const std::string& b) {
    return std::regex_replace(xml, std::regex("ACTUATOR_B"), b);
  };
  const ModelCatalog c = ModelCatalog::Build(
      LoadModelFromString(with("<position joint=\"b\" kp=\"100\"/>"), "t").get(), "t");
  ASSERT_EQ(c.joints[2].role, JointRole::kCoupled);
  EXPECT_EQ(c.joints[2].drivers, (std::vector<int>{0, 1}));
  EXPECT_EQ(c.joints[2].driver_slopes, (std::vector<double>{-1.0, -2.0}));
  try {
    ModelCatalog::Build(LoadModelFromString(with(""), "t").get(), "t");
    ADD_FAILURE() << "two followers accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("tendon 'link' couples two joints without an actuator"),
              std::string::npos)
        << e.what();
  }
}

TEST(Step, DynamicRunWithEffectsOffKeepsLockedJointsExactlyNominal) {
  auto sim = Rover();
  JointTrajectory traj;
  traj.Add(0.0, Command(*sim, {}));
  traj.Add(0.6, Command(*sim, {{"j1", 40}, {"j2", 70}, {"j3", 30}}));
  RunTrajectory(*sim, traj, 0.1, nullptr, nullptr);
  for (const JointEntry& j : sim->catalog().joints) {
    if (j.role != JointRole::kActuated) {
      EXPECT_EQ(sim->JointPosition(j.id), 0.0) << j.name;
    }
  }
  // Poses equal the nominal model at the current link angles.
  Eigen::VectorXd q(sim->num_actuated());
  for (int i = 0; i < q.size(); ++i) q[i] = sim->JointPosition(sim->catalog().actuated[i]);
  const Eigen::Isometry3d T = sim->Pose("ee");
  const Eigen::Isometry3d N = sim->NominalPose("ee", q);
  EXPECT_LT((T.translation() - N.translation()).norm(), 1e-12);
  // The servo reached the command.
  EXPECT_NEAR(sim->JointPosition("j2"), 70 * kDeg, 1e-3);
}

// ---- Each effect: off = nominal in its respect, on = different.

TEST(Effects, CompliantJointGroupsOffAreExactlyZero) {
  struct Case {
    std::string model, effect, joint, frame;
    std::map<std::string, double> pose;
    std::string params = "";
  };
  const std::vector<Case> cases = {
      {"rover_arm", "base_compliance", "plate_pitch", "ee", kOutstretched},
      {"rover_arm", "link_bending", "link2_bend_y", "ee", kOutstretched},
      {"rover_arm", "camera_mount_sag", "mast_sag", "mast_camera", {{"mast_tilt", 30}}},
      {"humanoid_upper", "neck_elasticity", "neck_1_pitch", "head_camera", {{"neck_pitch", 25}}},
      {"humanoid_upper",
       "nonlinear_wrist",
       "wrist_coupling_roll",
       "index_tip",
       {{"wrist_pitch", 30}}},
      {"jsk_arm", "link_bending", "link2_bend_y", "grasp_point", {{"link2_pitch_joint", 90}}},
      {"humanoid_upper",
       "lateral_compliance",
       "elbow_lateral_a",
       "index_tip",
       {{"shoulder_roll", -60}},
       "{stiffness_Nm_per_rad: 800}"},
  };
  for (const Case& c : cases) {
    // The effect off while every other compliance effect of the model is on.
    std::vector<std::pair<std::string, std::string>> others;
    for (const EffectEntry& e : EffectRegistry()) {
      const std::string n = e.name;
      if (n == c.effect) continue;
      if (n == "base_compliance" || n == "link_bending" || n == "camera_mount_sag" ||
          n == "neck_elasticity" || n == "nonlinear_wrist") {
        std::string why;
        auto probe = MakeEffect(n);
        MjModelPtr m = LoadModel(ModelPath(c.model));
        if (probe->SupportedBy(ModelCatalog::Build(m.get(), c.model), m.get(), &why)) {
          others.push_back({n, ""});
        }
      }
    }
    auto off = Simulation::Load(ModelPath(c.model), Effects(others));
    others.push_back({c.effect, c.params});
    auto on = Simulation::Load(ModelPath(c.model), Effects(others));
    for (Simulation* s : {off.get(), on.get()}) {
      s->SetCommand(Command(*s, c.pose));
      s->Settle();
    }
    for (int j : off->catalog().JointsOfEffect(c.effect)) {
      EXPECT_EQ(off->JointPosition(j), 0.0) << c.effect << ": " << off->catalog().Joint(j).name;
    }
    EXPECT_GT(std::abs(on->JointPosition(c.joint)), 1e-4) << c.effect;
    const double d_off =
        (off->Pose(c.frame).translation() - on->Pose(c.frame).translation()).norm();
    EXPECT_GT(d_off, 1e-4) << c.effect << " changes " << c.frame;
  }
}

TEST(Effects, JointElasticityOffHoldsTheCommandOnBendsTheGear) {
  auto off = Simulation::Load(ModelPath("jsk_arm"));
  auto on = Simulation::Load(ModelPath("jsk_arm"), Effects({{"joint_compliance", ""}}));
  for (Simulation* s : {off.get(), on.get()}) {
    s->SetCommand(Command(*s, {{"link2_pitch_joint", 90}}));
    s->Settle();
  }
  EXPECT_EQ(off->JointPosition("link2_pitch_joint"), 90 * kDeg);
  const int j2 = JointId(on->model(), "link2_pitch_joint");
  EXPECT_EQ(on->MotorPosition(j2), 90 * kDeg);
  // Link = motor - g / K (the model's 70 Nm/rad), g at the deflected configuration.
  Eigen::VectorXd q(on->num_actuated());
  for (int i = 0; i < q.size(); ++i) q[i] = on->JointPosition(on->catalog().actuated[i]);
  const double g = on->GravityTorque(q)[1];
  EXPECT_NEAR(on->JointPosition(j2), 90 * kDeg - g / 70.0, 0.05 * std::abs(g / 70.0));
  EXPECT_GT(on->JointPosition(j2) - 90 * kDeg, 0.5 * kDeg);  // sags (g < 0 here)
}

TEST(Effects, BacklashOffExactOnHalfThePlayAgainstTheLoad) {
  auto off = Rover();
  auto on = Rover({{"backlash", "{width_deg: {j2: 0.4, j3: 0.4}}"}});
  for (Simulation* s : {off.get(), on.get()}) {
    s->SetCommand(Command(*s, kOutstretched));
    s->Settle();
  }
  EXPECT_EQ(off->JointPosition("j2"), 90 * kDeg);
  const double g2 = on->GravityTorque(on->command())[1];
  ASSERT_LT(g2, 0.0);  // holding torque negative: the arm sags towards +j2
  EXPECT_NEAR(on->JointPosition("j2"), 90 * kDeg + 0.2 * kDeg, 1e-12);
  EXPECT_EQ(on->JointPosition("j1"), 0.0);  // not listed
  const int j2 = JointId(on->model(), "j2");
  EXPECT_EQ(on->MotorPosition(j2), 90 * kDeg);
  EXPECT_GT(Deflection(*on, "ee"), 1e-3);
}

TEST(Effects, PayloadOffLeavesMassesOnAddsMassAndDeflection) {
  auto off = Rover({{"base_compliance", ""}});
  auto on = Rover({{"base_compliance", ""}, {"payload", "{mass_kg: 1.0, offset_m: [0, 0, 0.1]}"}});
  for (int b = 0; b < off->model()->nbody; ++b) {
    EXPECT_EQ(off->model()->body_mass[b], off->nominal_model()->body_mass[b]);
  }
  const int hand = BodyId(on->model(), "hand");
  EXPECT_NEAR(on->model()->body_mass[hand], on->nominal_model()->body_mass[hand] + 1.0, 1e-12);
  for (Simulation* s : {off.get(), on.get()}) {
    s->SetCommand(Command(*s, kOutstretched));
    s->Settle();
  }
  EXPECT_GT(on->JointPosition("plate_pitch"), 1.2 * off->JointPosition("plate_pitch"));
  EXPECT_GT(Deflection(*on, "ee"), Deflection(*off, "ee") + 2e-3);
  // g(q) is the nominal model's: the payload is unknown to it.
  EXPECT_EQ(on->GravityTorque(on->command()), off->GravityTorque(off->command()));
}

TEST(Effects, ThermalExpansionOffLeavesGeometryOnStretchesTheLinks) {
  auto off = Rover();
  auto on = Rover({{"thermal_expansion", "{delta_T_K: 40, alpha_per_K: 2.3e-5}"}});
  for (int b = 0; b < off->model()->nbody; ++b) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(off->model()->body_pos[3 * b + k], off->nominal_model()->body_pos[3 * b + k]);
    }
  }
  for (Simulation* s : {off.get(), on.get()}) {
    s->SetCommand(Command(*s, kOutstretched));
    s->Settle();
  }
  // Upper arm (0.41 m) and forearm (0.28 m) grow by alpha dT: the wrist moves out along x.
  const double grow = 40 * 2.3e-5 * (0.41 + 0.28);
  const Vec3 d = on->Pose("wrist1").translation() - off->Pose("wrist1").translation();
  EXPECT_NEAR(d.x(), grow, 1e-9);
  EXPECT_NEAR(d.z(), 0.0, 1e-9);
  EXPECT_LT(
      (off->Pose("ee").translation() - off->NominalPose("ee", off->command()).translation()).norm(),
      1e-12);
}

TEST(Effects, EncoderOffsetAndImuBiasOffReadTheTruth) {
  auto off = Simulation::Load(ModelPath("jsk_arm"));
  auto on = Simulation::Load(ModelPath("jsk_arm"),
                             Effects({{"encoder_offset", "{offset_deg: 0.3}"},
                                      {"imu_bias", "{gyro_bias_rad_s: [0.01, 0, 0]}"}}));
  std::vector<SensorReading> a, b;
  for (auto* s : {off.get(), on.get()}) {
    s->SetCommand(Command(*s, {{"link2_pitch_joint", 45}}));
    s->Settle();
    auto enc = MakeSensor("encoder", "enc", "{side: link}", *s, 1);
    auto imu = MakeSensor("imu", "imu", "{site: imu_link2}", *s, 1);
    enc->Sample(*s, 0, s == off.get() ? &a : &b);
    imu->Sample(*s, 0, s == off.get() ? &a : &b);
  }
  for (size_t i = 0; i < a.size(); ++i) {
    if (const auto* e = std::get_if<EncoderReading>(&a[i])) {
      EXPECT_EQ(e->position, off->JointPosition(e->joint));
      EXPECT_NEAR(std::get<EncoderReading>(b[i]).position, e->position + 0.3 * kDeg, 1e-15);
    } else {
      const auto& ia = std::get<ImuReading>(a[i]);
      const auto& ib = std::get<ImuReading>(b[i]);
      EXPECT_EQ(ia.gyro, Vec3::Zero());
      EXPECT_NEAR(ib.gyro.x(), 0.01, 1e-15);
      EXPECT_EQ(ia.accel, ib.accel);
    }
  }
}

// The vocabulary identification shares (sim/effects/effect.h): joint_offset is link - reading,
// as identified; encoder_offset, its former name, gave the encoder's error. Both spellings, and
// every other former name, build the same truth bit for bit.
TEST(Effects, FormerNamesBuildTheSameTruth) {
  struct Pair {
    std::pair<std::string, std::string> now, before;
  };
  const std::vector<Pair> pairs = {
      {{"joint_offset", "{offset_deg: {j2: -0.3, j3: 0.25}}"},
       {"encoder_offset", "{offset_deg: {j2: 0.3, j3: -0.25}}"}},
      {{"joint_compliance", "{stiffness_Nm_per_rad: {j2: 800}}"},
       {"joint_elasticity", "{stiffness_Nm_per_rad: {j2: 800}}"}},
      {{"stiffening_spring", "{stiffness_Nm_per_rad: {j2: 800}, cubic_Nm_per_rad3: {j2: 3e5}}"},
       {"stiffening_joint", "{stiffness_Nm_per_rad: {j2: 800}, cubic_Nm_per_rad3: {j2: 3e5}}"}},
      {{"base_compliance", ""}, {"base_plate_compliance", ""}},
      {{"link_bending", ""}, {"link_elasticity", ""}},
  };
  for (const Pair& p : pairs) {
    std::vector<std::vector<SensorReading>> readings(2);
    std::vector<Eigen::Isometry3d> ee;
    for (int k = 0; k < 2; ++k) {
      auto s = Rover({k == 0 ? p.now : p.before});
      s->SetCommand(Command(*s, kOutstretched));
      s->Settle();
      ee.push_back(s->Pose("ee"));
      MakeSensor("encoder", "enc", "{side: link}", *s, 1)->Sample(*s, 0, &readings[k]);
    }
    EXPECT_TRUE(ee[0].matrix() == ee[1].matrix()) << p.now.first;
    ASSERT_EQ(readings[0].size(), readings[1].size());
    for (size_t i = 0; i < readings[0].size(); ++i) {
      EXPECT_EQ(std::get<EncoderReading>(readings[0][i]).position,
                std::get<EncoderReading>(readings[1][i]).position)
          << p.now.first << " reading " << i;
    }
  }
}

// A model annotated with the former effect names (effect:base_plate_compliance,
// effect:link_elasticity, effect:joint_elasticity[:stiffness]) builds the same truth as one with
// the current names, and says once which name it read as which.
TEST(Effects, FormerMjcfTagsBuildTheSameTruthWithANote) {
  testing::TempDir tmp;
  std::string xml = testing::ReadFile(ModelPath("rover_arm"));
  for (const auto& [now, before] : std::vector<std::pair<std::string, std::string>>{
           {"effect:base_compliance", "effect:base_plate_compliance"},
           {"effect:link_bending", "effect:link_elasticity"},
           {"effect:joint_compliance", "effect:joint_elasticity"}}) {
    for (size_t at; (at = xml.find(now + "\"")) != std::string::npos;)
      xml.replace(at, now.size(), before);
    for (size_t at; (at = xml.find(now + ":")) != std::string::npos;)
      xml.replace(at, now.size(), before);
  }
  ASSERT_EQ(xml.find("effect:joint_compliance"), std::string::npos);
  const std::string former = (tmp.path() / "rover_former.xml").string();
  testing::WriteFile(former, xml);
  const EffectList fx =
      Effects({{"base_compliance", ""}, {"link_bending", ""}, {"joint_compliance", ""}});
  std::vector<Eigen::Isometry3d> ee;
  for (const std::string& path : {ModelPath("rover_arm"), former}) {
    ::testing::internal::CaptureStderr();
    auto s = Simulation::Load(path, fx);
    const std::string err = ::testing::internal::GetCapturedStderr();
    const bool old = path == former;
    EXPECT_EQ(err.find("'joint_elasticity' is the former name of 'joint_compliance'") !=
                  std::string::npos,
              old)
        << err;
    EXPECT_EQ(err.find("'base_plate_compliance' is the former name of 'base_compliance'") !=
                  std::string::npos,
              old)
        << err;
    s->SetCommand(Command(*s, kOutstretched));
    s->Settle();
    ee.push_back(s->Pose("ee"));
  }
  EXPECT_TRUE(ee[0].matrix() == ee[1].matrix());
  auto rigid = Rover();
  rigid->SetCommand(Command(*rigid, kOutstretched));
  rigid->Settle();
  EXPECT_GT((ee[0].translation() - rigid->Pose("ee").translation()).norm(), 1e-4);
}

// One effect under both its names would apply twice (offsets cancelling, a plate twice as soft).
TEST(Effects, AnEffectUnderBothNamesIsGivenTwice) {
  try {
    Rover({{"joint_offset", "{offset_deg: 0.3}"}, {"encoder_offset", "{offset_deg: 0.3}"}});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("effect 'encoder_offset' given twice (it is "
                                         "'joint_offset')"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(Rover({{"base_plate_compliance", ""}, {"base_compliance", ""}}), InputError);
}

TEST(Effects, UnknownOrUnsupportedEffectsAreBadInput) {
  try {
    MakeEffect("gravity_waves");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown effect 'gravity_waves'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("base_compliance"), std::string::npos);
  }
  try {
    Rover({{"neck_elasticity", ""}});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("rover_arm.xml"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("neck_elasticity"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Rover({{"payload", "{}"}}), InputError);                     // needs mass_kg
  EXPECT_THROW(Rover({{"backlash", "{width_deg: {j9: 1}}"}}), InputError);  // no such joint
  EXPECT_THROW(Rover({{"link_bending", "{stiffness_scale: -1}"}}), InputError);
  EXPECT_THROW(Simulation::Load(ModelPath("humanoid_upper"), Effects({{"joint_compliance", ""}})),
               InputError);  // the humanoid declares no gear stiffness
}

// ---- Deflection against reach and load (PPOE paper, Table I).

TEST(RoverDeflection, GrowsWithReachAndLoadSoftMoreThanStiff) {
  auto sim = Rover({{"base_compliance", ""}, {"link_bending", ""}});
  double previous_tilt = -1.0, previous_defl = -1.0;
  for (int k = 0; k <= 6; ++k) {
    const double a = k / 6.0;
    sim->SetCommand(Command(*sim, {{"j2", 90 * a}, {"j3", 150 * (1 - a)}, {"j5", -90 + 60 * a}}));
    sim->Settle();
    const double tilt = sim->JointPosition("plate_pitch");
    const double defl = Deflection(*sim, "ee");
    EXPECT_GT(tilt, previous_tilt);
    EXPECT_GT(defl, previous_defl);
    previous_tilt = tilt;
    previous_defl = defl;
  }
  sim->SetCommand(Command(*sim, kFolded));
  sim->Settle();
  const double folded_tilt = sim->JointPosition("plate_pitch") / kDeg;
  const double folded_defl = Deflection(*sim, "ee");
  sim->SetCommand(Command(*sim, kOutstretched));
  sim->Settle();
  const double out_tilt = sim->JointPosition("plate_pitch") / kDeg;
  const double out_defl = Deflection(*sim, "ee");
  sim->SetCommand(Command(*sim, kSideways));
  sim->Settle();
  const double side_roll = std::abs(sim->JointPosition("plate_roll")) / kDeg;
  // Roughly 1 deg soft tilt stretched out, clearly less in the stiff direction.
  EXPECT_GT(out_tilt, 0.7);
  EXPECT_LT(out_tilt, 1.3);
  EXPECT_GT(out_tilt, 2.0 * folded_tilt);
  EXPECT_LT(side_roll, 0.5 * out_tilt);
  // Table I: about 1.5 cm stretched out, under 1 cm close in.
  EXPECT_GT(out_defl, 0.012);
  EXPECT_LT(out_defl, 0.025);
  EXPECT_LT(folded_defl, 0.01);

  auto loaded =
      Rover({{"base_compliance", ""}, {"link_bending", ""}, {"payload", "{mass_kg: 0.5}"}});
  loaded->SetCommand(Command(*loaded, kOutstretched));
  loaded->Settle();
  EXPECT_GT(loaded->JointPosition("plate_pitch") / kDeg, out_tilt);
  EXPECT_GT(Deflection(*loaded, "ee"), out_defl);
}

TEST(HumanoidNeck, BendsHalfToFiveDegreesUnderMotion) {
  auto sim = Simulation::Load(ModelPath("humanoid_upper"), Effects({{"neck_elasticity", ""}}));
  // Against the nominal model at the actuated joints' actual angles (not the command): the
  // neck's own bending, without the servos' tracking lag.
  const auto head_error_deg = [&]() {
    Eigen::VectorXd q(sim->num_actuated());
    for (int i = 0; i < q.size(); ++i) q[i] = sim->JointPosition(sim->catalog().actuated[i]);
    const Eigen::Isometry3d T = sim->Pose("head");
    const Eigen::Isometry3d N = sim->NominalPose("head", q);
    return Eigen::AngleAxisd(T.linear().transpose() * N.linear()).angle() / kDeg;
  };
  JointTrajectory traj;  // look down at the table, then turn the head
  traj.Add(0.0, Command(*sim, {}));
  traj.Add(0.8, Command(*sim, {{"neck_pitch", 30}}));
  traj.Add(1.6, Command(*sim, {{"neck_pitch", 30}, {"neck_yaw", 40}}));
  traj.Add(2.4, Command(*sim, {{"neck_pitch", 10}, {"neck_yaw", -20}}));
  sim->Settle();
  double worst = 0.0;
  while (sim->time() < 2.8) {
    sim->SetCommand(traj.At(sim->time()));
    sim->Step(5);
    worst = std::max(worst, head_error_deg());
  }
  EXPECT_GT(worst, 0.5);
  EXPECT_LT(worst, 5.0);
  sim->SetCommand(Command(*sim, {{"neck_pitch", 25}}));
  sim->Settle();
  EXPECT_GT(head_error_deg(), 0.5);
  EXPECT_LT(head_error_deg(), 5.0);
}

TEST(HumanoidWrist, LinkageDeviatesFromTwoRevoluteJointsNonlinearly) {
  auto sim = Simulation::Load(ModelPath("humanoid_upper"), Effects({{"nonlinear_wrist", ""}}));
  std::vector<double> err;
  for (double deg : {0.0, 10.0, 20.0, 40.0}) {
    sim->SetCommand(Command(*sim, {{"wrist_pitch", deg}}));
    sim->Settle();
    const Eigen::Isometry3d T = sim->Pose("hand");
    const Eigen::Isometry3d N = sim->NominalPose("hand", sim->command());
    err.push_back(Eigen::AngleAxisd(T.linear().transpose() * N.linear()).angle() / kDeg);
  }
  EXPECT_EQ(err[0], 0.0);
  // Quadratic: doubling the angle roughly quadruples the error.
  EXPECT_NEAR(err[2] / err[1], 4.0, 0.5);
  EXPECT_GT(err[3], 1.0);
  EXPECT_LT(err[3], 5.0);
}

TEST(JskArm, GravityDeflectionIsLargerHorizontalThanVertical) {
  auto sim = Simulation::Load(ModelPath("jsk_arm"),
                              Effects({{"joint_compliance", ""}, {"link_bending", ""}}));
  sim->SetCommand(Command(*sim, {}));
  sim->Settle();
  const double vertical = Deflection(*sim, "grasp_point");
  sim->SetCommand(Command(*sim, {{"link2_pitch_joint", 90}}));
  sim->Settle();
  const double horizontal = Deflection(*sim, "grasp_point");
  EXPECT_LT(vertical, 1e-3);  // small offsets of the centres of mass
  EXPECT_GT(horizontal, 0.01);
  EXPECT_LT(horizontal, 0.08);
}

// ---- Errors that name the model and the step / iteration.

TEST(Errors, DivergingSimulationNamesModelAndStep) {
  // A stiff spring on a tiny inertia: k >> 4 I / dt^2, semi-implicit Euler explodes.
  const char xml[] = R"(
<mujoco model="unstable">
  <option timestep="0.01"/>
  <worldbody>
    <body name="b">
      <joint name="spring" axis="0 1 0" stiffness="1e6"/>
      <inertial pos="0.1 0 0" mass="0.01" diaginertia="1e-6 1e-6 1e-6"/>
    </body>
  </worldbody>
</mujoco>)";
  auto sim = Simulation::FromString(xml, "unstable.xml");
  try {
    sim->Step(2000);
    FAIL() << "no divergence detected";
  } catch (const SimulationError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("unstable.xml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("diverged at step"), std::string::npos) << msg;
    EXPECT_NE(msg.find("spring"), std::string::npos) << msg;
  }
}

TEST(Errors, NonConvergingSettleNamesModelAndIteration) {
  auto sim = Rover({{"base_compliance", ""}});
  sim->SetCommand(Command(*sim, kOutstretched));
  SettleOptions opt;
  opt.tolerance = 0.0;
  opt.max_iterations = 3;
  try {
    sim->Settle(opt);
    FAIL();
  } catch (const SimulationError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("rover_arm.xml"), std::string::npos) << msg;
    EXPECT_NE(msg.find("did not converge"), std::string::npos) << msg;
    EXPECT_NE(msg.find("iteration"), std::string::npos) << msg;
  }
  EXPECT_THROW(sim->SettleDynamic(0.01, 1e-12), SimulationError);
}

TEST(Errors, PassiveJointWithoutStiffnessCannotSettle) {
  const char xml[] = R"(
<mujoco model="floppy">
  <custom><text name="effect:link_bending" data="floppy"/></custom>
  <worldbody>
    <body name="b">
      <joint name="floppy" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
    </body>
  </worldbody>
</mujoco>)";
  auto sim = Simulation::FromString(xml, "floppy.xml", Effects({{"link_bending", ""}}));
  // g = 0 and k = 0: already at equilibrium (residual 0), nothing to solve.
  EXPECT_NO_THROW(sim->Settle());
}

}  // namespace
}  // namespace flexbench::sim
