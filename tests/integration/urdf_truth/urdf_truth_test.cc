// A URDF as the truth. `flexbench convert` writes an MJCF that MuJoCo loads from any folder (its
// mesh found), with a position servo per joint and the URDF's inertials, whose bodies and geoms
// stand where MuJoCo's own import of the URDF puts them at random postures. The truth loads a
// URDF with the same servos, so truth effects act on its joints: a joint offset and a joint
// compliance checked against MuJoCo's import of the URDF without servos (its kinematics and its
// gravity torque), and a mismatch_matrix scenario on the URDF runs and scores its estimators.
// Bad input to convert is one line and exit 2. `flexbench export` writes mesh geoms in place.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "sim/effects/effect.h"
#include "sim/model_catalog.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;

// Three revolute joints (yaw, then two pitches), full inertia tensors, a mesh in a subfolder on
// the first link (off its origin, so MuJoCo recentres it), a box on the second, nothing on the
// third, and a fixed tool link.
constexpr char kArmUrdf[] = R"(<?xml version="1.0"?>
<robot name="arm3">
  <link name="base">
    <inertial><origin xyz="0 0 0.05"/><mass value="2.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
  </link>
  <joint name="j1" type="revolute">
    <origin xyz="0 0 0.1" rpy="0 0 0.3"/><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/>
  </joint>
  <link name="l1">
    <inertial><origin xyz="0.1 0.01 0.02" rpy="0.1 0.2 0.3"/><mass value="1.2"/>
      <inertia ixx="0.002" ixy="0.0001" ixz="0.00005" iyy="0.01" iyz="0.0002" izz="0.011"/>
    </inertial>
    <visual><origin xyz="0.02 0 0" rpy="0 0.1 0"/>
      <geometry><mesh filename="meshes/block.stl"/></geometry></visual>
  </link>
  <joint name="j2" type="continuous">
    <origin xyz="0.25 0 0.05" rpy="0 0 0"/><parent link="l1"/><child link="l2"/>
    <axis xyz="0 1 0"/>
  </joint>
  <link name="l2">
    <inertial><origin xyz="0.15 0 0"/><mass value="0.8"/>
      <inertia ixx="0.001" ixy="0" ixz="0.0001" iyy="0.005" iyz="0" izz="0.005"/></inertial>
    <visual><origin xyz="0.15 0 0"/><geometry><box size="0.3 0.03 0.03"/></geometry></visual>
  </link>
  <joint name="j3" type="revolute">
    <origin xyz="0.3 0 0" rpy="0.05 0 0"/><parent link="l2"/><child link="l3"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="10" velocity="1"/>
  </joint>
  <link name="l3">
    <inertial><origin xyz="0.1 0 0"/><mass value="0.4"/>
      <inertia ixx="0.0003" ixy="0" ixz="0" iyy="0.0015" iyz="0" izz="0.0015"/></inertial>
  </link>
  <joint name="tool_joint" type="fixed">
    <origin xyz="0.2 0 0"/><parent link="l3"/><child link="tool"/>
  </joint>
  <link name="tool"/>
</robot>
)";

// A binary STL box of 40 x 30 x 20 mm with a corner at the origin.
std::string BlockStl() {
  const float a = 0.04f, b = 0.03f, c = 0.02f;
  const float v[8][3] = {{0, 0, 0}, {a, 0, 0}, {a, b, 0}, {0, b, 0},
                         {0, 0, c}, {a, 0, c}, {a, b, c}, {0, b, c}};
  const int f[12][3] = {{0, 2, 1}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}, {0, 1, 5}, {0, 5, 4},
                        {1, 2, 6}, {1, 6, 5}, {2, 3, 7}, {2, 7, 6}, {3, 0, 4}, {3, 4, 7}};
  std::string s(80, '\0');
  const std::uint32_t n = 12;
  s.append(reinterpret_cast<const char*>(&n), 4);
  for (const auto& t : f) {
    const float normal[3] = {0, 0, 0};
    s.append(reinterpret_cast<const char*>(normal), 12);
    for (int k : t) s.append(reinterpret_cast<const char*>(v[k]), 12);
    s.append(2, '\0');
  }
  return s;
}

class UrdfTruth : public ::testing::Test {
 protected:
  void SetUp() override {
    testing::WriteFile(dir() / "robot" / "arm.urdf", kArmUrdf);
    testing::WriteFile(dir() / "robot" / "meshes" / "block.stl", BlockStl());
  }
  fs::path dir() const { return tmp_.path(); }
  std::string urdf() const { return (dir() / "robot" / "arm.urdf").string(); }
  testing::CommandResult Fb(const std::string& args) const {
    return testing::RunCommand(testing::Flexbench() + " " + args);
  }

