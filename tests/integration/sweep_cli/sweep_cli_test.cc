// `flexbench sweep` through the CLI. Deterministic whatever the worker count or the
// order runs finished in, resumable, shards + collect equal to one local run, a failing run
// recorded while the sweep goes on, statistical gates with exit 3, bad input exit 2 in one line.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <thread>

#include "scenarios/runner/output.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

// The contact scenario runs in ~0.1 s and its metrics depend on the seed.
std::string SweepYaml(const std::string& extra = "",
                      const std::string& grid = "grid:\n  distance_std_m: [0.001, 0.002]\n") {
  return "sweep: contact_test\nscenario: " + SourceDir() +
         "/scenarios/humanoid_table_contact.yaml\nseeds: {from: 1, to: 4}\n" + grid + extra;
}

CommandResult Sweep(const fs::path& file, const fs::path& out, const std::string& extra = "") {
  return RunCommand(Flexbench() + " sweep " + file.string() + " --out " + out.string() + " " +
                    extra + " </dev/null");
}

TEST(SweepCli, LocalSweepIsDeterministicResumableAndIndependentOfWorkers) {
  TempDir tmp;
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, SweepYaml("plot: {metrics: [estimators.ppoe_ekf.metrics.pos_err_final_m]}\n"));
  CommandResult r = Sweep(file, tmp.path() / "a", "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("8 runs to do"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("8/8 runs"), std::string::npos) << r.err;  // the progress line
  EXPECT_NE(r.err.find("ETA"), std::string::npos);
  const std::string csv = ReadFile(tmp.path() / "a" / "sweep.csv");
  const std::string agg = ReadFile(tmp.path() / "a" / "aggregate.json");
  EXPECT_EQ(CountLines(csv), 9);
  EXPECT_EQ(csv.rfind("point,seed,status,exit_code,distance_std_m,", 0), 0u) << csv;
  const Json a = Json::parse(agg);
  ASSERT_EQ(a["points"].size(), 2u);
  EXPECT_EQ(a["points"][1]["set"]["distance_std_m"], "0.002");
  const Json& m = a["points"][0]["metrics"]["estimators.ppoe_ekf.metrics.pos_err_final_m"];
  EXPECT_EQ(m["n"], 4);
  EXPECT_LE(m["ci_low"].get<double>(), m["mean"].get<double>());
  EXPECT_GE(m["ci_high"].get<double>(), m["mean"].get<double>());
  EXPECT_GT(m["std"].get<double>(), 0.0);  // the seeds differ
  const Json& g = a["points"][0]["gates"]["correlations_correct_unobserved_directions"];
  EXPECT_EQ(g["n"], 4);
  EXPECT_TRUE(fs::exists(tmp.path() / "a" / "sweep.png"));

  // Resumed: nothing to do, the same bytes. The temporary of a worker that ended (one killed
  // while the resumed sweep had already redone its run) is removed; a folder named alike
  // without a marker is the user's and is kept.
  const fs::path runs = tmp.path() / "a" / "runs" / "distance_std_m_0.001";
  ASSERT_TRUE(fs::exists(runs / "seed_1")) << "the sweep's run folders moved";
  const std::string ended = scenarios::TemporaryName("seed_1", "tmp", 1999999997);
  const std::string users = scenarios::TemporaryName("seed_1", "tmp", 1999999998);
  WriteFile(runs / ended / scenarios::kTemporaryMarker,
            Marker(Host(), PidNamespace(), 1999999997, 5));
  WriteFile(runs / users / "notes.txt", "mine");
  r = Sweep(file, tmp.path() / "a", "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("0 runs to do"), std::string::npos) << r.err;
  EXPECT_EQ(ReadFile(tmp.path() / "a" / "sweep.csv"), csv);
  EXPECT_EQ(ReadFile(tmp.path() / "a" / "aggregate.json"), agg);
  EXPECT_FALSE(fs::exists(runs / ended));
  EXPECT_EQ(ReadFile(runs / users / "notes.txt"), "mine");

  // One worker, so another finishing order: the same bytes.
  r = Sweep(file, tmp.path() / "b", "-j 1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ReadFile(tmp.path() / "b" / "sweep.csv"), csv);
  EXPECT_EQ(ReadFile(tmp.path() / "b" / "aggregate.json"), agg);
  EXPECT_EQ(ReadFile(tmp.path() / "b" / "sweep.png"), ReadFile(tmp.path() / "a" / "sweep.png"));

  // Shards, then --collect: the same bytes as the local run; collecting early lists the gap.
  const fs::path c = tmp.path() / "c";
  for (int i = 0; i < 3; ++i) {
    r = Sweep(file, c, "--shard " + std::to_string(i) + "/3");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    if (i == 0) {
      EXPECT_FALSE(fs::exists(c / "sweep.csv"));  // a shard does not collect
    }
    if (i == 1) {
      r = Sweep(file, c, "--collect");
      EXPECT_EQ(r.exit_code, 1) << r.err;
      EXPECT_NE(r.err.find("2 have no result"), std::string::npos) << r.err;
    }
  }
  r = Sweep(file, c, "--collect");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ReadFile(c / "sweep.csv"), csv);
  EXPECT_EQ(ReadFile(c / "aggregate.json"), agg);
}

// --run-files summary (or the file's run_files: summary): each run keeps its summary.json and
// report.html only, and the sweep's table, aggregate and figure are the same bytes.
TEST(SweepCli, RunFilesSummaryKeepsTheSameAggregate) {
  TempDir tmp;
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, SweepYaml("plot: {metrics: [estimators.ppoe_ekf.metrics.pos_err_final_m]}\n"));
  CommandResult r = Sweep(file, tmp.path() / "all", "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = Sweep(file, tmp.path() / "small", "-j 2 --run-files summary");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"sweep.csv", "aggregate.json", "sweep.png"}) {
    EXPECT_EQ(ReadFile(tmp.path() / "small" / f), ReadFile(tmp.path() / "all" / f)) << f;
  }
  const auto files = [](const fs::path& dir) {
    std::set<std::string> out;
    for (const auto& e : fs::recursive_directory_iterator(dir)) {
      if (e.is_regular_file()) out.insert(fs::relative(e.path(), dir).string());
    }
    return out;
  };
  const fs::path run = fs::path("runs") / "distance_std_m_0.002" / "seed_3";
  const std::set<std::string> kept = files(tmp.path() / "small" / run);
  EXPECT_EQ(kept, (std::set<std::string>{"summary.json", "report.html", "run.key",
                                         scenarios::kResultMarker}));
  EXPECT_GT(files(tmp.path() / "all" / run).size(), kept.size() + 2);
  EXPECT_EQ(Json::parse(ReadFile(tmp.path() / "small" / run / "summary.json"))["estimators"],
            Json::parse(ReadFile(tmp.path() / "all" / run / "summary.json"))["estimators"]);

  WriteFile(file, SweepYaml("run_files: summary\n"));
  r = Sweep(file, tmp.path() / "file", "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(files(tmp.path() / "file" / run), kept);
  WriteFile(file, SweepYaml("run_files: some\n"));
  r = Sweep(file, tmp.path() / "bad", "-j 2");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("run_files 'some': expected all or summary"), std::string::npos) << r.err;
  WriteFile(file, SweepYaml());
  r = Sweep(file, tmp.path() / "bad", "--run-files most");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--run-files 'most'"), std::string::npos) << r.err;
}

