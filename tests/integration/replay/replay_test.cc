// `kind: replay`: a recorded log folder through the estimators. The log is written here from the
// declared jsk_arm's kinematics along a smooth motion (encoders with an offset at the pitch
// joints, two IMUs whose gyro and accelerometer readings follow the links' orientations, the
// grasp point's truth), not by the code under test. Direct fusion reads the pitch angles off
// the raw IMU readings where fk is off by the offset; the same seed gives the same bytes; bad
// logs are one line and exit 2.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "tests/common/jsk_log.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;
using testing::CommandResult;
using testing::RunCommand;

std::string Scenario(const fs::path& log) {
  return "scenario: replay_test\nkind: replay\nseed: 4\nlog: " + log.string() +
         "\nstep_hz: 10\nestimators:\n  fk: {}\n  pf_encoders_imu: {particles: 512}\n  "
         "direct_fusion_yxz: {}\n";
}

CommandResult RunReplay(const fs::path& scenario, const fs::path& out) {
  return RunCommand(testing::Flexbench() + " run " + scenario.string() + " --out " + out.string() +
                    " --quiet");
}

TEST(Replay, ALogRunsThroughTheEstimatorsWithTheSameBytesEachTime) {
  testing::TempDir tmp;
  testing::JskLogOptions o;
  o.duration = 6.0;
  testing::WriteJskLog(tmp.path() / "log", o);
  testing::WriteFile(tmp.path() / "replay.yaml", Scenario(tmp.path() / "log"));
  const CommandResult r = RunReplay(tmp.path() / "replay.yaml", tmp.path() / "out");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json s =
      nlohmann::json::parse(testing::ReadFile(tmp.path() / "out" / "summary.json"));
  const nlohmann::json& m = s["metrics"];
  EXPECT_EQ(m["steps"], 61);
  EXPECT_EQ(m["streams"]["joints"]["rows"], 601);
  EXPECT_EQ(m["streams"]["imu"]["rows"], 2 * 1200);
  EXPECT_EQ(m["streams"]["imu"]["gaps"], 0);
  EXPECT_EQ(m["streams_without_overlap"], 0);
  const nlohmann::json& fk = s["estimators"]["fk"]["metrics"];
  EXPECT_EQ(fk["steps_scored"], 61);
  EXPECT_GT(fk["pos_err_mean_m"].get<double>(), 0.02);  // the encoders' offset
  const nlohmann::json& pf = s["estimators"]["pf_encoders_imu"]["metrics"];
  EXPECT_EQ(pf["steps_scored"], 61);
  EXPECT_EQ(pf["rejected_readings"], 0);
  EXPECT_LT(pf["pos_err_mean_m"].get<double>(), 0.05);
  // The pitch angles read off the raw IMU readings (through Madgwick's filters) instead of the
  // offset encoders: the IMU stream reaches the estimators in the right frames and order.
  const nlohmann::json& fusion = s["estimators"]["direct_fusion_yxz"]["metrics"];
  EXPECT_LT(fusion["pos_err_mean_m"].get<double>(), 0.003);
  std::printf(
      "mean position error on the replayed log: fk %.4f m, direct_fusion_yxz %.4f m, "
      "pf_encoders_imu %.4f m\n",
      fk["pos_err_mean_m"].get<double>(), fusion["pos_err_mean_m"].get<double>(),
      pf["pos_err_mean_m"].get<double>());
  const fs::path tum = tmp.path() / "out" / "trajectories" / "base" / "pf_encoders_imu.tum";
  ASSERT_TRUE(fs::exists(tum));
  ASSERT_EQ(RunReplay(tmp.path() / "replay.yaml", tmp.path() / "again").exit_code, 0);
  EXPECT_EQ(testing::ReadFile(tum), testing::ReadFile(tmp.path() / "again" / "trajectories" /
                                                      "base" / "pf_encoders_imu.tum"));
}

