// Hostile command lines: a value the CLI would wrap or silently drop, a --set that bypasses an
// option's checks, and a calibration that is far off its stated noise. Each ends with exit 2 and
// one line naming the option, or with a warning and the verdict "unexplained".
#include <gtest/gtest.h>

#include <cstdio>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "tests/common/planar_rows.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

CommandResult RunSmoke(const TempDir& tmp, const std::string& args) {
  return RunCommand(Flexbench() + " run " + SourceDir() + "/scenarios/smoke.yaml --out " +
                    (tmp.path() / "out").string() + " " + args + " </dev/null");
}

TEST(CliReliability, SeedOutsideTheFilesRangeIsRefusedNotWrapped) {
  TempDir tmp;
  for (const char* seed :
       {"-1", "18446744073709551616", "18446744073709551615", "2147483648", "1e3", "", "+3"}) {
    const CommandResult r = RunSmoke(tmp, std::string("--seed '") + seed + "'");
    EXPECT_EQ(r.exit_code, 2) << seed << ": " << r.err;
    EXPECT_NE(LastLine(r.err).find("--seed '" + std::string(seed) +
                                   "': expected a whole number from 0 to 2147483647"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "out"));
  }
}

TEST(CliReliability, AnUnknownCommandIsNamed) {
  const CommandResult r = RunCommand(Flexbench() + " frobnicate </dev/null");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(LastLine(r.err).find("unknown command 'frobnicate' (expected one of: run, "),
            std::string::npos)
      << r.err;
}

TEST(CliReliability, SetWithoutAValueOrWithInvalidUtf8IsRefused) {
  TempDir tmp;
  for (const char* set : {"configuration.joint1=", "configuration.joint1=null",
                          "configuration.joint1='~'", "camera="}) {
    const CommandResult r = RunSmoke(tmp, std::string("--set ") + set);
    EXPECT_EQ(r.exit_code, 2) << set << ": " << r.err;
    const std::string key = std::string(set).substr(0, std::string(set).find('='));
    EXPECT_NE(LastLine(r.err).find("--set " + key + ": no value"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "out"));
  }
  const CommandResult r = RunSmoke(tmp, "--set \"description=caf$(printf '\\351')\"");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("--set description: the value is not valid UTF-8 (byte 0xE9)"),
            std::string::npos)
      << r.err;
}

class IdentifyReliability : public ::testing::Test {
 protected:
  void SetUp() override {
    std::mt19937_64 rng(5);
    cal_ = kPlanarHeader + PlanarRows(60, rng);
    WriteFile(tmp_.path() / "cal.csv", cal_);
    WriteFile(tmp_.path() / "val.csv", kPlanarHeader + PlanarRows(40, rng));
  }
  CommandResult Identify(const std::string& cal, const std::string& extra) {
    return RunCommand(Flexbench() + " identify --declared " + SourceDir() +
                      "/models/planar3.declared.yaml --calibration " +
                      (tmp_.path() / cal).string() + " --validation " +
                      (tmp_.path() / "val.csv").string() + " --out " +
                      (tmp_.path() / "out").string() + " " + extra + " </dev/null");
  }
  TempDir tmp_;
  std::string cal_;
};

// The options own the files and the model: a --set of them would be ignored or bypass the
// checks the option makes (validation rows the same as the calibration rows).
TEST_F(IdentifyReliability, SetOfAKeyAnOptionOwnsIsRefused) {
  CommandResult r = Identify("cal.csv", "--set model=" + SourceDir() + "/models/rover_arm.xml");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("--set model: identify sets 'model' from its options; use "
                                 "--model"),
            std::string::npos)
      << r.err;
  r = Identify("cal.csv", "--set validation.csv=" + (tmp_.path() / "cal.csv").string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("--set validation.csv: identify sets 'validation'"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(tmp_.path() / "out"));
}

