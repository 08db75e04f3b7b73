// "Nothing lost, nothing hangs": the promises of docs/reliability.md through the CLI.
// Exit codes (0 ok, 2 bad input, 3 gate failed, 1 internal), one line on stderr for an error,
// echoed values capped, results moved into place whole, nothing removed that is not a result.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

std::string SmokeYaml(const std::string& extra = "", const std::string& model = "") {
  const std::string model_path = model.empty() ? SourceDir() + "/models/planar3.xml" : model;
  return "scenario: smoke_copy\nkind: smoke\nseed: 3\nmodel: " + model_path +
         "\ncamera: overview\nconfiguration: {joint1: 0.35, joint2: -0.6, joint3: 0.5}\n" + extra;
}

std::string RunCmd(const fs::path& scenario, const fs::path& out, const std::string& extra = "") {
  return Flexbench() + " run " + scenario.string() + " --out " + out.string() + " " + extra +
         " </dev/null";
}

// --set KEY=VALUE on `run`: the value is used and recorded; a wrong path or type is
// bad input naming the override, with nothing written.
TEST(Reliability, SetOverridesAKeyAndIsRecordedOrNamed) {
  const fs::path dir = fs::temp_directory_path() / ("flexbench_set_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const fs::path s = dir / "smoke.yaml";
  WriteFile(s, SmokeYaml());
  CommandResult r = RunCommand(RunCmd(
      s, dir / "ok", "--set seed=11 --set configuration.joint2=-0.5 --set render.mode=fast"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto summary = nlohmann::json::parse(ReadFile(dir / "ok" / "summary.json"));
  EXPECT_EQ(summary["seed"], 11);
  EXPECT_EQ(summary["overrides"],
            (nlohmann::json{"seed=11", "configuration.joint2=-0.5", "render.mode=fast"}));
  // Without overrides the key is absent (same bytes as before for every existing run).
  r = RunCommand(RunCmd(s, dir / "plain"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(
      nlohmann::json::parse(ReadFile(dir / "plain" / "summary.json")).contains("overrides"));
  const std::pair<const char*, const char*> bad[] = {
      {"--set descripton=typo", "--set descripton: unknown key 'descripton'"},
      {"--set seed=abc", "--set seed: key 'seed': expected an integer"},
      {"--set seed.x=1", "--set seed.x: 'seed'"},
      {"--set nonsense", "--set 'nonsense': expected KEY=VALUE"}};
  int k = 0;
  for (const auto& [arg, expected] : bad) {
    const fs::path out = dir / ("bad" + std::to_string(k++));
    r = RunCommand(RunCmd(s, out, arg));
    EXPECT_EQ(r.exit_code, 2) << arg << ": " << r.err;
    EXPECT_NE(LastLine(r.err).find(expected), std::string::npos) << arg << ": " << r.err;
    EXPECT_FALSE(fs::exists(out)) << arg;
  }
  fs::remove_all(dir);
}

// --quiet: a successful run says nothing; without it the run logs what it did.
TEST(Reliability, QuietRunPrintsNothingButErrors) {
  TempDir tmp;
  const fs::path s = tmp.path() / "smoke.yaml";
  WriteFile(s, SmokeYaml());
  CommandResult r = RunCommand(RunCmd(s, tmp.path() / "quiet", "--quiet"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "");
  EXPECT_TRUE(fs::exists(tmp.path() / "quiet" / "summary.json"));
  r = RunCommand(RunCmd(s, tmp.path() / "loud"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("[flexbench] results in"), std::string::npos) << r.err;
  // Bad input still gets its one line.
  r = RunCommand(RunCmd(s, tmp.path() / "bad", "--quiet --set seed=abc"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(LastLine(r.err).find("--set seed"), std::string::npos) << r.err;
}

TEST(Reliability, OutThatHoldsUserFilesIsRefusedAndKept) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  const fs::path out = tmp.path() / "mine";
  WriteFile(out / "thesis.tex", "years of work");
  CommandResult r = RunCommand(RunCmd(s, out));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("not a flexbench result"), std::string::npos) << r.err;
  EXPECT_EQ(ReadFile(out / "thesis.tex"), "years of work");
  // --force is the user's say-so.
  r = RunCommand(RunCmd(s, out, "--force"));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / "summary.json"));
  // A previous result is replaced without --force.
  r = RunCommand(RunCmd(s, out));
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

TEST(Reliability, OutThatHoldsTheScenarioIsRefusedEvenWithForce) {
  TempDir tmp;
  const fs::path s = tmp.path() / "here" / "s.yaml";
  WriteFile(s, SmokeYaml());
  for (const char* extra : {"", "--force"}) {
    const CommandResult r = RunCommand(RunCmd(s, tmp.path() / "here", extra));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_TRUE(fs::exists(s)) << "the scenario file was deleted";
  }
}

TEST(Reliability, OutThatIsARegularFileIsRefusedAndKept) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  const fs::path out = tmp.path() / "notes.txt";
  WriteFile(out, "keep me");
  for (const char* extra : {"", "--force"}) {
    const CommandResult r = RunCommand(RunCmd(s, out, extra));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("is not a folder"), std::string::npos) << r.err;
    EXPECT_EQ(ReadFile(out), "keep me");
  }
}

TEST(Reliability, NonUtf8ScenarioIsBadInputBeforeAnyWork) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml("description: caf\xe9\n"));
  const CommandResult r = RunCommand(RunCmd(s, tmp.path() / "out"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("key 'description': not valid UTF-8"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "out"));
}

TEST(Reliability, DevicesFoldersAndLongNamesAreBadInput) {
  TempDir tmp;
  const std::string long_name = std::string(300, 'a');
  for (const std::string& cmd :
       {Flexbench() + " run /dev/zero", Flexbench() + " run " + tmp.path().string(),
        Flexbench() + " run " + long_name, Flexbench() + " list --dir " + long_name,
        Flexbench() + " inspect " + long_name, Flexbench() + " inspect " + long_name + ".yaml",
        Flexbench() + " identify --model " + long_name + " --declared " + SourceDir() +
            "/models/planar3.declared.yaml --calibration " + long_name + " --validation c",
        Flexbench() + " run " + SourceDir() + "/scenarios/smoke.yaml --out " + long_name}) {
    const CommandResult r = RunCommand("cd " + tmp.path().string() + " && " + cmd + " </dev/null");
    EXPECT_EQ(r.exit_code, 2) << cmd << "\n" << r.err;
    EXPECT_EQ(CountLines(r.err), CountLines(r.err) > 1 ? 2 : 1) << r.err;  // a log line at most
    EXPECT_LT(LastLine(r.err).size(), 400u) << r.err;
  }
}

TEST(Reliability, MujocoFatalErrorsAndBadOffscreenSizesAreBadInputWithoutAPrompt) {
  TempDir tmp;
  std::string xml = ReadFile(SourceDir() + "/models/planar3.xml");
  const std::string from = "offwidth=\"640\" offheight=\"480\"";
  ASSERT_NE(xml.find(from), std::string::npos);
  for (const char* size :
       {"offwidth=\"60000\" offheight=\"60000\"", "offwidth=\"640\" offheight=\"-5\""}) {
    std::string m = xml;
    m.replace(m.find(from), from.size(), size);
    WriteFile(tmp.path() / "m.xml", m);
    WriteFile(tmp.path() / "s.yaml", SmokeYaml("", (tmp.path() / "m.xml").string()));
    const CommandResult r = RunCommand("cd " + tmp.path().string() + " && timeout 120 " +
                                       RunCmd(tmp.path() / "s.yaml", tmp.path() / "out"));
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(LastLine(r.err).find("offwidth"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("Press Enter"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "MUJOCO_LOG.TXT"));
    EXPECT_FALSE(fs::exists(tmp.path() / "out"));
  }
}

TEST(Reliability, MujocoErrorHandlerThrowsOneLineBadInput) {
  sim::InstallMujocoHandlers();
  try {
    mju_error("boom\nsecond line");
    ADD_FAILURE() << "mju_error returned";
  } catch (const sim::MujocoError& e) {
    EXPECT_STREQ(e.what(), "MuJoCo: boom second line");
  }
  ::testing::internal::CaptureStderr();
  mju_warning("careful");
  const std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(err, "[flexbench] MuJoCo warning: careful\n");
}

TEST(Reliability, CheckGatesWithoutGatesAndGateTyposAreBadInput) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  CommandResult r = RunCommand(RunCmd(s, tmp.path() / "out", "--check-gates"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("no gates"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "out"));
  WriteFile(s, SmokeYaml("gates:\n  - {name: typo, metric: corner_rmse_pix, op: '<', "
                         "threshold: 1.0}\n"));
  r = RunCommand(RunCmd(s, tmp.path() / "out", "--check-gates"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find(s.string() + ":8: gate 'typo': metric 'corner_rmse_pix' is "
                                              "not in this scenario's results"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "out"));
}

// Found by mutation testing: a huge detector setting crashed the AprilTag library (rc 139).
TEST(Reliability, AbsurdDetectorSettingsAreBadInput) {
  TempDir tmp;
  for (const char* setting :
       {"decimate: 1.1e300", "decimate: 500", "sigma: 1e300", "threads: 100000"}) {
    const fs::path s = tmp.path() / "s.yaml";
    WriteFile(s, SmokeYaml(std::string("detector:\n  family: tag36h11\n  ") + setting + "\n"));
    const CommandResult r = RunCommand(RunCmd(s, tmp.path() / "out"));
    EXPECT_EQ(r.exit_code, 2) << setting << "\n" << r.err;
    EXPECT_NE(LastLine(r.err).find("detector."), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "out"));
  }
}

TEST(Reliability, ScenarioNameCannotLeaveTheOutputFolder) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  std::string y = SmokeYaml();
  y.replace(y.find("smoke_copy"), 10, "../../escape");
  WriteFile(s, y);
  const CommandResult r =
      RunCommand("cd " + tmp.path().string() + " && " + Flexbench() + " run " + s.string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("key 'scenario': must be a plain name"), std::string::npos) << r.err;
}

// A closed_loop scenario on a user's CSV with an inline declared block.
std::string ClosedLoopYaml(const fs::path& dir, const std::string& declared_model,
                           const std::string& distances) {
  std::string csv = "joint1,joint2,joint3,group\n";
  for (int i = 0; i < 12; ++i) {
    char row[120];
    std::snprintf(row, sizeof(row), "%.3f,%.3f,%.3f,g%d\n", 0.05 * i, -0.03 * i, 0.02 * i, i % 2);
    csv += row;
  }
  WriteFile(dir / "cal.csv", csv);
  WriteFile(dir / "val.csv", csv + "0.600,-0.360,0.240,g0\n");
  return "scenario: cl\nkind: closed_loop\nseed: 1\nmodel: " + SourceDir() +
         "/models/planar3.xml\ndeclared:\n  model: " + declared_model +
         "\n  actuated_joints: [joint1, joint2, joint3]\n  end_effector: ee\n"
         "  sources:\n    - {at: joint1, about_axis_deg: 1}\n"
         "calibration: {csv: " +
         (dir / "cal.csv").string() + ", distances: " + distances +
         "}\nvalidation: {csv: " + (dir / "val.csv").string() + "}\ncandidates: [joint_offset]\n";
}

TEST(Reliability, InlineDeclaredModelMustBeTheScenariosModel) {
  TempDir tmp;
  const fs::path s = tmp.path() / "cl.yaml";
  WriteFile(s, ClosedLoopYaml(tmp.path(), SourceDir() + "/models/rover_arm.xml", "[]"));
  const CommandResult r = RunCommand(RunCmd(s, tmp.path() / "out"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("cl.yaml:6: key 'declared.model': names "), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("not the scenario's model"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "out"));
}

TEST(Reliability, CsvGroupDistancesMustBePositiveAndBetweenTwoGroups) {
  TempDir tmp;
  const fs::path s = tmp.path() / "cl.yaml";
  const std::string model = SourceDir() + "/models/planar3.xml";
  for (const char* bad : {"[[g0, g1, -0.05]]", "[[g0, g1, 0]]", "[[g0, g1, 1e300]]",
                          "[[g0, g1, .nan]]", "[[g0, g0, 0.05]]"}) {
    WriteFile(s, ClosedLoopYaml(tmp.path(), model, bad));
    const CommandResult r = RunCommand(RunCmd(s, tmp.path() / "out"));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.err;
    EXPECT_NE(LastLine(r.err).find("cl.yaml:11: key 'calibration.distances[0]"), std::string::npos)
        << bad << ": " << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "out")) << bad;
  }
}

// The size caps of docs/reliability.md (16 MiB YAML, 64 MiB model, 512 MiB CSV): files one byte
// over are bad input, refused before they are read (sparse files: nothing is written to disk).
TEST(Reliability, FilesOverTheSizeCapsAreRefusedUnread) {
  TempDir tmp;
  const auto sparse = [&](const std::string& name, std::uintmax_t bytes) {
    const fs::path p = tmp.path() / name;
    WriteFile(p, "");
    fs::resize_file(p, bytes);
    return p;
  };
  const fs::path big_yaml = sparse("big.yaml", (16u << 20) + 1);
  CommandResult r = RunCommand(RunCmd(big_yaml, tmp.path() / "out"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("big.yaml: 16777217 bytes, more than the 16777216 allowed"),
            std::string::npos)
      << r.err;
  const fs::path big_xml = sparse("big.xml", (64u << 20) + 1);
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml("", big_xml.string()));
  r = RunCommand(RunCmd(s, tmp.path() / "out"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("big.xml: 67108865 bytes, more than"), std::string::npos) << r.err;
  // Two different oversized CSVs: refused by size, not read whole to compare them.
  const fs::path big_csv = sparse("big.csv", (512ull << 20) + 1);
  const fs::path big_csv2 = sparse("big2.csv", (512ull << 20) + 1);
  r = RunCommand(Flexbench() + " identify --declared " + SourceDir() +
                 "/models/planar3.declared.yaml --calibration " + big_csv.string() +
                 " --validation " + big_csv2.string() + " --out " + (tmp.path() / "out").string() +
                 " </dev/null");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(
      LastLine(r.err).find("--calibration: " + big_csv.string() + ": 536870913 bytes, more than"),
      std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "out"));
}

// identify: configured in memory, errors name the option, --model used or rejected.
class IdentifyCli : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string csv = "joint1,joint2,joint3,x,y,z\n";
    for (int i = 0; i < 30; ++i) {
      char row[200];
      std::snprintf(row, sizeof(row), "%.3f,%.3f,%.3f,%.3f,%.3f,0.1\n", 0.05 * i, -0.03 * i,
                    0.02 * i, 0.3 - 0.01 * i, 0.01 * i);
      csv += row;
    }
    WriteFile(tmp_.path() / "cal.csv", csv);
    csv += "0.5,0.5,0.5,0.2,0.2,0.1\n";
    WriteFile(tmp_.path() / "val.csv", csv);
  }
  CommandResult Identify(const std::string& extra) {
    return RunCommand(Flexbench() + " identify --declared " + SourceDir() +
                      "/models/planar3.declared.yaml --calibration " +
                      (tmp_.path() / "cal.csv").string() + " --validation " +
                      (tmp_.path() / "val.csv").string() + " --out " +
                      (tmp_.path() / "out").string() + " " + extra + " </dev/null");
  }
  TempDir tmp_;
};