TEST(Replay, ABadLogIsOneLineAndExitTwo) {
  const struct {
    const char* file;
    std::string from, to, expect;
  } cases[] = {
      {"joints.csv", "link2_pitch_joint_rad", "link9_rad",
       "joints.csv:1: no column for declared joint 'link2_pitch_joint'"},
      {"log.yaml", "frame: imu_link3", "frame: nowhere", "nowhere"},
      {"log.yaml", "frame: grasp_point", "frame: imu_link2", "truth.frame 'imu_link2'"},
      {"joints.csv", "gripper_joint_rad", "gripper_joint_m",
       "column 'gripper_joint_m': " + testing::SourceDir() +
           "/models/jsk_arm.declared.yaml declares 'gripper_joint' revolute"},
      {"log.yaml", "frame: imu_link3", "frame: nowhere", "log.yaml: imu.sensors.imu3.frame"},
      {"imu.csv", "0.01,imu3", "0.01,imu7", "imu.csv:5: column 'sensor': 'imu7'"},
      {"tags.csv", ",cam0,20,", ",cam9,20,", "tags.csv:2: column 'camera': 'cam9'"},
      {"tags.csv", ",cam0,20,", ",cam0,21,",
       "tags.csv:2: column 'tag_id': 21 is not one of the log's tags.ids"},
      {"tags.csv", "u3_px", "u3", "tags.csv:1: the header must be t_s,camera,tag_id,"},
      {"tags.csv", ",cam0,20,", ",cam0,20,nan,", "tags.csv:2: 12 columns, the header has 11"},
      {"log.yaml", "frame: tag_gripper", "frame: nowhere", "log.yaml: tags.ids.20.frame"},
      {"log.yaml", "frame: external_camera", "frame: nowhere", "log.yaml: cameras.cam0.frame"},
      {"log.yaml", "size_m: 0.04", "size_m: -1", "size_m"},
      {"contacts.csv", ",tip,table,", ",toe,table,", "contacts.csv:2: column 'point': 'toe'"},
      {"contacts.csv", ",tip,table,", ",tip,floor,", "contacts.csv:2: column 'plane': 'floor'"},
      {"contacts.csv", ",0.0005\n", ",0\n", "contacts.csv:2: column 'std_m' must be > 0"},
      {"log.yaml", "points: {tip: {frame: grasp_point}}", "points: {tip: {frame: nowhere}}",
       "log.yaml: contacts.points.tip.frame"},
      {"log.yaml", "0.9, 1, 0, 0, 0]", "0.9, 2, 0, 0, 0]", "T_base_plane"},
  };
  for (const auto& c : cases) {
    testing::TempDir tmp;
    testing::JskLogOptions o;
    o.duration = 3.0;
    o.tags = true;
    o.contacts = true;
    testing::WriteJskLog(tmp.path() / "log", o);
    const fs::path f = tmp.path() / "log" / c.file;
    std::string text = testing::ReadFile(f);
    const size_t at = text.find(c.from);
    ASSERT_NE(at, std::string::npos) << c.from;
    text.replace(at, c.from.size(), c.to);
    testing::WriteFile(f, text);
    testing::WriteFile(tmp.path() / "replay.yaml", Scenario(tmp.path() / "log"));
    const CommandResult r = RunReplay(tmp.path() / "replay.yaml", tmp.path() / "out");
    EXPECT_EQ(r.exit_code, 2) << c.expect << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "out"));
  }
}

// Positions of a TUM file by time.
std::map<double, Vec3> TumPositions(const fs::path& file) {
  std::map<double, Vec3> out;
  std::istringstream in(testing::ReadFile(file));
  for (std::string line; std::getline(in, line);) {
    double t, x, y, z;
    if (line.empty() || line[0] == '#') continue;
    if (std::sscanf(line.c_str(), "%lf %lf %lf %lf", &t, &x, &y, &z) == 4) out[t] = Vec3(x, y, z);
  }
  return out;
}

