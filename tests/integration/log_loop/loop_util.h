// Shared by the log-loop tests: the closed loop run on a recorded log's time spans, and logs
// exported from MuJoCo runs of jsk_flexible_arm.
#pragma once

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/common/test_util.h"

namespace flexbench::testing {

namespace fs = std::filesystem;

inline const std::string kModels = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";

// The loop on `log`: calibration up to `split` s, validation (held out) after it; the points in
// the base frame, or in an unknown tracker frame named `frame`. `source_keys` go into both log
// sources (", streams: [imu]"), `root_keys` into the scenario (lines).
inline nlohmann::json RunLoop(const fs::path& dir, const fs::path& log, double split,
                              const std::vector<std::string>& expected,
                              const std::string& frame = "", const std::string& source_keys = "",
                              const std::string& root_keys = "") {
  std::string names;
  for (const std::string& e : expected) names += (names.empty() ? "" : ", ") + e;
  const std::string in_frame = (frame.empty() ? "" : ", frame: " + frame) + source_keys;
  char spans[1024];
  std::snprintf(spans, sizeof(spans),
                "calibration: {log: {dir: %s, to_s: %.17g%s}}\n"
                "validation: {log: {dir: %s, from_s: %.17g%s}}\n%s",
                log.c_str(), split, in_frame.c_str(), log.c_str(), split + 1e-3, in_frame.c_str(),
                frame.empty() ? "" : ("frames: {" + frame + ": {}}\n").c_str());
  testing::WriteFile(dir / "loop.yaml", "scenario: log_loop\nkind: closed_loop\nseed: 1\nmodel: " +
                                            kModels + "jsk_arm.xml\ndeclared: " + kModels +
                                            "jsk_arm.declared.yaml\npoint_std_m: 0.0003\n" + spans +
                                            "expected_effects: [" + names + "]\n" + root_keys);
  const CommandResult r = RunCommand(testing::Flexbench() + " run " + (dir / "loop.yaml").string() +
                                     " --out " + (dir / "loop").string() + " --quiet");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return nlohmann::json::parse(testing::ReadFile(dir / "loop" / "summary.json"))["metrics"];
}

inline void Print(const char* what, const nlohmann::json& m) {
  const nlohmann::json& fk = m["heldout_replay"]["fk"];
  std::printf("%s: verdict %s, found %s, held-out fk %.2f -> %.2f mm\n", what,
              m["verdict"].get<std::string>().c_str(), m["effects_found"].dump().c_str(),
              1e3 * fk["before"]["pos_err_mean_m"].get<double>(),
              1e3 * fk["after"]["pos_err_mean_m"].get<double>());
}

inline double HeldOut(const nlohmann::json& m, const char* when) {
  return m["heldout_replay"]["fk"][when]["pos_err_mean_m"].get<double>();
}

// jsk_flexible_arm's run of the truth `effects` (its motion, motor-side encoders with noise and
// quantisation, two IMUs, truth at 10 Hz), exported as a log; `tags`: with the external camera
// rendered and its tags detected at each step; `model`: the truth's MJCF (default jsk_arm's).
inline fs::path ExportMujocoRun(const fs::path& dir, const std::string& effects, int seed,
                                bool tags = false, const std::string& model = "") {
  testing::WriteFile(
      dir / "run.yaml",
      "scenario: export\nkind: jsk_flexible_arm\nseed: " + std::to_string(seed) + "\nmodel: " +
          (model.empty() ? kModels + "jsk_arm.xml" : model) + "\ndeclared: " + kModels +
          "jsk_arm.declared.yaml\nimus: [imu_link2, imu_link3]\neffects: " + effects +
          "\nsensors:\n"
          "  - {name: encoders, kind: encoder, side: motor, noise_std_deg: 0.02, "
          "counts_per_rev: 4096, rate_hz: 100}\n"
          "  - {name: imu2, kind: imu, site: imu_link2, gyro_noise_std_rad_s: 0.003, "
          "accel_noise_std_m_s2: 0.05, rate_hz: 200}\n"
          "  - {name: imu3, kind: imu, site: imu_link3, gyro_noise_std_rad_s: 0.003, "
          "accel_noise_std_m_s2: 0.05, rate_hz: 200}\n"
          "filter_rate_hz: 10\nmadgwick: {beta: 0.05, init: accel}\ntrajectory:\n"
          "  waypoints_deg: [[0, 0, 0, 0], [20, 30, 20, 10], [-20, 60, 30, 30], [10, 90, 0, 10], "
          "[0, 70, 40, 0]]\n  segment_s: 3\n  hold_s: 2\nburn_in_s: 1.0\n"
          "estimators: {fk: {}}\n" +
          (tags ? "tag_camera: {camera: external_camera}\n" : ""));
  const CommandResult r =
      RunCommand(testing::Flexbench() + " run " + (dir / "run.yaml").string() + " --out " +
                 (dir / "run").string() + " --export-log " + (dir / "log").string() + " --quiet");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return dir / "log";
}

// The log's truth.tum and its mention removed: what is left are the sensors.
inline void RemoveTruth(const fs::path& log) {
  fs::remove(log / "truth.tum");
  std::string yaml = testing::ReadFile(log / "log.yaml");
  const size_t at = yaml.find("truth:");
  yaml.erase(at, yaml.find('\n', at) + 1 - at);
  testing::WriteFile(log / "log.yaml", yaml);
}

}  // namespace flexbench::testing