TEST_F(IdentifyCli, ModelIsTheDeclaredFilesOrRejected) {
  CommandResult r = Identify("--model /tmp");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--model /tmp: is not the model the declared file names"), std::string::npos)
      << r.err;
  r = Identify("--model " + SourceDir() + "/models/rover_arm.xml");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  r = Identify("--model " + SourceDir() +
               "/models/../models/planar3.xml --candidates "
               "joint_offset");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = Identify("--candidates joint_offset");  // --model is optional
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

TEST_F(IdentifyCli, OptionErrorsNameTheOptionNotATemporaryFile) {
  CommandResult r = Identify("--candidates bogus_effect");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("error: --candidates: no candidate effect 'bogus_effect'"),
            std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("/tmp/flexbench_identify"), std::string::npos) << r.err;
  r = Identify("--point-std 1e-300");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("--point-std 1e-300: must be between"), std::string::npos) << r.err;
  r = Identify("--point-std -1");
  EXPECT_EQ(r.exit_code, 2) << r.err;
}

TEST_F(IdentifyCli, RowsAreNamedByThePathAsGiven) {
  const CommandResult r = RunCommand(
      "cd " + tmp_.path().string() + " && " + Flexbench() + " identify --declared " + SourceDir() +
      "/models/planar3.declared.yaml --calibration cal.csv --validation ./val.csv "
      "--candidates joint_offset --out out </dev/null");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string res = ReadFile(tmp_.path() / "out" / "calibration_residuals.csv");
  EXPECT_NE(res.find(",cal.csv:2,"), std::string::npos) << res.substr(0, 400);
}

TEST_F(IdentifyCli, SameRowsForCalibrationAndValidationAreRefused) {
  const CommandResult r = RunCommand(Flexbench() + " identify --declared " + SourceDir() +
                                     "/models/planar3.declared.yaml --calibration " +
                                     (tmp_.path() / "cal.csv").string() + " --validation " +
                                     (tmp_.path() / "cal.csv").string() + " --out " +
                                     (tmp_.path() / "out").string() + " </dev/null");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("error: --validation: " + (tmp_.path() / "cal.csv").string() +
                                 " holds the same rows as the calibration file"),
            std::string::npos)
      << r.err;
}

}  // namespace
}  // namespace flexbench::testing