// Tag detections in a log (tags.csv, cameras and tags in log.yaml) reach the estimators that use
// them, at the camera and tag frames the log names: at the steps the gripper's tag is seen, the
// PPOE EKF corrects the offset encoders' kinematic prior across the camera's line of sight,
// where fk cannot (along it a 4 cm tag 1.2 m away says little).
TEST(Replay, TagDetectionsInALogCorrectTheOffsetEncoders) {
  testing::TempDir tmp;
  testing::JskLogOptions o;
  o.duration = 20.0;
  o.tags = true;
  testing::WriteJskLog(tmp.path() / "log", o);
  const CommandResult r = RunCommand(
      testing::Flexbench() + " replay " + (tmp.path() / "log").string() +
      " --estimators fk,ppoe_ekf --step-hz 10 --quiet --out " + (tmp.path() / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json s =
      nlohmann::json::parse(testing::ReadFile(tmp.path() / "out" / "summary.json"));
  EXPECT_EQ(s["estimators"]["ppoe_ekf"]["metrics"]["rejected_readings"], 0);
  const fs::path dir = tmp.path() / "out" / "trajectories" / "base";
  const std::map<double, Vec3> truth = TumPositions(dir / "truth.tum");
  const std::map<double, Vec3> fk = TumPositions(dir / "fk.tum");
  const std::map<double, Vec3> ekf = TumPositions(dir / "ppoe_ekf.tum");
  // The camera's line of sight to the gripper: from the camera's position in jsk_arm.xml.
  const Vec3 p_camera(0.30, -1.05, 1.10);
  std::istringstream tags(testing::ReadFile(tmp.path() / "log" / "tags.csv"));
  std::string line;
  std::getline(tags, line);
  int seen = 0;
  double fk_across = 0.0, ekf_across = 0.0;
  for (; std::getline(tags, line); ++seen) {
    const double t = std::stod(line.substr(0, line.find(',')));
    const auto at = truth.lower_bound(t - 1e-9);
    ASSERT_NE(at, truth.end());
    const Vec3 sight = (at->second - p_camera).normalized();
    const auto across = [&](const Vec3& e) { return (e - e.dot(sight) * sight).norm(); };
    fk_across += across(fk.at(at->first) - at->second);
    ekf_across += across(ekf.at(at->first) - at->second);
  }
  std::printf(
      "%d steps with the tag seen; mean position error across the line of sight fk %.2f mm, "
      "ppoe_ekf %.2f mm\n",
      seen, 1e3 * fk_across / seen, 1e3 * ekf_across / seen);
  EXPECT_EQ(s["metrics"]["streams"]["tags"]["rows"], seen);
  EXPECT_GE(seen, 30);
  EXPECT_LT(ekf_across, 0.2 * fk_across);
}

// Contact readings in a log (contacts.csv; planes and points in log.yaml) reach the EKF after each
// step's joints: the grasp point's height over a plane corrects the offset encoders' prior
// along the plane's normal at every step, where fk keeps the offset's error.
TEST(Replay, ContactReadingsInALogCorrectTheOffsetEncodersAlongTheNormal) {
  testing::TempDir tmp;
  testing::JskLogOptions o;
  o.duration = 10.0;
  o.contacts = true;
  testing::WriteJskLog(tmp.path() / "log", o);
  const CommandResult r = RunCommand(
      testing::Flexbench() + " replay " + (tmp.path() / "log").string() +
      " --estimators fk,ppoe_ekf --step-hz 10 --quiet --out " + (tmp.path() / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json s =
      nlohmann::json::parse(testing::ReadFile(tmp.path() / "out" / "summary.json"));
  EXPECT_EQ(s["metrics"]["streams"]["contacts"]["rows"], 101);
  EXPECT_EQ(s["estimators"]["ppoe_ekf"]["metrics"]["rejected_readings"], 0);
  const fs::path dir = tmp.path() / "out" / "trajectories" / "base";
  const std::map<double, Vec3> truth = TumPositions(dir / "truth.tum");
  const std::map<double, Vec3> fk = TumPositions(dir / "fk.tum");
  const std::map<double, Vec3> ekf = TumPositions(dir / "ppoe_ekf.tum");
  double fk_z = 0.0, ekf_z = 0.0;
  for (const auto& [t, p] : truth) {
    fk_z += std::abs(fk.at(t).z() - p.z());
    ekf_z += std::abs(ekf.at(t).z() - p.z());
  }
  std::printf("%zu steps; mean height error fk %.2f mm, ppoe_ekf %.2f mm\n", truth.size(),
              1e3 * fk_z / truth.size(), 1e3 * ekf_z / truth.size());
  EXPECT_EQ(truth.size(), 101u);
  EXPECT_LT(ekf_z, 0.3 * fk_z);  // 0.22: the plane is known within 0.5 deg, the prior 1-3 deg
}

// With a tag camera (rendered through OSMesa, detected by libapriltag at each filter step), the
// exported log carries the detections (tags.csv, the camera and the tags' corners in log.yaml),
// or with export_images the frames themselves (images/<camera>/<t_ns>.png), which the replay
// runs through the same detector; either way the PPOE EKF, which corrects its prior with the
// tags, replays to the same bits.
TEST(Replay, AnExportedRunWithATagCameraReplaysToTheSameBits) {
  for (const bool images : {false, true}) {
    testing::TempDir tmp;
    std::string yaml = testing::ReadFile(testing::SourceDir() + "/scenarios/jsk_flexible_arm.yaml");
    for (size_t at; (at = yaml.find("../models/")) != std::string::npos;) {
      yaml.replace(at, 10, testing::SourceDir() + "/models/");
    }
    const std::string estimators = "estimators:\n  fk: {}\n";
    ASSERT_NE(yaml.find(estimators), std::string::npos);
    yaml.replace(yaml.find(estimators), estimators.size(),
                 "tag_camera: {camera: external_camera, pixel_std_px: 0.8, export_images: " +
                     std::string(images ? "true" : "false") + "}\n" + estimators +
                     "  ppoe_ekf: {}\n");
    yaml = yaml.substr(0, yaml.find("gates:"));
    testing::WriteFile(tmp.path() / "tags.yaml", yaml);
    const CommandResult live =
        RunCommand(testing::Flexbench() + " run " + (tmp.path() / "tags.yaml").string() +
                   " --out " + (tmp.path() / "live").string() + " --export-log " +
                   (tmp.path() / "log").string() + " --quiet");
    ASSERT_EQ(live.exit_code, 0) << live.err;
    EXPECT_EQ(fs::exists(tmp.path() / "log" / "images"), images);
    EXPECT_EQ(fs::exists(tmp.path() / "log" / "tags.csv"), !images);
    const CommandResult replay =
        RunCommand(testing::Flexbench() + " replay " + (tmp.path() / "log").string() +
                   " --estimators fk,ppoe_ekf --set seed=3 --quiet --out " +
                   (tmp.path() / "replayed").string());
    ASSERT_EQ(replay.exit_code, 0) << replay.err;
    const nlohmann::json s =
        nlohmann::json::parse(testing::ReadFile(tmp.path() / "replayed" / "summary.json"));
    EXPECT_GE(s["metrics"]["streams"]["tags"]["rows"].get<int>(), 100);
    if (images) {
      EXPECT_EQ(s["metrics"]["streams"]["images"]["rows"], 220);
    }
    for (const char* name : {"fk", "ppoe_ekf"}) {
      for (const std::string ext : {".tum", ".cov.csv"}) {
        const fs::path live_file = tmp.path() / "live" / "trajectories" / "base" / (name + ext);
        const fs::path replayed = tmp.path() / "replayed" / "trajectories" / "base" / (name + ext);
        ASSERT_TRUE(fs::exists(live_file) && fs::exists(replayed)) << name << ext;
        EXPECT_EQ(testing::ReadFile(live_file), testing::ReadFile(replayed)) << name << ext;
      }
    }
    const double fk = s["estimators"]["fk"]["metrics"]["pos_err_mean_m"].get<double>();
    const double ekf = s["estimators"]["ppoe_ekf"]["metrics"]["pos_err_mean_m"].get<double>();
    std::printf("%s: %d tag detections; mean position error fk %.2f mm, ppoe_ekf %.2f mm\n",
                images ? "images" : "tags.csv", s["metrics"]["streams"]["tags"]["rows"].get<int>(),
                1e3 * fk, 1e3 * ekf);
    EXPECT_LT(ekf, fk);
  }
}

// `scenario` (scenarios/, its gates dropped, `edit` replaced by `with`) run with --export-log,
// then its log replayed with the scenario's estimators and seed: every estimate and covariance
// of `estimators` (the live ones under trajectories/`frame`/`live_dir`) bit for bit. Returns
// the log's log.yaml.
std::string ExpectReplayedBitForBit(const std::string& scenario, const std::string& edit,
                                    const std::string& with, const std::string& live_dir,
                                    const std::vector<std::string>& estimators,
                                    const std::string& frame = "base") {
  testing::TempDir tmp;
  std::string yaml = testing::ReadFile(testing::SourceDir() + "/scenarios/" + scenario);
  for (size_t at; (at = yaml.find("../models/")) != std::string::npos;) {
    yaml.replace(at, 10, testing::SourceDir() + "/models/");
  }
  yaml = yaml.substr(0, yaml.find("gates:"));
  if (!edit.empty()) {
    EXPECT_NE(yaml.find(edit), std::string::npos) << edit;
    if (yaml.find(edit) != std::string::npos) yaml.replace(yaml.find(edit), edit.size(), with);
  }
  testing::WriteFile(tmp.path() / "live.yaml", yaml);
  const CommandResult live =
      RunCommand(testing::Flexbench() + " run " + (tmp.path() / "live.yaml").string() + " --out " +
                 (tmp.path() / "live").string() + " --export-log " + (tmp.path() / "log").string() +
                 " --quiet");
  EXPECT_EQ(live.exit_code, 0) << live.err;
  const size_t seed = yaml.find("\nseed: ");
  EXPECT_NE(seed, std::string::npos) << scenario << " names no seed";
  if (seed == std::string::npos) return "";
  const std::string seed_line = yaml.substr(seed + 1, yaml.find('\n', seed + 1) - seed);
  // The scenario's estimators block runs to the end of the file or to a comment line.
  std::string block = yaml.substr(yaml.find("\nestimators:") + 1);
  block = block.substr(
      0, block.find("\n#") == std::string::npos ? block.size() : block.find("\n#") + 1);
  testing::WriteFile(tmp.path() / "replay.yaml", "scenario: replayed\nkind: replay\n" + seed_line +
                                                     "log: " + (tmp.path() / "log").string() +
                                                     "\n" + block);
  const CommandResult replay =
      RunCommand(testing::Flexbench() + " run " + (tmp.path() / "replay.yaml").string() +
                 " --out " + (tmp.path() / "replayed").string() + " --quiet");
  EXPECT_EQ(replay.exit_code, 0) << replay.err;
  for (const std::string& name : estimators) {
    for (const std::string ext : {".tum", ".cov.csv"}) {
      const fs::path live_file =
          tmp.path() / "live" / "trajectories" / frame / live_dir / (name + ext);
      const fs::path replayed = tmp.path() / "replayed" / "trajectories" / frame / (name + ext);
      EXPECT_TRUE(fs::exists(live_file) && fs::exists(replayed)) << name << ext;
      if (fs::exists(live_file) && fs::exists(replayed)) {
        EXPECT_EQ(testing::ReadFile(live_file), testing::ReadFile(replayed)) << name << ext;
      }
    }
  }
  return testing::ReadFile(tmp.path() / "log" / "log.yaml");
}

// closed_loop_estimators' tracking with the declared model (rendered tags, libapriltag's tag
// centres fused with noisy encoders by fk, two EKFs and a particle filter). The log says what
// the replay needs: the encoders' noise (joints.std_rad), the detector's centres (uc_px,
// vc_px) and that the centre is what is fused (tags.measurement: centre).
TEST(Replay, AnExportedClosedLoopEstimatorsRunReplaysToTheSameBits) {
  const std::string log_yaml =
      ExpectReplayedBitForBit("closed_loop_estimators.yaml", "  steps: 30\n", "  steps: 10\n",
                              "before", {"fk", "naive_ekf", "ppoe_ekf", "pf_encoders"});
  EXPECT_NE(log_yaml.find("measurement: centre"), std::string::npos);
  EXPECT_NE(log_yaml.find("std_rad: "), std::string::npos);
}

// tag_fusion's configurations (Table I's rover): each a static posture estimated afresh, which
// the log says (static_postures: true).
TEST(Replay, AnExportedTagFusionRunReplaysToTheSameBits) {
  const std::string log_yaml = ExpectReplayedBitForBit("rover_apriltag_exp1.yaml", "", "", "",
                                                       {"fk", "ppoe_ekf", "naive_ekf"});
  EXPECT_NE(log_yaml.find("static_postures: true"), std::string::npos);
  EXPECT_NE(log_yaml.find("measurement: centre"), std::string::npos);
}

// jsk_sim_deflection's synthetic run ([PF eq. 31]): its orientation sensors and end-effector
// tracker are the log's orientations.csv and positions.csv; every particle filter, bootstrap and
// conjugate, replays bit for bit.
TEST(Replay, AnExportedSyntheticRunReplaysToTheSameBits) {
  const std::string log_yaml = ExpectReplayedBitForBit(
      "jsk_sim_deflection.yaml", "", "", "",
      {"pf_encoders", "pf_encoders_ee", "pf_encoders_imu", "pf_all", "pf_encoders_bootstrap",
       "pf_encoders_ee_bootstrap", "pf_encoders_imu_bootstrap", "pf_all_bootstrap"});
  EXPECT_NE(log_yaml.find("orientations: {file: orientations.csv}"), std::string::npos);
  EXPECT_NE(log_yaml.find("positions: {file: positions.csv}"), std::string::npos);
}

// contact_fusion (the PPOE paper's Fig. 5 on the humanoid): a fingertip's contacts with a table
// known within per-axis standard deviations, estimated in the head camera's frame. The log holds
// the posture once per iteration (static postures), the contact sensor's running mean with its
// standard error, the table (contacts.planes with `std: [6]`) and `estimate_in: head_camera`.
TEST(Replay, AnExportedContactFusionRunReplaysToTheSameBits) {
  const std::string log_yaml = ExpectReplayedBitForBit(
      "humanoid_table_contact.yaml", "", "", "", {"fk", "ppoe_ekf", "naive_ekf"}, "head_camera");
  EXPECT_NE(log_yaml.find("estimate_in: head_camera"), std::string::npos);
  EXPECT_NE(log_yaml.find("static_postures: true"), std::string::npos);
}

// Rows of a trajectory file (TUM, or a covariance CSV) by their first field, the time.
std::map<std::string, std::string> RowsByTime(const fs::path& file) {
  std::map<std::string, std::string> rows;
  std::istringstream in(testing::ReadFile(file));
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#' || line.rfind("timestamp", 0) == 0) continue;
    const size_t cut = line.find_first_of(" ,");
    rows[line.substr(0, cut)] = line.substr(cut + 1);
  }
  return rows;
}

// mismatch_matrix: each effect column's log (DIR/<column>), its configurations postures of 20
// readings at rest (postures.csv: the estimators start afresh at each) with the tracked end
// effector (positions.csv). Replayed (the kind's estimators are seeded 1), each configuration's
// last step gives the live estimate and covariance, bit for bit.
TEST(Replay, AnExportedMismatchMatrixReplaysEachConfigurationToTheSameBits) {
  testing::TempDir tmp;
  std::string yaml = testing::ReadFile(testing::SourceDir() + "/scenarios/mismatch_matrix.yaml");
  for (size_t at; (at = yaml.find("../models/")) != std::string::npos;) {
    yaml.replace(at, 10, testing::SourceDir() + "/models/");
  }
  yaml = yaml.substr(0, yaml.find("gates:"));
  const std::string count = "configurations: 30\n";
  ASSERT_NE(yaml.find(count), std::string::npos);
  yaml.replace(yaml.find(count), count.size(), "configurations: 4\n");
  testing::WriteFile(tmp.path() / "live.yaml", yaml);
  const CommandResult live =
      RunCommand(testing::Flexbench() + " run " + (tmp.path() / "live.yaml").string() + " --out " +
                 (tmp.path() / "live").string() + " --export-log " + (tmp.path() / "log").string() +
                 " --quiet");
  ASSERT_EQ(live.exit_code, 0) << live.err;
  std::string block = yaml.substr(yaml.find("\nestimators:") + 1);
  for (size_t at; (at = block.find("\n  #")) != std::string::npos;) {
    block.erase(at + 1, block.find('\n', at + 1) - at);  // comment lines inside the block
  }
  for (const std::string column : {"none", "joint_offset"}) {
    const fs::path log = tmp.path() / "log" / column;
    EXPECT_NE(testing::ReadFile(log / "log.yaml").find("postures: {file: postures.csv}"),
              std::string::npos);
    testing::WriteFile(
        tmp.path() / "replay.yaml",
        "scenario: replayed\nkind: replay\nseed: 1\nlog: " + log.string() + "\n" + block);
    const fs::path out = tmp.path() / ("replayed_" + column);
    const CommandResult replay =
        RunCommand(testing::Flexbench() + " run " + (tmp.path() / "replay.yaml").string() +
                   " --out " + out.string() + " --quiet");
    ASSERT_EQ(replay.exit_code, 0) << replay.err;
    for (const std::string name : {"fk", "naive_ekf", "ppoe_ekf", "pf_encoders_ee"}) {
      for (const std::string ext : {".tum", ".cov.csv"}) {
        const auto live_rows =
            RowsByTime(tmp.path() / "live" / "trajectories" / "base" / column / (name + ext));
        const auto replayed = RowsByTime(out / "trajectories" / "base" / (name + ext));
        ASSERT_EQ(live_rows.size(), 4u) << column << " " << name << ext;
        for (const auto& [config, row] : live_rows) {
          const std::string last_step = std::to_string(std::stoi(config) * 20 + 19);
          ASSERT_TRUE(replayed.count(last_step)) << column << " " << name << ext << " " << config;
          EXPECT_EQ(replayed.at(last_step), row) << column << " " << name << ext << " " << config;
        }
      }
    }
  }
}

// A log of static postures is replayed a posture a step: a step rate is refused, in one line.
TEST(Replay, AStepRateOnStaticPosturesIsRefused) {
  testing::TempDir tmp;
  testing::JskLogOptions o;
  o.duration = 1.0;
  testing::WriteJskLog(tmp.path() / "log", o);
  std::ofstream(tmp.path() / "log" / "log.yaml", std::ios::app) << "static_postures: true\n";
  const CommandResult r =
      RunCommand(testing::Flexbench() + " replay " + (tmp.path() / "log").string() +
                 " --estimators fk --step-hz 10 --quiet --out " + (tmp.path() / "out").string());
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("a log of postures (static_postures, postures.csv) is replayed a joint "
                       "row a step"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find('\n'), r.err.size() - 1) << r.err;
}

// `flexbench replay LOG`: the same run from the command line; a bad option is one line naming
// it; the log folder is never an output, even with --force.
TEST(Replay, TheCommandRunsALogAndNeverReplacesIt) {
  testing::TempDir tmp;
  const fs::path log = tmp.path() / "log";
  testing::JskLogOptions o;
  o.duration = 2.0;
  testing::WriteJskLog(log, o);
  const std::string fb = testing::Flexbench() + " replay " + log.string();
  const CommandResult r = RunCommand(fb + " --estimators fk,direct_fusion_yxz --step-hz 10 --out " +
                                     (tmp.path() / "out").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json s =
      nlohmann::json::parse(testing::ReadFile(tmp.path() / "out" / "summary.json"));
  EXPECT_EQ(s["metrics"]["steps"], 21);
  EXPECT_LT(s["estimators"]["direct_fusion_yxz"]["metrics"]["pos_err_mean_m"].get<double>(), 0.003);
  const CommandResult bad =
      RunCommand(fb + " --estimators fk,nope --out " + (tmp.path() / "bad").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(std::count(bad.err.begin(), bad.err.end(), '\n'), 1) << bad.err;
  EXPECT_NE(bad.err.find("--estimators: unknown estimator 'nope'"), std::string::npos) << bad.err;
  const std::string joints = testing::ReadFile(log / "joints.csv");
  const CommandResult onto = RunCommand(fb + " --out " + log.string() + " --force");
  EXPECT_EQ(onto.exit_code, 2) << onto.err;
  EXPECT_EQ(testing::ReadFile(log / "joints.csv"), joints);
  EXPECT_TRUE(fs::exists(log / "log.yaml"));
}

// A simulated run written as a log (--export-log) and replayed gives every estimator's
// trajectory and covariances bit for bit: the raw IMU readings, the encoder rows, the steps, the
// IMUs' initial orientations and their filters' gain (not the default here) all cross the files
// exactly.
TEST(Replay, AnExportedRunReplaysToTheSameBits) {
  testing::TempDir tmp;
  const std::string scenario = testing::SourceDir() + "/scenarios/jsk_flexible_arm.yaml";
  const CommandResult live = RunCommand(
      testing::Flexbench() + " run " + scenario + " --out " + (tmp.path() / "live").string() +
      " --export-log " + (tmp.path() / "log").string() + " --quiet --set madgwick.beta=0.2");
  ASSERT_EQ(live.exit_code, 0) << live.err;
  testing::WriteFile(tmp.path() / "replay.yaml",
                     "scenario: replayed\nkind: replay\nseed: 3\nlog: log\nestimators:\n"
                     "  fk: {}\n  pf_encoders: {conjugate_proposal: 1}\n"
                     "  pf_encoders_imu: {conjugate_proposal: 1}\n"
                     "  pf_encoders_bootstrap: {estimator: pf_encoders}\n"
                     "  pf_encoders_imu_bootstrap: {estimator: pf_encoders_imu}\n"
                     "  pf_encoders_imu_laplace256: {estimator: pf_encoders_imu, "
                     "laplace_proposal: 1, particles: 256}\n");
  ASSERT_EQ(RunReplay(tmp.path() / "replay.yaml", tmp.path() / "replayed").exit_code, 0);
  int compared = 0;
  for (const auto& e : fs::directory_iterator(tmp.path() / "live" / "trajectories" / "base")) {
    const std::string name = e.path().filename().string();
    if (name == "truth.tum") continue;  // read back through a quaternion: the last digit moves
    const fs::path replayed = tmp.path() / "replayed" / "trajectories" / "base" / name;
    ASSERT_TRUE(fs::exists(replayed)) << name;
    EXPECT_EQ(testing::ReadFile(e.path()), testing::ReadFile(replayed)) << name;
    ++compared;
  }
  EXPECT_EQ(compared, 12);  // six estimators, their TUM and covariance files
  // A kind without readings to export, and a folder that exists, are refused before any work.
  const CommandResult smoke = RunCommand(
      testing::Flexbench() + " run " + testing::SourceDir() + "/scenarios/smoke.yaml --out " +
      (tmp.path() / "s").string() + " --export-log " + (tmp.path() / "slog").string());
  EXPECT_EQ(smoke.exit_code, 2);
  EXPECT_NE(smoke.err.find("does not export its readings"), std::string::npos) << smoke.err;
  const std::string joints = testing::ReadFile(tmp.path() / "log" / "joints.csv");
  const CommandResult again = RunCommand(testing::Flexbench() + " run " + scenario + " --out " +
                                         (tmp.path() / "live2").string() + " --export-log " +
                                         (tmp.path() / "log").string());
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_NE(again.err.find("exists"), std::string::npos) << again.err;
  EXPECT_EQ(testing::ReadFile(tmp.path() / "log" / "joints.csv"), joints);
  EXPECT_FALSE(fs::exists(tmp.path() / "live2"));
  // Nor may the log go inside the output folder (which a run replaces), or hold it.
  for (const std::string& log :
       {(tmp.path() / "o3" / "log").string(), tmp.path().string() + "/o4/"}) {
    const std::string out = log.back() == '/' ? log + "out" : (tmp.path() / "o3").string();
    const CommandResult inside = RunCommand(testing::Flexbench() + " run " + scenario + " --out " +
                                            out + " --export-log " + log);
    EXPECT_EQ(inside.exit_code, 2) << inside.err;
    EXPECT_NE(inside.err.find("name a folder of its own"), std::string::npos) << inside.err;
  }
}

// An IMU clock 37 ms ahead of the encoders' is found from the data (the gyros' angular speed
// against the encoders' through the kinematics) within its reported standard error and 2 ms,
// and the replay with it aligned reads the pitch angles off the IMUs as well as with none; a
// log without offset gives one near 0.
TEST(Replay, AnImuClockOffsetIsEstimatedFromTheData) {
  for (const double offset : {0.037, 0.0}) {
    testing::TempDir tmp;
    testing::JskLogOptions o;
    o.duration = 20.0;
    o.imu_clock_s = offset;
    testing::WriteJskLog(tmp.path() / "log", o);
    const std::string fb = testing::Flexbench() + " replay " + (tmp.path() / "log").string() +
                           " --estimators direct_fusion_yxz --step-hz 10 --quiet";
    ASSERT_EQ(
        RunCommand(fb + " --estimate-imu-clock-offset --out " + (tmp.path() / "aligned").string())
            .exit_code,
        0);
    ASSERT_EQ(RunCommand(fb + " --out " + (tmp.path() / "raw").string()).exit_code, 0);
    const auto summary = [&](const char* name) {
      return nlohmann::json::parse(testing::ReadFile(tmp.path() / name / "summary.json"));
    };
    const nlohmann::json aligned = summary("aligned"), raw = summary("raw");
    const double est = aligned["metrics"]["imu_clock_offset_s"].get<double>();
    const double sd = aligned["metrics"]["imu_clock_offset_std_s"].get<double>();
    const auto err = [](const nlohmann::json& s) {
      return s["estimators"]["direct_fusion_yxz"]["metrics"]["pos_err_mean_m"].get<double>();
    };
    std::printf(
        "IMU clock %+.3f s: estimated %+.4f +- %.4f s (correlation %.3f); direct fusion "
        "%.2f mm aligned, %.2f mm not\n",
        offset, est, sd, aligned["metrics"]["imu_clock_offset_correlation"].get<double>(),
        1e3 * err(aligned), 1e3 * err(raw));
    EXPECT_NEAR(est, -offset, 0.002);
    EXPECT_LT(std::abs(est + offset), 3.0 * sd + 5e-4);
    EXPECT_LT(err(aligned), 0.003);
    if (offset > 0.0) {
      EXPECT_LT(err(aligned), err(raw));
    }
    // An offset beyond the range searched is said, never cut to the range's edge.
    if (offset > 0.0) {
      const CommandResult narrow =
          RunCommand(fb + " --estimate-imu-clock-offset --set clock_offset_range_s=0.02 --out " +
                     (tmp.path() / "narrow").string());
      EXPECT_EQ(narrow.exit_code, 2);
      EXPECT_NE(narrow.err.find("at the edge of the searched +-0.02 s"), std::string::npos)
          << narrow.err;
    }
  }
}

}  // namespace
}  // namespace flexbench