// A run that fails inside a sweep (here: its output folder is blocked by a file, exit 2 from
// the run) is recorded with its exit code and last stderr line; the others go on.
TEST(SweepCli, AFailedRunIsRecordedAndTheSweepGoesOn) {
  TempDir tmp;
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, SweepYaml("", ""));
  const fs::path out = tmp.path() / "out";
  ASSERT_EQ(Sweep(file, out, "-j 2").exit_code, 0);
  fs::remove_all(out / "runs/base/seed_2");
  WriteFile(out / "runs/base/seed_2", "in the way\n");
  const CommandResult r = Sweep(file, out, "-j 2");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("1 runs to do"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("run runs/base/seed_2 failed (exit 2)"), std::string::npos) << r.err;
  const Json a = Json::parse(ReadFile(out / "aggregate.json"));
  ASSERT_EQ(a["failed"].size(), 1u);
  EXPECT_EQ(a["failed"][0]["seed"], 2);
  EXPECT_EQ(a["failed"][0]["exit_code"], 2);
  EXPECT_NE(a["failed"][0]["error"].get<std::string>().find("seed_2"), std::string::npos);
  EXPECT_EQ(a["succeeded"], 3);
  EXPECT_EQ(a["points"][0]["metrics"]["estimators.ppoe_ekf.metrics.pos_err_final_m"]["n"], 3);
  EXPECT_NE(ReadFile(out / "sweep.csv").find("base,2,failed,2"), std::string::npos);
  // Cleared, the failed run alone is redone and its record removed.
  fs::remove(out / "runs/base/seed_2");
  const CommandResult again = Sweep(file, out, "-j 2");
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.err.find("1 runs to do"), std::string::npos);
  EXPECT_FALSE(fs::exists(out / "failed/base/seed_2.json"));
}

