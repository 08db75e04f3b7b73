// The jsk_* scenario kinds through the runner: bad input fails before any work with exit code 2
// and a message naming the file and the parameter; the same seed gives the same bytes (every
// output but the timing object and the command, which names --out); short synthetic and
// dynamic runs give finite metrics.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

std::string Header(const std::string& kind) {
  return "scenario: jsk_test\nkind: " + kind + "\nseed: 7\nmodel: " + SourceDir() +
         "/models/jsk_arm.xml\ndeclared: " + SourceDir() +
         "/models/jsk_arm.declared.yaml\nimus: [imu_link2, imu_link3]\n";
}

const char kSynthetic[] =
    "deflection_k: 0.033\n"
    "trajectory: {waypoints_deg: [[0, 0, 0, 0], [10, 40, 20, 0]], segment_steps: 4, "
    "hold_steps: 2}\n"
    "burn_in_steps: 1\n";

CommandResult RunScenario(const TempDir& dir, const std::string& yaml,
                          const std::string& out = "out") {
  const auto file = dir.path() / "scenario.yaml";
  WriteFile(file, yaml);
  return RunCommand(BinDir() + "/flexbench run " + file.string() + " --out " +
                    (dir.path() / out).string());
}

TEST(JskScenarios, BadFilterParametersAreClearErrors) {
  struct Case {
    std::string estimators;
    std::string message;
  };
  const Case cases[] = {
      {"  pf_all: {kappa_v: 0}\n", "kappa_v must be finite and > 0"},
      {"  pf_all: {kappa_w: -2}\n", "kappa_w must be finite and > 0"},
      {"  pf_all: {bingham_lambda: [0, 0, -800, -800]}\n", "sorted ascending"},
      {"  pf_all: {bingham_lambda: [-700, -700, 100, 100]}\n", "shifted"},
      {"  pf_all: {kapa_v: 5}\n", "unknown parameter 'kapa_v'"},
      {"  mine: {estimator: pf_nothing}\n", "unknown estimator 'pf_nothing'"},
  };
  for (const Case& c : cases) {
    TempDir dir;
    const CommandResult r = RunScenario(
        dir, Header("jsk_sim_deflection") + kSynthetic + "estimators:\n" + c.estimators);
    EXPECT_EQ(r.exit_code, 2) << c.estimators << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("scenario.yaml"), std::string::npos) << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir.path() / "out")) << "no output on bad input";
  }
}

TEST(JskScenarios, BadScenarioKeysAreClearErrors) {
  TempDir dir;
  CommandResult r = RunScenario(dir, Header("jsk_sim_deflection") +
                                         "deflection_k: 0.033\n"
                                         "trajectory: {waypoints_deg: [[0, 0, 0], [1, 2, 3]], "
                                         "segment_steps: 4}\n"
                                         "estimators: {pf_all: {}}\n");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("expected 4 angles"), std::string::npos) << r.err;
  std::string yaml = Header("jsk_sim_deflection") + kSynthetic + "estimators: {pf_all: {}}\n";
  yaml.replace(yaml.find("[imu_link2, imu_link3]"), 22, "[grasp_point]");
  r = RunScenario(dir, yaml);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("is not an IMU site"), std::string::npos) << r.err;
  r = RunScenario(dir,
                  Header("jsk_imu_yaw_drift") +
                      "trajectory: {waypoints_deg: [[0, 0, 0, 0], [0, 10, 0, 0]], segment_s: 1}\n"
                      "sensors: []\nmadgwick: {init: sideways}\nestimators: {pf_all: {}}\n");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("'accel' or 'truth'"), std::string::npos) << r.err;
}

TEST(JskScenarios, SameSeedSameBytes) {
  TempDir dir;
  const std::string yaml = Header("jsk_sim_deflection") + kSynthetic +
                           "estimators:\n  pf_all: {particles: 256, conjugate_proposal: 1}\n"
                           "  boot: {estimator: pf_encoders_imu, particles: 256}\n";
  ASSERT_EQ(RunScenario(dir, yaml, "a").exit_code, 0);
  ASSERT_EQ(RunScenario(dir, yaml, "b").exit_code, 0);
  for (const char* file :
       {"traces.csv", "ee.csv", "frames/fig6_pf_all.png", "frames/fig6_boot.png"}) {
    EXPECT_EQ(ReadFile(dir.path() / "a" / file), ReadFile(dir.path() / "b" / file)) << file;
  }
  auto a = nlohmann::json::parse(ReadFile(dir.path() / "a" / "summary.json"));
  auto b = nlohmann::json::parse(ReadFile(dir.path() / "b" / "summary.json"));
  a.erase("timing");
  b.erase("timing");
  a.erase("command");  // names --out
  b.erase("command");
  EXPECT_EQ(a, b);
  const auto& m = a["estimators"]["pf_all"]["metrics"];
  EXPECT_TRUE(m["joint_rmse_deg"].is_number());
  EXPECT_TRUE(m["pos_err_mean_m"].is_number());
  EXPECT_EQ(m["estimator"], "pf_all");
  EXPECT_EQ(a["estimators"]["boot"]["metrics"]["estimator"], "pf_encoders_imu");
}

TEST(JskScenarios, ShortDynamicRunHasFiniteMetrics) {
  TempDir dir;
  const std::string yaml =
      Header("jsk_imu_yaw_drift") +
      "effects: {imu_bias: {gyro_bias_rad_s: [0, 0, 0.01]}}\n"
      "sensors:\n"
      "  - {name: enc, kind: encoder, side: motor, rate_hz: 100}\n"
      "  - {name: i2, kind: imu, site: imu_link2, rate_hz: 200}\n"
      "  - {name: i3, kind: imu, site: imu_link3, rate_hz: 200}\n"
      "madgwick: {beta: 0.05, init: truth}\n"
      "trajectory: {waypoints_deg: [[0, 20, 20, 0], [10, 40, 10, 0]], segment_s: 1, hold_s: 0.5}\n"
      "burn_in_s: 0.5\n"
      "estimators:\n  pf_bingham_axisym: {particles: 256, conjugate_proposal: 1}\n";
  const CommandResult r = RunScenario(dir, yaml);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto s = nlohmann::json::parse(ReadFile(dir.path() / "out" / "summary.json"));
  EXPECT_EQ(s["metrics"]["snapshots"], 20);
  EXPECT_GT(s["metrics"]["imu_yaw_drift_final_deg"].get<double>(), 0.5);
  EXPECT_LT(s["estimators"]["pf_bingham_axisym"]["metrics"]["joint_err_max_deg"].get<double>(),
            30.0);
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "out" / "frames" / "fig10_yaw_drift.png"));
}

}  // namespace
}  // namespace flexbench::testing