  testing::TempDir tmp_;
};

// Sets the hinge joints of `m` (one qpos each) and runs MuJoCo's kinematics.
void Pose(const mjModel* m, mjData* d, const std::vector<double>& q) {
  for (size_t k = 0; k < q.size(); ++k) d->qpos[m->jnt_qposadr[k]] = q[k];
  mj_kinematics(m, d);
}

double MaxDiff(const double* a, const double* b, int n) {
  double worst = 0.0;
  for (int i = 0; i < n; ++i) worst = std::max(worst, std::abs(a[i] - b[i]));
  return worst;
}

// Quaternions q and -q are one rotation.
double QuatDiff(const double* a, const double* b) {
  double plus = 0.0, minus = 0.0;
  for (int i = 0; i < 4; ++i) {
    plus = std::max(plus, std::abs(a[i] - b[i]));
    minus = std::max(minus, std::abs(a[i] + b[i]));
  }
  return std::min(plus, minus);
}

TEST_F(UrdfTruth, ConvertWritesServosInertialsAndTheUrdfsPoses) {
  // Written to another folder than the URDF's: the mesh must still be found.
  const fs::path out = dir() / "elsewhere" / "arm.xml";
  fs::create_directories(out.parent_path());
  const testing::CommandResult r =
      Fb("convert " + urdf() + " --actuators position --kp 40 -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("3 position servos"), std::string::npos) << r.out;

  sim::MjModelPtr urdf_model = sim::LoadModel(urdf());
  char error[1024] = "";
  sim::MjModelPtr mjcf(mj_loadXML(out.c_str(), nullptr, error, sizeof(error)));  // MuJoCo alone
  ASSERT_TRUE(mjcf) << error;
  const mjModel* u = urdf_model.get();
  const mjModel* c = mjcf.get();
  ASSERT_EQ(c->nbody, u->nbody);
  ASSERT_EQ(c->njnt, 3);
  ASSERT_EQ(c->ngeom, u->ngeom);
  EXPECT_EQ(c->nmesh, 1);  // the mesh loaded, not dropped
  EXPECT_EQ(u->nmesh, 1);

  // A <position> servo per joint, kp as given: the catalogue the truth reads takes them.
  const sim::ModelCatalog catalog = sim::ModelCatalog::Build(c, out.string());
  EXPECT_EQ(catalog.ActuatedNames(), (std::vector<std::string>{"j1", "j2", "j3"}));
  for (int a = 0; a < c->nu; ++a) EXPECT_EQ(c->actuator_gainprm[a * mjNGAIN], 40.0);

  // The URDF's inertials as MuJoCo imported them, every digit.
  EXPECT_EQ(MaxDiff(c->body_mass, u->body_mass, u->nbody), 0.0);
  EXPECT_LT(MaxDiff(c->body_inertia, u->body_inertia, 3 * u->nbody), 1e-15);
  EXPECT_LT(MaxDiff(c->body_ipos, u->body_ipos, 3 * u->nbody), 1e-15);

  // Bodies and geoms (the recentred mesh among them) where MuJoCo's import of the URDF puts
  // them, at random postures.
  sim::MjDataPtr du = sim::MakeData(u);
  sim::MjDataPtr dc = sim::MakeData(c);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> angle(-2.5, 2.5);
  double pos = 0.0, rot = 0.0, geom_pos = 0.0, geom_rot = 0.0;
  for (int trial = 0; trial < 20; ++trial) {
    const std::vector<double> q = {angle(rng), angle(rng), angle(rng)};
    Pose(u, du.get(), q);
    Pose(c, dc.get(), q);
    pos = std::max(pos, MaxDiff(dc->xpos, du->xpos, 3 * u->nbody));
    pos = std::max(pos, MaxDiff(dc->xipos, du->xipos, 3 * u->nbody));
    for (int b = 0; b < u->nbody; ++b) {
      rot = std::max(rot, QuatDiff(dc->xquat + 4 * b, du->xquat + 4 * b));
    }
    geom_pos = std::max(geom_pos, MaxDiff(dc->geom_xpos, du->geom_xpos, 3 * u->ngeom));
    geom_rot = std::max(geom_rot, MaxDiff(dc->geom_xmat, du->geom_xmat, 9 * u->ngeom));
  }
  EXPECT_LT(pos, 1e-12);
  EXPECT_LT(rot, 1e-12);
  EXPECT_LT(geom_pos, 1e-12);
  EXPECT_LT(geom_rot, 1e-12);

  // An existing output is refused without --force.
  const testing::CommandResult again =
      Fb("convert " + urdf() + " --actuators position -o " + out.string());
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_EQ(testing::CountLines(again.err), 1) << again.err;
  EXPECT_EQ(Fb("convert " + urdf() + " --actuators position --force -o " + out.string()).exit_code,
            0);
}

// The same writer under `flexbench export`: the rover's AprilTag meshes (recentred by MuJoCo)
// stand where the model has them; written at the model's compiled pose they were compiled a
// second time (1 mm and a quarter turn off).
TEST_F(UrdfTruth, ExportKeepsMeshGeomsWhereTheModelHasThem) {
  const std::string declared = testing::SourceDir() + "/models/rover_arm.declared.yaml";
  const fs::path out = dir() / "rover.xml";
  const testing::CommandResult r = Fb("export " + declared + " --mjcf " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  sim::MjModelPtr a = sim::LoadModel(testing::SourceDir() + "/models/rover_arm.xml");
  sim::MjModelPtr b = sim::LoadModel(out.string());
  ASSERT_EQ(a->ngeom, b->ngeom);
  int meshes = 0;
  for (int g = 0; g < a->ngeom; ++g) meshes += a->geom_type[g] == mjGEOM_MESH;
  ASSERT_GT(meshes, 0);
  sim::MjDataPtr da = sim::MakeData(a.get());
  sim::MjDataPtr db = sim::MakeData(b.get());
  mj_kinematics(a.get(), da.get());
  mj_kinematics(b.get(), db.get());
  EXPECT_LT(MaxDiff(da->geom_xpos, db->geom_xpos, 3 * a->ngeom), 1e-12);
  EXPECT_LT(MaxDiff(da->geom_xmat, db->geom_xmat, 9 * a->ngeom), 1e-12);
}

TEST_F(UrdfTruth, ConvertBadInputIsOneLineExit2) {
  std::string broken = kArmUrdf;
  broken.replace(broken.find("<parent link=\"l2\"/>"), 19, "<parent link=\"nowhere\"/>");
  testing::WriteFile(dir() / "robot" / "broken.urdf", broken);
  testing::WriteFile(dir() / "robot" / "cut.urdf", std::string(kArmUrdf).substr(0, 400));
  const std::string out = " -o " + (dir() / "out.xml").string();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {(dir() / "robot" / "broken.urdf").string() + " --actuators position", "broken.urdf"},
      {(dir() / "robot" / "cut.urdf").string() + " --actuators position", "cut.urdf"},
      {(dir() / "robot" / "missing.urdf").string() + " --actuators position", "missing.urdf"},
      {urdf() + " --actuators velocity", "--actuators 'velocity'"},
      {urdf(), "--actuators ''"},
      {urdf() + " --actuators position --kp -3", "--kp '-3'"},
      {urdf() + " --actuators position --kp 1e400", "--kp '1e400'"},
      {urdf() + " --actuators position --kp 5x", "--kp '5x'"},
      {(dir() / "robot" / "meshes" / "block.stl").string() + " --actuators position",
       "expected a URDF file"},
  };
  for (const auto& [args, named] : cases) {
    const testing::CommandResult r = Fb("convert " + args + out);
    EXPECT_EQ(r.exit_code, 2) << args << ": " << r.err;
    EXPECT_EQ(testing::CountLines(r.err), 1) << args << ": " << r.err;
    EXPECT_NE(r.err.find(named), std::string::npos) << args << ": " << r.err;
  }
  EXPECT_FALSE(fs::exists(dir() / "out.xml"));
}

TEST_F(UrdfTruth, InspectListsTheServosItAdds) {
  const testing::CommandResult r = Fb("inspect " + urdf());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  std::vector<std::string> names;
  for (const auto& a : j["actuated_joints"]) names.push_back(a["name"].get<std::string>());
  EXPECT_EQ(names, (std::vector<std::string>{"j1", "j2", "j3"}));
  EXPECT_NE(j.value("servos_added", "").find("<position> servo"), std::string::npos);
  for (const auto& e : j["effects"]) {
    if (e["name"] == "joint_offset" || e["name"] == "joint_compliance") {
      EXPECT_TRUE(e["supported"].get<bool>()) << e.dump();
    }
  }
}

// The truth's joint offset and gear compliance on URDF joints, against MuJoCo's import of the
// URDF without servos: the encoders read link - offset, and the compliant joint deflects until
// its spring holds the URDF's gravity torque.
TEST_F(UrdfTruth, TruthEffectsActOnUrdfJoints) {
  const double offset = 0.7 * kDeg;
  const double k = 150.0;
  const ConfigNode effects = ConfigNode::LoadString(
      "joint_offset: {offset_deg: {j2: 0.7}}\n"
      "joint_compliance: {stiffness_Nm_per_rad: {j3: 150}}\n",
      "effects.yaml");
  auto sim = sim::Simulation::Load(urdf(), sim::ParseEffects(effects));
  ASSERT_EQ(sim->actuated_joints(), (std::vector<std::string>{"j1", "j2", "j3"}));
  sim::MjModelPtr plain = sim::LoadModel(urdf());
  const mjModel* u = plain.get();
  EXPECT_EQ(u->nu, 0);
  sim::MjDataPtr d = sim::MakeData(u);
  const Eigen::Vector3d command(0.4, -0.6, 0.9);
  sim->SetCommand(command);
  sim->Settle();
  const double q1 = sim->JointPosition("j1");
  const double q2 = sim->JointPosition("j2");
  const double q3 = sim->JointPosition("j3");
  EXPECT_NEAR(q1, command[0], 1e-12);
  // The link stands at its command; its encoders read link - offset.
  EXPECT_NEAR(q2, command[1], 1e-12);
  EXPECT_EQ(sim->JointOffset(sim::JointId(sim->model(), "j2")), offset);
  // Deflected by gravity, by a visible amount.
  EXPECT_GT(std::abs(q3 - command[2]), 1e-3);
  // The URDF's own gravity torque at the settled posture is what the spring holds.
  Pose(u, d.get(), {q1, q2, q3});
  mj_forward(u, d.get());
  const double tau_gravity = d->qfrc_bias[u->jnt_dofadr[2]];
  EXPECT_NEAR(k * (command[2] - q3), tau_gravity, 1e-6 * std::abs(tau_gravity));
  // The tool where the URDF's kinematics put it at the links' angles.
  const Eigen::Isometry3d T = sim->BodyPose("tool");
  const int tool = sim::BodyId(u, "tool");
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(T.translation()[i], d->xpos[3 * tool + i], 1e-12);
}

// A scenario whose truth is the URDF: a joint offset and a gear compliance on its joints,
// estimators scored. Without the servos the truth refused the effects ("not an actuated joint").
TEST_F(UrdfTruth, MismatchMatrixOnAUrdfTruthScoresItsEstimators) {
  const std::string scenario = R"(scenario: urdf_truth
kind: mismatch_matrix
seed: 5
model: robot/arm.urdf
declared:
  model: robot/arm.urdf
  actuated_joints: [j1, j2, j3]
  end_effector: tool
  sources:
    - {at: j1, about_axis_deg: 0.05}
    - {at: j2, about_axis_deg: 0.05}
    - {at: j3, about_axis_deg: 0.05}
effects:
  none: {}
  offset: {joint_offset: {offset_deg: {j2: 1.0}}}
  compliance: {joint_compliance: {stiffness_Nm_per_rad: {j2: 150}}}
configurations: 12
ranges_deg: {j1: [-60, 60], j2: [-60, 30], j3: [-90, 90]}
encoder_noise_deg: 0.05
point_std_m: 0.002
estimators:
  fk: {}
  ppoe_ekf: {}
)";
  testing::WriteFile(dir() / "urdf_truth.yaml", scenario);
  const fs::path out = dir() / "out";
  const testing::CommandResult r =
      Fb("run " + (dir() / "urdf_truth.yaml").string() + " --quiet --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json s = nlohmann::json::parse(testing::ReadFile(out / "summary.json"));
  for (const char* e : {"fk", "ppoe_ekf"}) {
    for (const char* col : {"none", "offset", "compliance"}) {
      const double err = s["estimators"][e]["metrics"][col]["pos_err_mean_m"].get<double>();
      EXPECT_TRUE(std::isfinite(err) && err > 0.0) << e << " " << col;
    }
  }
  const nlohmann::json& fk = s["estimators"]["fk"]["metrics"];
  // fk reads the encoders only: a 1 deg offset at j2 moves the tool by 1 deg times its distance
  // from j2's axis, between |0.3 - 0.2| and 0.3 + 0.2 m (j3 to the tool, j2 to j3), plus the
  // encoders' noise (the 'none' column).
  const double none = fk["none"]["pos_err_mean_m"].get<double>();
  const double with_offset = fk["offset"]["pos_err_mean_m"].get<double>();
  EXPECT_GT(with_offset, 0.1 * kDeg - none);
  EXPECT_LT(with_offset, 0.5 * kDeg + none);
  EXPECT_GT(fk["compliance"]["pos_err_mean_m"].get<double>(), 2.0 * none);
}

}  // namespace
}  // namespace flexbench