// A run that dies by a signal (here SIGKILL, as the OOM killer would) is recorded with the
// signal and the sweep goes on with the next run.
TEST(SweepCli, ARunKilledByASignalIsRecordedAndTheSweepGoesOn) {
  TempDir tmp;
  const fs::path file = tmp.path() / "s.yaml";
  // Two runs of a ~1 s scenario, one worker: the first is killed while it runs.
  WriteFile(file, "sweep: killed\nscenario: " + SourceDir() +
                      "/scenarios/rover_apriltag_exp1.yaml\nseeds: {from: 1, to: 2}\n");
  const fs::path out = tmp.path() / "out";
  const std::string err_file = (tmp.path() / "err.txt").string();
  const pid_t sweep = ::fork();
  ASSERT_GE(sweep, 0);
  if (sweep == 0) {
    const std::string cmd = "exec " + Flexbench() + " sweep " + file.string() + " --out " +
                            out.string() + " -j 1 </dev/null >/dev/null 2>" + err_file;
    ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  pid_t worker = -1;
  for (int k = 0; k < 3000 && worker < 0; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const std::vector<pid_t> children = ChildrenOf(sweep);
    worker = children.empty() ? -1 : children.front();
  }
  ASSERT_GT(worker, 0) << "no worker appeared";
  ASSERT_EQ(::kill(worker, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(sweep, &status, 0), sweep);
  ASSERT_TRUE(WIFEXITED(status));
  const std::string err = ReadFile(err_file);
  EXPECT_EQ(WEXITSTATUS(status), 1) << err;
  const Json a = Json::parse(ReadFile(out / "aggregate.json"));
  ASSERT_EQ(a["failed"].size(), 1u) << a.dump();
  // The first run, unless the machine was slow enough for it to end before the kill.
  const int killed = a["failed"][0]["seed"].get<int>();
  const std::string dir = "runs/base/seed_" + std::to_string(killed);
  EXPECT_NE(err.find("run " + dir + " failed (signal 9)"), std::string::npos) << err;
  EXPECT_EQ(a["failed"][0]["signal"], 9);
  EXPECT_TRUE(a["failed"][0]["exit_code"].is_null());
  EXPECT_EQ(a["succeeded"], 1);
  EXPECT_TRUE(fs::is_regular_file(out / "runs/base" / ("seed_" + std::to_string(3 - killed)) /
                                  "summary.json"));
  EXPECT_FALSE(fs::exists(out / dir / "summary.json"));
}

TEST(SweepCli, StatisticalGatesPassFailAndNameTheirMetric) {
  TempDir tmp;
  const std::string metric = "estimators.ppoe_ekf.metrics.pos_err_final_m";
  const fs::path pass = tmp.path() / "pass.yaml";
  WriteFile(pass, SweepYaml("gates:\n  - name: paired\n    metric: \"ci_high(ratio(" + metric +
                                ", estimators.fk.metrics.pos_err_final_m))\"\n    op: \"<\"\n"
                                "    threshold: 1000\n"
                                "  - {name: finite, metric: \"n(" +
                                metric +
                                ")\", op: \"==\", "
                                "threshold: 4}\n",
                            ""));
  CommandResult r = Sweep(pass, tmp.path() / "p");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("PASS gate paired @base"), std::string::npos) << r.err;
  const Json a = Json::parse(ReadFile(tmp.path() / "p" / "aggregate.json"));
  EXPECT_TRUE(a["gates_passed"].get<bool>());
  EXPECT_TRUE(a["points"][0]["ratios"].contains("ratio(" + metric +
                                                ", estimators.fk.metrics.pos_err_final_m)"));

  const fs::path fail = tmp.path() / "fail.yaml";
  WriteFile(fail, SweepYaml("gates:\n  - {name: impossible, metric: \"mean(" + metric +
                                ")\", op: \"<\", threshold: 0}\n",
                            ""));
  r = Sweep(fail, tmp.path() / "f");
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("FAIL gate impossible @base"), std::string::npos) << r.err;

  // A metric no run has: bad input naming the gate's line, not a failed gate.
  const fs::path typo = tmp.path() / "typo.yaml";
  WriteFile(typo, SweepYaml("gates:\n  - {name: t, metric: \"mean(estimators.ppoe_ekf.metrics."
                            "pos_err_finl_m)\", op: \"<\", threshold: 1}\n",
                            ""));
  r = Sweep(typo, tmp.path() / "t");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("typo.yaml:5: gate 't': metric"), std::string::npos) << r.err;
}

