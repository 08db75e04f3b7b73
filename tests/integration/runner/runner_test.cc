// The runner contract end to end: exit codes, one-line errors for bad input, no half-written
// output, same seed same bytes.
#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

std::string SmokeYaml(const std::string& extra = "", const std::string& model = "") {
  const std::string model_path = model.empty() ? SourceDir() + "/models/planar3.xml" : model;
  return "scenario: smoke_copy\nkind: smoke\nseed: 3\nmodel: " + model_path +
         "\ncamera: overview\nconfiguration: {joint1: 0.35, joint2: -0.6, joint3: 0.5}\n" + extra;
}

// A bad-input run: exit 2, exactly one line on stderr, no output folder left behind.
void ExpectBadInput(const TempDir& tmp, const std::string& scenario_path,
                    const std::string& must_contain) {
  const fs::path out = tmp.path() / "out";
  const CommandResult r =
      RunCommand(Flexbench() + " run " + scenario_path + " --out " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(must_contain), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  for (const auto& entry : fs::directory_iterator(tmp.path())) {
    EXPECT_EQ(entry.path().filename().string().find("out.tmp"), std::string::npos)
        << "temporary output left behind: " << entry.path();
  }
}

TEST(RunnerBadInput, MissingScenarioFile) {
  TempDir tmp;
  const std::string path = (tmp.path() / "nope.yaml").string();
  ExpectBadInput(tmp, path, path);
}

TEST(RunnerBadInput, YamlSyntaxErrorNamesFileAndLine) {
  TempDir tmp;
  const fs::path path = tmp.path() / "broken.yaml";
  WriteFile(path, "scenario: x\nkind: smoke\nseed: [1, 2\nmodel: a.xml\n");
  ExpectBadInput(tmp, path.string(), path.string() + ":");
  const CommandResult r = RunCommand(Flexbench() + " run " + path.string());
  EXPECT_NE(r.err.find("syntax error"), std::string::npos) << r.err;
}

TEST(RunnerBadInput, UnknownTopLevelKeyIsNamed) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml("colour: blue\n"));
  ExpectBadInput(tmp, path.string(), "unknown key 'colour'");
}

TEST(RunnerBadInput, UnknownNestedKeyIsNamedWithItsLine) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml("render:\n  mode: fast\n  shadows: false\n"));
  ExpectBadInput(tmp, path.string(), path.string() + ":9: unknown key 'render.shadows'");
}

TEST(RunnerBadInput, ModelRejectedByMujocoPassesItsMessageOn) {
  TempDir tmp;
  const fs::path model = tmp.path() / "bad.xml";
  WriteFile(model,
            "<mujoco><worldbody><geom type=\"sphere\" size=\"-1\"/>"
            "<body><joint type=\"bogus\"/></body></worldbody></mujoco>");
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml("", model.string()));
  ExpectBadInput(tmp, path.string(), "MuJoCo rejected the model");
  const CommandResult r = RunCommand(Flexbench() + " run " + path.string());
  EXPECT_NE(r.err.find("bogus"), std::string::npos) << "MuJoCo's own message: " << r.err;
}

TEST(RunnerBadInput, MissingModelFile) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml("", (tmp.path() / "absent.xml").string()));
  ExpectBadInput(tmp, path.string(), "absent.xml: model file not found");
}

TEST(RunnerBadInput, UnknownKind) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, "scenario: x\nkind: teleport\nseed: 1\n");
  ExpectBadInput(tmp, path.string(), "unknown scenario kind 'teleport'");
}

TEST(RunnerBadInput, BadGateOperator) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml("gates:\n  - {name: g, metric: detections, op: '=>', threshold: 1}\n"));
  ExpectBadInput(tmp, path.string(), "unknown operator '=>'");
}

TEST(RunnerBadInput, UnknownJointInConfiguration) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  std::string yaml = SmokeYaml();
  yaml.replace(yaml.find("joint3"), 6, "joint9");
  WriteFile(path, yaml);
  ExpectBadInput(tmp, path.string(), "no joint named 'joint9'");
}

TEST(RunnerBadInput, UnwritableOutputFolder) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml());
  const fs::path blocker = tmp.path() / "file";
  WriteFile(blocker, "not a folder");
  const CommandResult r =
      RunCommand(Flexbench() + " run " + path.string() + " --out " + (blocker / "out").string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("cannot create output folder"), std::string::npos) << r.err;
}

