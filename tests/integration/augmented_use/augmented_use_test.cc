// An augmented model used beyond its calibration: its sources keep what the calibration rows
// could not see, its file says where it was fitted (fitted_under), and a run that leaves those
// joint ranges is warned of in the log and in summary.json's `warnings`.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "estimators/error.h"
#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/runner.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "sim/posture_load.h"
#include "tests/common/test_util.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

fs::path TempDir(const std::string& what) {
  const fs::path dir =
      fs::temp_directory_path() / ("flexbench_" + what + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

sim::DeclaredModel WithRange(double lo_deg, double hi_deg) {
  sim::DeclaredModel d;
  d.file = "/somewhere/declared_augmented.yaml";
  d.fitted_under.joint_ranges.push_back({"j2", lo_deg * M_PI / 180.0, hi_deg * M_PI / 180.0});
  return d;
}

Json Checked(const sim::DeclaredModel& d, const std::vector<double>& j2_deg) {
  Json summary = {{"metrics", Json::object()}};
  RunContext ctx;
  ctx.summary = &summary;
  ctx.log = [](const std::string&) {};
  FittedRangeCheck check(d, {"j1", "j2", "j3"}, nullptr, nullptr);
  for (double deg : j2_deg) {
    const double q[3] = {1.0, deg * M_PI / 180.0, -2.0};  // j1, j3 have no fitted range
    check.Observe(q, 3);
  }
  check.Report(ctx);
  return summary;
}

TEST(FittedRange, InsideSaysNothingOutsideWarnsOnce) {
  const sim::DeclaredModel d = WithRange(10.0, 40.0);
  EXPECT_FALSE(Checked(d, {12.0, 39.0}).contains("warnings"));
  const Json out = Checked(d, {12.0, 45.0, 50.0});
  ASSERT_TRUE(out.contains("warnings"));
  ASSERT_EQ(out["warnings"].size(), 1u);
  const std::string w = out["warnings"][0];
  EXPECT_NE(w.find("j2 12..50 deg (fitted 10..40)"), std::string::npos) << w;
  EXPECT_NE(w.find("declared_augmented.yaml"), std::string::npos) << w;
  EXPECT_EQ(w.find("j1"), std::string::npos) << w;
  // A model without fitted_under is not checked.
  EXPECT_FALSE(Checked(sim::DeclaredModel{}, {500.0}).contains("warnings"));
}

// The load and the reach are conditions of their own: a posture inside every joint range can
// hold another gravity torque or put the end effector elsewhere. rover_arm with the ranges,
// torques and box of one posture: that posture says nothing; j2 = 0 instead of 0.6 rad (arm
// upright, inside a range widened to hold both) leaves the torque band and the box.
TEST(FittedRange, GravityTorqueAndEndEffectorBoxAreChecked) {
  sim::DeclaredModel d =
      sim::LoadDeclaredModel(testing::SourceDir() + "/models/rover_arm.declared.yaml");
  const sim::MjModelPtr m = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(chain.model.nq());
  const int j2 = chain.QIndex("j2");
  q[j2] = 0.6;
  q[chain.QIndex("j3")] = 0.9;
  sim::PostureLoadEvaluator load(m.get(), chain);
  sim::PostureLoad at;
  load.Evaluate(q, &at);
  // MuJoCo's own gravity torque at that posture, set up independently of PostureLoad.
  mjData* data = mj_makeData(m.get());
  chain.WriteQpos(q, data->qpos);
  mj_forward(m.get(), data);
  const int dof = m->jnt_dofadr[mj_name2id(m.get(), mjOBJ_JOINT, "j2")];
  EXPECT_NEAR(at.gravity_torque[j2], data->qfrc_bias[dof], 1e-9);
  EXPECT_GT(std::abs(at.gravity_torque[j2]), 1.0);  // the arm held out loads its shoulder
  mj_deleteData(data);

  d.file = "/somewhere/declared_augmented.yaml";
  d.fitted_under.joint_ranges.push_back({"j2", -0.1, 0.7});
  d.fitted_under.gravity_torques.push_back(
      {"j2", at.gravity_torque[j2] - 0.5, at.gravity_torque[j2] + 0.5});
  d.fitted_under.has_box = true;
  d.fitted_under.box_min = at.p_base_ee - Vec3::Constant(0.01);
  d.fitted_under.box_max = at.p_base_ee + Vec3::Constant(0.01);
  const auto warnings = [&](const Eigen::VectorXd& posture) {
    Json summary = {{"metrics", Json::object()}};
    RunContext ctx;
    ctx.summary = &summary;
    FittedRangeCheck check(d, chain.q_joints, m.get(), &chain);
    check.Observe(posture.data(), static_cast<int>(posture.size()));
    check.Report(ctx);
    return summary.value("warnings", Json::array());
  };
  EXPECT_TRUE(warnings(q).empty());
  Eigen::VectorXd upright = q;
  upright[j2] = 0.0;
  const Json w = warnings(upright);
  ASSERT_EQ(w.size(), 1u);
  const std::string line = w[0];
  EXPECT_EQ(line.find("joint ranges"), std::string::npos) << line;
  EXPECT_NE(line.find("gravity torques: j2"), std::string::npos) << line;
  EXPECT_NE(line.find("end-effector position"), std::string::npos) << line;
}

TEST(FittedRange, WrittenAndReadBackEnclosingTheRows) {
  const fs::path dir = TempDir("fitted_under");
  sim::DeclaredModel d =
      sim::LoadDeclaredModel(testing::SourceDir() + "/models/rover_arm.declared.yaml");
  d.fitted_under = WithRange(-12.345678912, 47.000000123).fitted_under;
  d.fitted_under.source_scale = 1e-6;
  d.fitted_under.constrained_sources = {"j3:about_axis"};
  d.fitted_under.kept_declared_sources = {"base_plate:rot_x"};
  d.fitted_under.gravity_torques.push_back({"j2", -31.234567891, 4.5000001});
  d.fitted_under.has_box = true;
  d.fitted_under.box_min = Vec3(0.8712345678, -0.2, 0.48);
  d.fitted_under.box_max = Vec3(1.0572345678, 0.2042, 0.589);
  d.model_path = fs::absolute(d.model_path).string();
  testing::WriteFile(dir / "aug.yaml", sim::EmitDeclaredModel(d, "header"));
  const sim::DeclaredModel back = sim::LoadDeclaredModel((dir / "aug.yaml").string());
  ASSERT_EQ(back.fitted_under.joint_ranges.size(), 1u);
  const auto& r = back.fitted_under.joint_ranges[0];
  EXPECT_LE(r.min, d.fitted_under.joint_ranges[0].min);
  EXPECT_GE(r.max, d.fitted_under.joint_ranges[0].max);
  EXPECT_NEAR(r.max * 180.0 / M_PI, 47.0001, 1e-9);  // outward by one unit of the 6th digit
  EXPECT_EQ(back.fitted_under.constrained_sources, d.fitted_under.constrained_sources);
  EXPECT_EQ(back.fitted_under.kept_declared_sources, d.fitted_under.kept_declared_sources);
  EXPECT_EQ(back.fitted_under.source_scale, 1e-6);
  ASSERT_EQ(back.fitted_under.gravity_torques.size(), 1u);
  EXPECT_LE(back.fitted_under.gravity_torques[0].min, -31.234567891);
  EXPECT_GE(back.fitted_under.gravity_torques[0].max, 4.5000001);
  ASSERT_TRUE(back.fitted_under.has_box);
  EXPECT_TRUE((back.fitted_under.box_min.array() <= d.fitted_under.box_min.array()).all());
  EXPECT_TRUE((back.fitted_under.box_max.array() >= d.fitted_under.box_max.array()).all());
  EXPECT_NEAR(back.fitted_under.box_max.x(), 1.05724, 1e-12);
  // Bad input names the file, the line and the key.
  std::string text = testing::ReadFile(dir / "aug.yaml");
  const std::string written = "[-12.3457, 47.0001]";
  ASSERT_NE(text.find(written), std::string::npos) << text;
  text.replace(text.find(written), written.size(), "[47, -12]");
  testing::WriteFile(dir / "bad.yaml", text);
  const std::string err =
      testing::ErrorOf([&] { sim::LoadDeclaredModel((dir / "bad.yaml").string()); });
  EXPECT_NE(err.find("bad.yaml:"), std::string::npos) << err;
  EXPECT_NE(err.find("min must not exceed max"), std::string::npos) << err;
  fs::remove_all(dir);
}

// A recorded log replayed under an augmented model whose fitted_under leaves out part of the
// log's postures: the warning is printed and in summary.json; within the ranges, none.
TEST(FittedRange, ReplayOfALogBeyondTheRangesIsWarned) {
  const fs::path dir = TempDir("replay_range");
  RunOptions cal;
  cal.scenario_path = testing::SourceDir() + "/scenarios/closed_loop_recorded_log.yaml";
  cal.out_dir = (dir / "cal").string();
  cal.quiet = true;
  ASSERT_EQ(RunScenario(cal), kExitOk);
  std::string yaml = testing::ReadFile(dir / "cal" / "declared_augmented.yaml");
  const size_t at = yaml.find("link2_pitch_joint: [");
  ASSERT_NE(at, std::string::npos) << yaml;
  yaml.replace(at, yaml.find(']', at) - at + 1, "link2_pitch_joint: [0, 45]");
  testing::WriteFile(dir / "cal" / "narrow.yaml", yaml);
  const auto replay = [&](const std::string& declared, const std::string& out) {
    const testing::CommandResult r = testing::RunCommand(
        testing::Flexbench() + " replay " + testing::SourceDir() +
        "/scenarios/logs/jsk_flexible_arm --declared " + (dir / "cal" / declared).string() +
        " --out " + (dir / out).string() + " --quiet");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return std::make_pair(r.err,
                          nlohmann::json::parse(testing::ReadFile(dir / out / "summary.json")));
  };
  const auto [err, narrow] = replay("narrow.yaml", "narrow");
  ASSERT_TRUE(narrow.contains("warnings"));
  EXPECT_NE(narrow["warnings"][0].get<std::string>().find("link2_pitch_joint 0..90"),
            std::string::npos);
  EXPECT_NE(err.find("warning: the run leaves the conditions narrow.yaml"), std::string::npos)
      << err;
  EXPECT_FALSE(replay("declared_augmented.yaml", "whole").second.contains("warnings"));
  // The jsk kinds check too: jsk_sim_deflection's trajectory swings link1 to 30 deg and link3
  // to 60 deg, beyond the recorded log's postures.
  RunOptions deflection;
  deflection.scenario_path = testing::SourceDir() + "/scenarios/jsk_sim_deflection.yaml";
  deflection.out_dir = (dir / "deflection").string();
  deflection.quiet = true;
  deflection.set = {"declared=" + (dir / "cal" / "declared_augmented.yaml").string()};
  ASSERT_EQ(RunScenario(deflection), kExitOk);
  const nlohmann::json d =
      nlohmann::json::parse(testing::ReadFile(dir / "deflection" / "summary.json"));
  ASSERT_TRUE(d.contains("warnings"));
  EXPECT_NE(d["warnings"][0].get<std::string>().find("link3_pitch_joint 0..60 deg"),
            std::string::npos)
      << d["warnings"];
  fs::remove_all(dir);
}

struct Lateral {
  double ppoe = 0.0, naive = 0.0;
  int warned = 0;
};

// rover_apriltag_exp1 over seeds with the given declared model (empty: the scenario's own).
Lateral Exp1(const fs::path& out, const std::string& declared, const std::vector<int>& seeds) {
  Lateral l;
  for (int seed : seeds) {
    RunOptions o;
    o.scenario_path = testing::SourceDir() + "/scenarios/rover_apriltag_exp1.yaml";
    o.out_dir = (out / ("exp1_" + std::to_string(seed))).string();
    o.seed = seed;
    o.quiet = true;
    o.force = true;
    if (!declared.empty()) o.set = {"declared=" + declared};
    EXPECT_EQ(RunScenario(o), kExitOk);
    const nlohmann::json s =
        nlohmann::json::parse(testing::ReadFile(fs::path(o.out_dir) / "summary.json"));
    l.ppoe +=
        s["estimators"]["ppoe_ekf"]["metrics"]["lateral_err_mean_m"].get<double>() / seeds.size();
    l.naive +=
        s["estimators"]["naive_ekf"]["metrics"]["lateral_err_mean_m"].get<double>() / seeds.size();
    // The sockets sit a metre out; exp1's end effector stays near the chassis.
    l.warned += s.contains("warnings") && s["warnings"][0].get<std::string>().find(
                                              "end-effector position") != std::string::npos
                    ? 1
                    : 0;
  }
  return l;
}

// Calibration rows of sockets whose truth has only exp1's elbow offset (0.17 deg): they see no
// plate tilt (a socket's rows move alike) and no mast. Scaling every source by 1e-6 on their
// word put ppoe_ekf's lateral error on exp1 (compliant plate, bending links) above naive_ekf's.
TEST(AugmentedModelElsewhere, KeepsWhatTheCalibrationDidNotSeeAndWarns) {
  const fs::path dir = TempDir("augmented_use");
  RunOptions cal;
  cal.scenario_path = testing::SourceDir() + "/scenarios/closed_loop_encoder_offset.yaml";
  cal.out_dir = (dir / "cal").string();
  cal.quiet = true;
  cal.set = {"truth.effects.joint_offset.offset_deg={j3: 0.17}"};
  ASSERT_EQ(RunScenario(cal), kExitOk);
  const nlohmann::json scaling = nlohmann::json::parse(
      testing::ReadFile(dir / "cal" / "summary.json"))["metrics"]["source_scaling"];
  const std::vector<std::string> kept = scaling["kept_declared"];
  for (const char* k : {"base_plate:rot_x", "base_plate:rot_y", "base_plate:rot_z",
                        "mast_pan:about_axis", "mast_tilt:about_axis"}) {
    EXPECT_NE(std::find(kept.begin(), kept.end(), k), kept.end()) << k;
  }
  const std::vector<std::string> constrained = scaling["constrained"];
  EXPECT_NE(std::find(constrained.begin(), constrained.end(), "j3:about_axis"), constrained.end());
  const fs::path augmented = dir / "cal" / "declared_augmented.yaml";
  const sim::DeclaredModel aug = sim::LoadDeclaredModel(augmented.string());
  EXPECT_FALSE(aug.fitted_under.empty());
  EXPECT_EQ(aug.fitted_under.kept_declared_sources, kept);

  const std::vector<int> seeds = {101, 102, 103, 104, 105, 106};
  const Lateral declared = Exp1(dir, "", seeds);
  const Lateral fitted = Exp1(dir, augmented.string(), seeds);
  EXPECT_LT(fitted.ppoe, 1.1 * declared.ppoe);
  EXPECT_LT(fitted.ppoe, 0.8 * fitted.naive);  // ppoe_beats_naive on the seeds' means
  // exp1's postures are not the sockets': every run with the augmented model is warned.
  EXPECT_EQ(declared.warned, 0);
  EXPECT_EQ(fitted.warned, static_cast<int>(seeds.size()));
  fs::remove_all(dir);
}

// The same robot calibrated: sockets of exp1's own truth (plate, bending links, every encoder's
// offset) a metre out. The fitted model then beats the declared one on exp1 for ppoe_ekf and
// naive_ekf alike, and the runs are still warned: exp1's end effector is not where the sockets
// were.
TEST(AugmentedModelElsewhere, SameRobotCalibrationImprovesExp1) {
  const fs::path dir = TempDir("augmented_same");
  RunOptions cal;
  cal.scenario_path = testing::SourceDir() + "/scenarios/closed_loop_encoder_offset.yaml";
  cal.out_dir = (dir / "cal").string();
  cal.quiet = true;
  cal.set = {
      "truth.effects={base_compliance: {}, link_bending: {}, joint_offset: {offset_deg: "
      "{j1: -0.235, j2: 0.349, j3: 0.17, j4: -0.093, j5: 0.254, j6: 0.018, "
      "mast_pan: -0.1, mast_tilt: -0.1}}}",
      "truth.expected=[joint_offset@j2]"};
  ASSERT_EQ(RunScenario(cal), kExitOk);
  const std::vector<int> seeds = {101, 102, 103, 104, 105, 106};
  const Lateral declared = Exp1(dir, "", seeds);
  const Lateral fitted = Exp1(dir, (dir / "cal" / "declared_augmented.yaml").string(), seeds);
  EXPECT_LT(fitted.ppoe, 0.9 * declared.ppoe);
  EXPECT_LT(fitted.naive, 0.9 * declared.naive);
  EXPECT_EQ(fitted.warned, static_cast<int>(seeds.size()));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace flexbench::scenarios
