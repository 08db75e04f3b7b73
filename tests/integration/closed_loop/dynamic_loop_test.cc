// The dynamic closed loop closes: the augmented model closed_loop_dynamic writes from a log
// (MuJoCo physics whose links bend, the declared model rigid) carries the modes into its MJCF;
// identifying again from the same log, as a user's log (`log:`), with the augmented model as the
// declared one finds nothing left to add (verdict no_effect); and with a declared file that holds
// the static identification's bend of a link (link_bending, as closed_loop writes it) the
// identification starts from that link's mode, ends where it ended cold, with fewer rollouts,
// and the augmented model carries the mode in the static bend's place.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

// `flexbench run ARGS --out DIR/NAME`; its summary (null when the run failed).
Json RunScenario(const fs::path& dir, const std::string& args, const std::string& name) {
  const testing::CommandResult r = testing::RunCommand(testing::Flexbench() + " run " + args +
                                                       " --quiet --out " + (dir / name).string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  if (r.exit_code != 0) return Json();
  return Json::parse(testing::ReadFile(dir / name / "summary.json"));
}

// A scenario identifying from the first run's log with `declared`.
Json FromLog(const fs::path& dir, const std::string& declared, const std::string& name) {
  testing::WriteFile(
      dir / (name + ".yaml"),
      "scenario: " + name + "\ndescription: the first run's log\n" +
          "kind: closed_loop_dynamic\nseed: 1\nlog: " + (dir / "first" / "log").string() +
          "\ndeclared: " + declared + "\nidentify: {threads: 2}\n");
  return RunScenario(dir, (dir / (name + ".yaml")).string(), name);
}

double Value(const Json& s, const std::string& effect, const char* key) {
  for (const Json& c : s["dynamic_identification"]["chosen"]) {
    if (c["name"] == effect) return c["values"][key];
  }
  return NAN;
}

// One test: ctest runs each test in a process of its own, and every part needs the first run.
TEST(DynamicLoop, ExportsClosesAndStartsFromAStaticBend) {
  const fs::path dir =
      fs::temp_directory_path() / ("flexbench_dynloop_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const Json first =
      RunScenario(dir,
                  testing::SourceDir() +
                      "/scenarios/closed_loop_dynamic_link_mode.yaml --set truth.duration_s=8",
                  "first");
  ASSERT_FALSE(first.is_null());
  ASSERT_EQ(first["metrics"]["verdict"], "explained") << first["dynamic_identification"]["log"];

  // The exported MJCF holds the fitted modes, released: no longer an undeclared effect's joints.
  const double s2 = Value(first, "link_mode@link2_b", "stiffness_scale");
  ASSERT_GT(s2, 0.9);
  sim::MjModelPtr m = sim::LoadModel((dir / "first" / "calibrated_model.xml").string());
  const int j = mj_name2id(m.get(), mjOBJ_JOINT, "link2_bend_y");
  ASSERT_GE(j, 0);
  EXPECT_DOUBLE_EQ(m->jnt_stiffness[j], 220.0 * s2);
  EXPECT_EQ(testing::ReadFile(dir / "first" / "calibrated_model.xml").find("effect:link_bending"),
            std::string::npos);

  // The same log with the augmented model: nothing left to add, the held-out error where the
  // first fit ended (its segment starts refined; these are not: a little above).
  const Json again = FromLog(dir, (dir / "first" / "declared_augmented.yaml").string(), "again");
  ASSERT_FALSE(again.is_null());
  EXPECT_EQ(again["metrics"]["verdict"], "no_effect") << again["dynamic_identification"]["log"];
  EXPECT_LT(again["metrics"]["heldout_before"].get<double>(),
            1.1 * first["metrics"]["heldout_after"].get<double>());

  // The bend closed_loop would write for link2 (compliance 1 / (1.1 k), k = 220 N m/rad): the
  // warm start, the same end, fewer rollouts, the mode in the bend's place.
  std::string declared = testing::ReadFile(testing::SourceDir() + "/models/jsk_arm.declared.yaml");
  declared.replace(declared.find("model: jsk_arm.xml"), 18,
                   "model: " + testing::SourceDir() + "/models/jsk_arm.xml");
  declared += "identified_effects:\n  - {effect: link_bending@link3_pitch_joint, value: [" +
              std::to_string(1.0 / (1.1 * 220.0)) + "], unit: rad/Nm}\n";
  testing::WriteFile(dir / "static.yaml", declared);
  const Json warm = FromLog(dir, (dir / "static.yaml").string(), "warm");
  ASSERT_FALSE(warm.is_null());
  const std::string log = warm["dynamic_identification"]["log"].dump();
  EXPECT_NE(log.find("warm start from the declared file's static effects "
                     "(link_bending@link3_pitch_joint -> link_mode@link2_b)"),
            std::string::npos)
      << log;
  EXPECT_EQ(warm["metrics"]["verdict"], "explained") << log;
  for (const char* effect : {"link_mode@link2_b", "link_mode@link3_b"}) {
    EXPECT_NEAR(Value(warm, effect, "stiffness_scale"), Value(first, effect, "stiffness_scale"),
                1e-6)
        << effect;
  }
  EXPECT_LT(warm["metrics"]["rollouts"].get<int>(), first["metrics"]["rollouts"].get<int>());
  const std::string augmented = testing::ReadFile(dir / "warm" / "declared_augmented.yaml");
  EXPECT_EQ(augmented.find("link_bending@link3_pitch_joint"), std::string::npos) << augmented;
  EXPECT_NE(augmented.find("link_mode@link2_b"), std::string::npos) << augmented;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace flexbench