TEST(Runner, FailedGateExitsThreeAndReportsIt) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  WriteFile(path, SmokeYaml("gates:\n  - {name: impossible, metric: corner_rmse_px, op: '<', "
                            "threshold: 0.0}\n"));
  const fs::path out = tmp.path() / "out";
  CommandResult r = RunCommand(Flexbench() + " run " + path.string() + " --out " + out.string() +
                               " --check-gates");
  EXPECT_EQ(r.exit_code, 3) << r.err;
  const auto summary = nlohmann::json::parse(ReadFile(out / "summary.json"));
  EXPECT_FALSE(summary["gates"][0]["passed"].get<bool>());
  // Without --check-gates the same run is a success.
  r = RunCommand(Flexbench() + " run " + path.string() + " --out " + out.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

TEST(Runner, SummaryFollowsTheContract) {
  TempDir tmp;
  const fs::path out = tmp.path() / "out";
  const CommandResult r = RunCommand(Flexbench() + " run " + SourceDir() +
                                     "/scenarios/smoke.yaml --out " + out.string() + " --seed 11");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto s = nlohmann::json::parse(ReadFile(out / "summary.json"));
  EXPECT_EQ(s["scenario"], "smoke");
  EXPECT_EQ(s["seed"], 11);
  EXPECT_TRUE(s["estimators"].is_object());
  EXPECT_TRUE(s["metrics"]["corner_rmse_px"].is_number());
  EXPECT_TRUE(s["timing"]["total_s"].is_number());
  ASSERT_EQ(s["gates"].size(), 2u);
  for (const auto& g : s["gates"]) {
    for (const char* key : {"name", "metric", "op", "threshold", "value", "passed"}) {
      EXPECT_TRUE(g.contains(key)) << key;
    }
  }
  EXPECT_TRUE(fs::exists(out / "frames" / "smoke.png"));
}

// --frames: key (default) writes a few of tag_fusion's configuration frames and every figure,
// all every frame, none no PNG, with the same numbers; a wrong word is bad input.
TEST(Runner, FramesOptionChoosesTheImagesAndNothingElse) {
  TempDir tmp;
  const std::string run =
      Flexbench() + " run " + SourceDir() + "/scenarios/rover_apriltag_exp1.yaml --quiet --out ";
  std::map<std::string, std::set<std::string>> pngs;
  std::map<std::string, nlohmann::json> estimators;
  for (const char* f : {"key", "all", "none"}) {
    const fs::path out = tmp.path() / f;
    const CommandResult r = RunCommand(
        run + out.string() + (std::string(f) == "key" ? "" : " --frames " + std::string(f)));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const auto& e : fs::recursive_directory_iterator(out)) {
      if (e.path().extension() == ".png") pngs[f].insert(e.path().filename().string());
    }
    estimators[f] = nlohmann::json::parse(ReadFile(out / "summary.json"))["estimators"];
  }
  EXPECT_EQ(pngs["key"], (std::set<std::string>{"config_00.png", "config_03.png", "config_06.png",
                                                "lateral_error.png"}));
  EXPECT_EQ(pngs["all"].size(), 10u);
  EXPECT_TRUE(pngs["none"].empty());
  EXPECT_EQ(estimators["key"], estimators["all"]);
  EXPECT_EQ(estimators["key"], estimators["none"]);
  EXPECT_NE(nlohmann::json::parse(ReadFile(tmp.path() / "none" / "summary.json"))["command"]
                .get<std::string>()
                .find("--frames none"),
            std::string::npos);
  const CommandResult bad = RunCommand(run + (tmp.path() / "x").string() + " --frames some");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--frames 'some': expected all, key or none"), std::string::npos);
}

TEST(Runner, SameSeedSameBytes) {
  TempDir tmp;
  const std::string cmd = Flexbench() + " run " + SourceDir() + "/scenarios/smoke.yaml --out ";
  ASSERT_EQ(RunCommand(cmd + (tmp.path() / "a").string()).exit_code, 0);
  ASSERT_EQ(RunCommand(cmd + (tmp.path() / "b").string()).exit_code, 0);
  for (const auto& entry : fs::recursive_directory_iterator(tmp.path() / "a")) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), tmp.path() / "a");
    std::string a = ReadFile(entry.path());
    std::string b = ReadFile(tmp.path() / "b" / rel);
    // The recorded command names --out (summary.json, report.html): the one other difference.
    const std::string out_b = (tmp.path() / "b").string();
    for (size_t p = b.find(out_b); p != std::string::npos; p = b.find(out_b, p + 1)) {
      b.replace(p, out_b.size(), (tmp.path() / "a").string());
    }
    if (rel == "summary.json") {
      // Wall-clock timing is the one field allowed to differ.
      auto ja = nlohmann::json::parse(a);
      auto jb = nlohmann::json::parse(b);
      ja.erase("timing");
      jb.erase("timing");
      a = ja.dump();
      b = jb.dump();
    }
    EXPECT_EQ(a, b) << rel;
  }
}

TEST(Runner, VersionListAndHelp) {
  CommandResult r = RunCommand(Flexbench() + " --version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("flexbench "), std::string::npos);
  r = RunCommand(Flexbench() + " list --dir " + SourceDir() + "/scenarios");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("smoke.yaml"), std::string::npos) << r.out;
  r = RunCommand(Flexbench() + " --help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("run"), std::string::npos);
  r = RunCommand(Flexbench() + " run");
  EXPECT_EQ(r.exit_code, 2);
}

}  // namespace
}  // namespace flexbench::testing