TEST(SweepCli, BadInputIsOneLineAndExit2) {
  TempDir tmp;
  struct Case {
    std::string yaml;
    std::string extra;
    std::string expect;
  };
  const std::vector<Case> cases{
      {SweepYaml("", "grid:\n  truth.nothing_here: [1, 2]\n"), "",
       "point 'truth.nothing_here_1': --set truth.nothing_here: unknown key 'truth'"},
      {SweepYaml("", "grid:\n  distance_std_m: [fast, 2]\n"), "", "--set distance_std_m"},
      {SweepYaml("", "grid: {}\n"), "", "empty grid"},
      {"sweep: x\nscenario: " + SourceDir() + "/scenarios/smoke.yaml\nseeds: {from: 9, to: 1}\n",
       "", "seed range is empty"},
      {SweepYaml(), "--shard 4/4", "--shard '4/4': index out of range (0..3)"},
      {SweepYaml(), "--shard x", "--shard 'x'"},
      {SweepYaml(), "--executor slurm", "sbatch not found on PATH"},
      {SweepYaml(), "--executor cloud", "--executor 'cloud'"},
      {SweepYaml("gates:\n  - {name: g, metric: pass_fraction(no_such_gate), op: \">\", "
                 "threshold: 0}\n",
                 ""),
       "", "'no_such_gate' is not a gate of the scenario"},
  };
  for (const Case& c : cases) {
    const fs::path file = tmp.path() / "bad.yaml";
    WriteFile(file, c.yaml);
    const std::string env = c.extra == "--executor slurm" ? "PATH=/nonexistent " : "";
    const CommandResult r = RunCommand(env + Flexbench() + " sweep " + file.string() + " --out " +
                                       (tmp.path() / "o").string() + " " + c.extra);
    EXPECT_EQ(r.exit_code, 2) << c.expect << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(tmp.path() / "o" / "runs")) << c.expect;
  }
  // An --out that is somebody's folder is refused, untouched.
  const fs::path file = tmp.path() / "ok.yaml";
  WriteFile(file, SweepYaml());
  WriteFile(tmp.path() / "mine" / "notes.txt", "keep\n");
  const CommandResult r = Sweep(file, tmp.path() / "mine");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is not a sweep's folder"), std::string::npos) << r.err;
  EXPECT_EQ(ReadFile(tmp.path() / "mine" / "notes.txt"), "keep\n");
}

}  // namespace
}  // namespace flexbench::testing
