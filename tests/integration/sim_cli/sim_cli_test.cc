// The truth side through the flexbench binary: `inspect`, the rover_deflection scenario's
// determinism, and bad input (unknown effect or sensor, declared file naming a missing joint or
// frame, MJCF errors): exit 2 with one line naming the file and the cause.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <set>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string Model(const std::string& name) { return SourceDir() + "/models/" + name; }

void ExpectBadInput(const std::string& command, const std::string& must_contain) {
  const CommandResult r = RunCommand(command);
  EXPECT_EQ(r.exit_code, 2) << command << "\n" << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(must_contain), std::string::npos) << r.err;
}

// A short rover_deflection scenario (no rendering) with `extra` appended.
std::string Scenario(const std::string& model, const std::string& extra) {
  return "scenario: rd\nkind: rover_deflection\nseed: 5\nmodel: " + model +
         "\neffects:\n  base_compliance: {}\n"
         "sweep:\n  directions_deg: [0, 90]\n  steps: 3\n"
         "  folded_deg: {j2: 0, j3: 150, j5: -90}\n  outstretched_deg: {j2: 90, j3: 0, j5: -30}\n"
         "sensors:\n  - {name: enc, kind: encoder, side: link, noise_std_deg: 0.01}\n" +
         extra;
}

TEST(Inspect, RoverModelAsJson) {
  const CommandResult r = RunCommand(Flexbench() + " inspect " + Model("rover_arm.xml"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["name"], "rover_arm");
  EXPECT_EQ(j["actuated_joints"].size(), 8u);
  std::map<std::string, std::string> passive;
  for (const Json& p : j["passive_joints"]) passive[p["name"]] = p["effect"];
  // Labelled with the effect's name, as the MJCF tags them (effect:base_compliance).
  EXPECT_EQ(passive["plate_pitch"], "base_compliance");
  EXPECT_EQ(passive["plate_roll"], "base_compliance");
  EXPECT_EQ(passive["link2_bend_y"], "link_bending");
  EXPECT_EQ(passive["mast_sag"], "camera_mount_sag");
  std::set<int> ids;
  for (const Json& t : j["tags"]) ids.insert(t["id"].get<int>());
  EXPECT_EQ(ids, (std::set<int>{10, 11, 12, 13}));
  bool mast = false;
  for (const Json& c : j["cameras"]) {
    if (c["name"] == "mast_camera") {
      mast = true;
      EXPECT_EQ(c["width_px"], 640);
      EXPECT_EQ(c["height_px"], 480);
    }
  }
  EXPECT_TRUE(mast);
  std::map<std::string, bool> supported;
  for (const Json& e : j["effects"]) supported[e["name"]] = e["supported"];
  EXPECT_TRUE(supported["base_compliance"]);
  EXPECT_TRUE(supported["link_bending"]);
  EXPECT_TRUE(supported["payload"]);
  EXPECT_FALSE(supported["neck_elasticity"]);
  EXPECT_TRUE(supported["transmission_error"]);
  EXPECT_TRUE(supported["stiffening_spring"]);
  EXPECT_FALSE(supported["lateral_compliance"]);  // no J_lateral_a/b hinges
  EXPECT_TRUE(supported["joint_origin"]);
  EXPECT_TRUE(supported["joint_friction"]);
  EXPECT_TRUE(supported["link_mode"]);
  EXPECT_TRUE(supported["base_mode"]);
  EXPECT_EQ(supported.size(), 24u);
  std::map<std::string, std::vector<std::string>> parts;
  for (const Json& e : j["effects"]) {
    if (e.contains("parts")) parts[e["name"]] = e["parts"].get<std::vector<std::string>>();
  }
  EXPECT_EQ(parts["base_compliance"], (std::vector<std::string>{"plate_pitch", "plate_roll"}));
  EXPECT_EQ(parts["link_bending"].size(), 4u);
  EXPECT_EQ(parts["joint_compliance"].size(), 6u);
  EXPECT_EQ(j["sensors"]["encoders"].size(), 8u);
}

TEST(Inspect, DeclaredFileAndOtherModels) {
  const CommandResult r = RunCommand(Flexbench() + " inspect " + Model("jsk_arm.declared.yaml"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json j = Json::parse(r.out);
  EXPECT_EQ(j["declared"]["end_effector"], "grasp_point");
  EXPECT_EQ(j["truth"]["sensors"]["imu_sites"], Json({"imu_link2", "imu_link3"}));
  const CommandResult h = RunCommand(Flexbench() + " inspect " + Model("humanoid_upper.xml"));
  ASSERT_EQ(h.exit_code, 0) << h.err;
  const Json coupled = Json::parse(h.out)["coupled_joints"];
  ASSERT_EQ(coupled.size(), 3u);  // the wrist linkage's two, the torso's one
  EXPECT_EQ(coupled[0]["name"], "torso_pitch_3");
  EXPECT_EQ(coupled[0]["follows"], Json({{"torso_pitch_1", -1.0}, {"torso_pitch_2", -1.0}}));
}

// What closed_loop writes, inspect reads: the format is the reader's (sim/declared_model.h).
TEST(Inspect, AnAugmentedDeclaredFile) {
  TempDir tmp;
  const fs::path p = tmp.path() / "aug.declared.yaml";
  WriteFile(p, "model: " + Model("rover_arm.xml") +
                   "\nactuated_joints: [j1, j2]\nend_effector: ee\n"
                   "sources:\n  - {at: j1, about_axis_deg: 0.5, covariance: [" +
                   std::string("0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, ") +
                   "0, 0, 0, 1e-6, 0, 0, 0, 0, 0, 0, 1e-6, 0, 0, 0, 0, 0, 0, 1e-6]}\n"
                   "identified_effects:\n  - effect: joint_offset@j2\n"
                   "    equivalent: [joint_offset@j2, link_offset@j3]\n"
                   "    value: [0.001]\n    std: [1e-5]\n    unit: rad\n");
  const CommandResult r = RunCommand(Flexbench() + " inspect " + p.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  WriteFile(p, "model: " + Model("rover_arm.xml") +
                   "\nactuated_joints: [j1]\nend_effector: ee\n"
                   "identified_effects:\n  - {effect: joint_offset@j1, value: [.nan]}\n");
  ExpectBadInput(Flexbench() + " inspect " + p.string(), p.string() + ":5");
}

TEST(BadInput, DeclaredFileNamingAMissingJointOrFrame) {
  TempDir tmp;
  const fs::path p = tmp.path() / "x.declared.yaml";
  WriteFile(p, "model: " + Model("rover_arm.xml") +
                   "\nactuated_joints: [j1, j2, elbow]\nend_effector: ee\n");
  ExpectBadInput(Flexbench() + " inspect " + p.string(), p.string() + ":2");
  ExpectBadInput(Flexbench() + " inspect " + p.string(), "no hinge or slide joint named 'elbow'");
  WriteFile(p, "model: " + Model("rover_arm.xml") +
                   "\nactuated_joints: [j1]\nend_effector: ee\nobserved_frames: [tag_ee_back]\n");
  ExpectBadInput(Flexbench() + " inspect " + p.string(), "named 'tag_ee_back'");
}

TEST(BadInput, MjcfErrorNamesTheFile) {
  TempDir tmp;
  const fs::path model = tmp.path() / "broken.xml";
  WriteFile(model,
            "<mujoco><worldbody><body><joint type=\"hinge\" axis=\"0 0 0\"/>"
            "<geom size=\"0.1\"/></body></worldbody></mujoco>");
  ExpectBadInput(Flexbench() + " inspect " + model.string(), model.string());
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, Scenario(model.string(), ""));
  ExpectBadInput(Flexbench() + " run " + s.string() + " --out " + (tmp.path() / "o").string(),
                 "broken.xml");
  EXPECT_FALSE(fs::exists(tmp.path() / "o"));
}

TEST(BadInput, UnknownEffectOrSensorInAScenario) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  std::string text = Scenario(Model("rover_arm.xml"), "");
  text.replace(text.find("base_compliance"), 15, "base_plate_wobble");
  WriteFile(s, text);
  ExpectBadInput(Flexbench() + " run " + s.string() + " --out " + (tmp.path() / "o").string(),
                 s.string() + ":6: unknown effect 'base_plate_wobble'");
  text = Scenario(Model("rover_arm.xml"), "");
  text.replace(text.find("kind: encoder"), 13, "kind: odometer");
  WriteFile(s, text);
  ExpectBadInput(Flexbench() + " run " + s.string() + " --out " + (tmp.path() / "o").string(),
                 "unknown sensor kind 'odometer'");
  // An effect the model cannot carry, and a joint the model lacks.
  text = Scenario(Model("rover_arm.xml"), "");
  text.replace(text.find("base_compliance: {}"), 19, "neck_elasticity: {}");
  WriteFile(s, text);
  ExpectBadInput(Flexbench() + " run " + s.string() + " --out " + (tmp.path() / "o").string(),
                 "no passive joints for effect 'neck_elasticity'");
  text = Scenario(Model("rover_arm.xml"), "");
  text.replace(text.find("j5: -90"), 7, "j7: -90");
  WriteFile(s, text);
  ExpectBadInput(Flexbench() + " run " + s.string() + " --out " + (tmp.path() / "o").string(),
                 "no actuated joint named 'j7'");
  EXPECT_FALSE(fs::exists(tmp.path() / "o"));
}

std::map<std::string, std::string> ReadTree(const fs::path& root) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    if (!e.is_regular_file()) continue;
    std::string text = ReadFile(e.path());
    const std::string rel = fs::relative(e.path(), root).string();
    // The recorded command names --out (summary.json, report.html).
    const std::string out = root.string();
    for (size_t p = text.find(out); p != std::string::npos; p = text.find(out, p + 1)) {
      text.replace(p, out.size(), "OUT");
    }
    if (rel == "summary.json") {
      Json j = Json::parse(text);
      j.erase("timing");
      text = j.dump();
    }
    files[rel] = text;
  }
  return files;
}

