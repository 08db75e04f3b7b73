// The dynamic closed loop closes: the augmented model closed_loop_dynamic writes from a log
// (MuJoCo physics with friction and armature the declared model lacks) carries the effects into
// its MJCF, and identifying again from the same log, as a user's log (`log:`), with the
// augmented model as the declared one finds nothing left to add: verdict no_effect.
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

TEST(DynamicLoop, TheAugmentedModelLeavesNothingToFindInTheSameLog) {
  const fs::path dir =
      fs::temp_directory_path() / ("flexbench_dynloop_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const testing::CommandResult first = testing::RunCommand(
      testing::Flexbench() + " run " + testing::SourceDir() +
      "/scenarios/closed_loop_dynamic_friction.yaml --quiet --set truth.duration_s=8 --out " +
      (dir / "first").string());
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const auto a = nlohmann::json::parse(testing::ReadFile(dir / "first" / "summary.json"));
  ASSERT_EQ(a["metrics"]["verdict"], "explained") << a["dynamic_identification"]["log"];
  double friction = 0.0;
  for (const auto& c : a["dynamic_identification"]["chosen"]) {
    if (c["name"] == "joint_friction@link2_pitch_joint") friction = c["values"]["Nm"];
  }
  ASSERT_GT(friction, 0.1);

  // The MJCF carries the fitted friction (the declared MJCF has none at that joint).
  sim::MjModelPtr m = sim::LoadModel((dir / "first" / "calibrated_model.xml").string());
  const int j = mj_name2id(m.get(), mjOBJ_JOINT, "link2_pitch_joint");
  ASSERT_GE(j, 0);
  EXPECT_DOUBLE_EQ(m->dof_frictionloss[m->jnt_dofadr[j]], friction);

  testing::WriteFile(dir / "again.yaml",
                     "scenario: again\ndescription: the same log, the augmented model\n"
                     "kind: closed_loop_dynamic\nseed: 1\nlog: " +
                         (dir / "first" / "log").string() +
                         "\ndeclared: " + (dir / "first" / "declared_augmented.yaml").string() +
                         "\nidentify: {threads: 2}\n");
  const testing::CommandResult again =
      testing::RunCommand(testing::Flexbench() + " run " + (dir / "again.yaml").string() +
                          " --quiet --out " + (dir / "again").string());
  ASSERT_EQ(again.exit_code, 0) << again.err;
  const auto b = nlohmann::json::parse(testing::ReadFile(dir / "again" / "summary.json"));
  EXPECT_EQ(b["metrics"]["verdict"], "no_effect") << b["dynamic_identification"]["log"];
  // Where the first fit ended (its segment starts refined; these are not: a little above).
  EXPECT_LT(b["metrics"]["heldout_before"].get<double>(),
            1.1 * a["metrics"]["heldout_after"].get<double>());
  EXPECT_LT(b["metrics"]["heldout_before"].get<double>(),
            0.5 * a["metrics"]["heldout_before"].get<double>());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace flexbench
