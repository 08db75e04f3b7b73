// scripts/run_all.sh in its default summary mode: one line per scenario (name, gates passed of
// total, time, folder), the run's own output in the folder's log.txt, then the table of
// `flexbench summary`.
#include <gtest/gtest.h>

#include <regex>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

std::string RunAll(const std::string& args) {
  return "cd " + SourceDir() + " && FLEXBENCH_BIN=" + Flexbench() + " bash scripts/run_all.sh " +
         args;
}

TEST(RunAll, SummaryModePrintsOneLinePerScenarioAndKeepsTheLogInTheFolder) {
  TempDir tmp;
  const fs::path out = tmp.path() / "results";
  const CommandResult r = RunCommand(RunAll("--no-build --only smoke " + out.string()));
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::regex line("(^|\\n)smoke +gates 2/2 +[0-9]+ s +" + out.string() + "/smoke\\n");
  EXPECT_TRUE(std::regex_search(r.out, line)) << r.out;
  EXPECT_NE(r.out.find("scenario  gates  headline"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("corner_rmse"), std::string::npos) << r.out;
  // The runner's own lines are in the log, not on the console.
  EXPECT_EQ(r.out.find("[flexbench]"), std::string::npos) << r.out;
  EXPECT_NE(ReadFile(out / "smoke" / "log.txt").find("[flexbench] scenario smoke"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(out / ".smoke.log.tmp"));
}

TEST(RunAll, VerboseModeShowsTheRunnersOwnLines) {
  TempDir tmp;
  const CommandResult r =
      RunCommand(RunAll("--verbose --no-build --only smoke " + (tmp.path() / "r").string()));
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("[flexbench] scenario smoke"), std::string::npos);
}

TEST(RunAll, AnUnknownOptionIsRefusedWithExitTwo) {
  const CommandResult r = RunCommand(RunAll("--sumary"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--sumary"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace flexbench::testing