TEST(RoverDeflection, SameSeedSameBytes) {
  TempDir tmp;
  const std::string scenario = SourceDir() + "/scenarios/rover_deflection.yaml";
  for (const char* out : {"a", "b"}) {
    const CommandResult r = RunCommand(Flexbench() + " run " + scenario + " --out " +
                                       (tmp.path() / out).string() + " --check-gates");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const auto a = ReadTree(tmp.path() / "a");
  const auto b = ReadTree(tmp.path() / "b");
  EXPECT_EQ(a.size(), b.size());
  EXPECT_GE(a.size(), 32u * 2 + 3);  // per-configuration CSVs, deflection.csv/png, summary
  EXPECT_TRUE(a.count("deflection.png"));
  EXPECT_TRUE(a.count("frames/mast_config_07.png"));
  for (const auto& [name, text] : a) {
    ASSERT_TRUE(b.count(name)) << name;
    EXPECT_TRUE(text == b.at(name)) << name << " differs between two runs with the same seed";
  }
  // Another seed changes the sensor noise, not the truth.
  const CommandResult r = RunCommand(Flexbench() + " run " + scenario + " --seed 8 --out " +
                                     (tmp.path() / "c").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto c = ReadTree(tmp.path() / "c");
  EXPECT_EQ(c.at("deflection.csv"), a.at("deflection.csv"));
  EXPECT_NE(c.at("configs/config_07_sensors.csv"), a.at("configs/config_07_sensors.csv"));
}

}  // namespace
}  // namespace flexbench::testing