// A scenario file is held to the same rule as --validation: the same rows twice (a copy under
// another name) give no held-out error.
TEST_F(IdentifyReliability, ScenarioWithTheSameRowsTwiceIsRefused) {
  WriteFile(tmp_.path() / "copy.csv", cal_);
  const fs::path s = tmp_.path() / "cl.yaml";
  WriteFile(s, "scenario: cl\nkind: closed_loop\nseed: 1\nmodel: " + SourceDir() +
                   "/models/planar3.xml\ndeclared: " + SourceDir() +
                   "/models/planar3.declared.yaml\ncalibration: {csv: cal.csv}\n"
                   "validation: {csv: copy.csv}\n");
  const CommandResult r = RunCommand(Flexbench() + " run " + s.string() + " --out " +
                                     (tmp_.path() / "out").string() + " </dev/null");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find(
                "cl.yaml:7: key 'validation.csv': " + (tmp_.path() / "copy.csv").string() +
                " holds the same rows as the calibration file"),
            std::string::npos)
      << r.err;
}

// 25 identical rows at 500 m among 85 put the upper quartile among the outliers, so the IQR rule
// rejects none: the run must not end quietly with a calibration error far above the noise.
TEST_F(IdentifyReliability, ErrorFarAboveTheStatedNoiseIsNeverQuiet) {
  std::string bad = cal_;
  for (int i = 0; i < 25; ++i) bad += "0.1,0.2,0.3,500,0,0\n";
  WriteFile(tmp_.path() / "bad.csv", bad);
  CommandResult r = Identify("bad.csv", "--candidates joint_offset --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("warning: the calibration residual is"), std::string::npos) << r.err;
  auto m = nlohmann::json::parse(ReadFile(tmp_.path() / "out" / "summary.json"))["metrics"];
  EXPECT_EQ(m["verdict"], "unexplained");
  EXPECT_GT(m["cal_residual_noise_ratio"].get<double>(), 100.0);
  // The clean rows: no warning, a ratio near 1.
  r = Identify("cal.csv", "--candidates joint_offset --quiet --force");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("warning"), std::string::npos) << r.err;
  m = nlohmann::json::parse(ReadFile(tmp_.path() / "out" / "summary.json"))["metrics"];
  EXPECT_LT(m["cal_residual_noise_ratio"].get<double>(), 3.0);
}

TEST_F(IdentifyReliability, OneRowSaysRowsOnce) {
  WriteFile(
      tmp_.path() / "one.csv",
      "joint1,joint2,joint3,x,y,z\n" +
          cal_.substr(cal_.find('\n') + 1, cal_.find('\n', cal_.find('\n') + 1) - cal_.find('\n')));
  const CommandResult r = Identify("one.csv", "--folds-by row");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("cross-validation by row needs at least two rows; the data has 1"),
            std::string::npos)
      << r.err;
}

// The command's options go into the run's set-up directly: each is held to what the scenario key
// it sets is held to, and a --set of a key is read over the options, not instead of them.
TEST_F(IdentifyReliability, OptionsAreCheckedAsTheirKeysAndSetKeysReadOverThem) {
  struct Case {
    std::string extra, message;
  };
  const std::vector<Case> refused = {
      {"--frame base", "--frame: a frame name is letters, digits, '_' or '-' (and not 'base')"},
      {"--set seed=-1", "key 'seed': seed must be >= 0"},
      {"--set scenario=a/b", "key 'scenario': must be a plain name"},
      {"--max-effects -1", "--max-effects: must be >= 0 (leave it out for no cap)"},
      {"--set max_effects=-1", "--set max_effects: key 'max_effects': must be >= 0"},
      // Both frames stay (no row names either): the keyed one does not replace the other.
      {"--frame a --frame b --set frames.b.T_base_frame=[0,0,0,1,0,0,0]",
       "frame 'a' is declared but no calibration row is measured in it"}};
  for (const Case& c : refused) {
    const CommandResult r = Identify("cal.csv", c.extra);
    EXPECT_EQ(r.exit_code, 2) << c.extra << "\n" << r.err;
    EXPECT_NE(LastLine(r.err).find(c.message), std::string::npos) << c.extra << "\n" << r.err;
  }
  // A candidate named twice is one candidate, as in a scenario's `candidates`.
  const CommandResult r =
      Identify("cal.csv", "--candidates joint_offset --candidates joint_offset --quiet");
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

}  // namespace
}  // namespace flexbench::testing
