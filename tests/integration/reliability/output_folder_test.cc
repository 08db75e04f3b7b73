// The output folder of `flexbench run` / `identify`: temporaries are recognised by their marker
// (host, PID namespace, PID, start time) and only those of ended runs of this host and
// namespace are removed; a previous result is recognised by its marker or a real flexbench
// summary; --force never replaces a folder holding a file the run read; long and empty --out;
// SIGTERM and SIGINT remove the run's temporary.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <climits>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <thread>
#include <vector>

#include "scenarios/runner/output.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using scenarios::kResultMarker;
using scenarios::kTemporaryMarker;
using scenarios::OutputDir;
using scenarios::TemporaryName;

std::string SmokeYaml() {
  return "scenario: smoke_copy\nkind: smoke\nseed: 3\nmodel: " + SourceDir() +
         "/models/planar3.xml\ncamera: overview\nconfiguration: {joint1: 0.35, joint2: -0.6, "
         "joint3: 0.5}\n";
}

std::string RunCmd(const fs::path& scenario, const fs::path& out, const std::string& extra = "") {
  return Flexbench() + " run " + scenario.string() + " --out '" + out.string() + "' " + extra +
         " </dev/null";
}

// Every regular file below `dir` (hidden ones too), by relative path, with its bytes.
std::map<std::string, std::string> Files(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = ReadFile(e.path());
  }
  return out;
}

// Names beside `dir` that start like its temporaries (".tmp-" or ".old-" after a prefix of
// its name: long names are cut).
std::vector<std::string> Temporaries(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir.parent_path())) {
    const std::string f = e.path().filename().string();
    if (f.find(".tmp-") != std::string::npos || f.find(".old-") != std::string::npos) {
      out.push_back(f);
    }
  }
  return out;
}

// Only a temporary with a marker of this host and PID namespace whose process has ended
// (gone, its PID reused, or a zombie), or one that holds nothing but a partial marker and whose
// PID runs nowhere, is removed; a user's folder named like one, a live run's and one of another
// host or container are kept.
TEST(OutputFolder, OnlyMarkedTemporariesOfEndedRunsAreRemoved) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  const fs::path dir = tmp.path();
  const std::string host = Host(), ns = PidNamespace();
  const unsigned long long me = StartTime(getpid());
  ASSERT_FALSE(ns.empty());
  // Kept: the data-loss reproducer (a user's folder named like a temporary) and an unmarked
  // "temporary".
  WriteFile(dir / "results.old-2024" / "thesis.tex", "years of work");
  WriteFile(dir / "results.tmp-1999999999" / "notes.txt", "mine");
  // Kept: a marker of another host, of another PID namespace (a Slurm node, a container), of
  // a live process (this test), a marker naming another PID than the folder, a broken marker.
  const long gone = 1999999998;  // above any pid_max: no such process
  WriteFile(dir / ("results.tmp-" + std::to_string(gone)) / kTemporaryMarker,
            Marker("other-node", ns, gone, 5));
  WriteFile(dir / ("results.old-" + std::to_string(gone)) / kTemporaryMarker,
            Marker(host, "pid:[1]", gone, 5));
  const std::string live = "results.tmp-" + std::to_string(getpid());
  WriteFile(dir / live / kTemporaryMarker, Marker(host, ns, getpid(), me));
  WriteFile(dir / "results.tmp-1999999997" / kTemporaryMarker, Marker(host, ns, gone, 5));
  // Kept: an unmarked empty folder whose PID runs (the test runner's: mid-way through its
  // mkdir and marker write, as far as a later run can tell).
  const std::string unmarked_live = "results.tmp-" + std::to_string(getppid());
  fs::create_directories(dir / unmarked_live);
  // Removed: a run killed between its mkdir and the end of its marker's write: an empty
  // folder, or one holding only a partial marker, whose PID runs nowhere here.
  fs::create_directories(dir / "results.tmp-1999999994");
  WriteFile(dir / "results.tmp-1999999996" / kTemporaryMarker, "flexbench temporary folder\n");
  // Removed: ended runs of this host and namespace: gone, PID reused (this test's PID with
  // another start time), a zombie.
  const std::string gone_dir = "results.tmp-1999999995";
  WriteFile(dir / gone_dir / kTemporaryMarker, Marker(host, ns, 1999999995, 5));
  WriteFile(dir / gone_dir / "frames" / "f.png", "x");
  const std::string reused = "results.old-" + std::to_string(getpid()) + "-1";
  WriteFile(dir / reused / kTemporaryMarker, Marker(host, ns, getpid(), me + 1));
  const pid_t zombie = ::fork();
  ASSERT_GE(zombie, 0);
  if (zombie == 0) ::_exit(0);
  for (int k = 0; k < 500; ++k) {
    if (ReadFile("/proc/" + std::to_string(zombie) + "/stat").find(") Z") != std::string::npos) {
      break;
    }
    ::usleep(2000);
  }
  const std::string zombie_dir = "results.tmp-" + std::to_string(zombie);
  WriteFile(dir / zombie_dir / kTemporaryMarker, Marker(host, ns, zombie, StartTime(zombie)));

  const CommandResult r = RunCommand(RunCmd(s, dir / "results"));
  ::waitpid(zombie, nullptr, 0);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ReadFile(dir / "results.old-2024" / "thesis.tex"), "years of work");
  EXPECT_EQ(ReadFile(dir / "results.tmp-1999999999" / "notes.txt"), "mine");
  EXPECT_TRUE(fs::exists(dir / ("results.tmp-" + std::to_string(gone))));
  EXPECT_TRUE(fs::exists(dir / ("results.old-" + std::to_string(gone))));
  EXPECT_TRUE(fs::exists(dir / live));
  EXPECT_TRUE(fs::exists(dir / "results.tmp-1999999997"));
  EXPECT_TRUE(fs::exists(dir / unmarked_live));
  EXPECT_FALSE(fs::exists(dir / "results.tmp-1999999994"));
  EXPECT_FALSE(fs::exists(dir / "results.tmp-1999999996"));
  EXPECT_FALSE(fs::exists(dir / gone_dir));
  EXPECT_FALSE(fs::exists(dir / reused));
  EXPECT_FALSE(fs::exists(dir / zombie_dir));
  // The result holds the result marker, never the temporary's.
  EXPECT_TRUE(fs::is_regular_file(dir / "results" / kResultMarker));
  EXPECT_FALSE(fs::exists(dir / "results" / kTemporaryMarker));
}

// A live temporary holds its marker while the run works (what a run on another node reads).
TEST(OutputFolder, TemporaryHoldsItsMakersMarker) {
  TempDir tmp;
  const fs::path out = tmp.path() / "out";
  OutputDir o(out);
  const fs::path t = tmp.path() / TemporaryName("out", "tmp", getpid());
  ASSERT_TRUE(fs::is_directory(t));
  EXPECT_EQ(ReadFile(t / kTemporaryMarker),
            Marker(Host(), PidNamespace(), getpid(), StartTime(getpid())));
  o.Commit();
  EXPECT_FALSE(fs::exists(t));
  EXPECT_FALSE(fs::exists(out / kTemporaryMarker));
  EXPECT_TRUE(fs::exists(out / kResultMarker));
}

// a summary.json that is not a flexbench summary does not make a folder a result.
TEST(OutputFolder, OnlyARealSummaryOrTheMarkerMakesAResult) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  int k = 0;
  for (const std::string& summary :
       {std::string("not json\n"), std::string("{}\n"), std::string("[1, 2]\n"),
        std::string("{\"scenario\": \"x\", \"kind\": \"smoke\", \"seed\": 1}\n"),
        std::string(100000, '[')}) {
    const fs::path out = tmp.path() / ("myproj" + std::to_string(k++));
    WriteFile(out / "summary.json", summary);
    WriteFile(out / "thesis.tex", "years of work");
    const auto before = Files(out);
    const CommandResult r = RunCommand(RunCmd(s, out));
    EXPECT_EQ(r.exit_code, 2) << summary.substr(0, 40) << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("not a flexbench result"), std::string::npos) << r.err;
    EXPECT_TRUE(Files(out) == before) << "the folder changed";
    EXPECT_EQ(Temporaries(out), std::vector<std::string>{});
  }
  // A result of an earlier version (no marker, a complete summary) is replaced; so is a result
  // with the marker.
  const fs::path out = tmp.path() / "earlier";
  ASSERT_EQ(RunCommand(RunCmd(s, out)).exit_code, 0);
  fs::remove(out / kResultMarker);
  CommandResult r = RunCommand(RunCmd(s, out));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / kResultMarker));
  r = RunCommand(RunCmd(s, out));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(Temporaries(out), std::vector<std::string>{});
}

// Two runs of the same command: the same files, byte for byte, apart from the summary's
// wall-clock timing (the marker has fixed bytes).
TEST(OutputFolder, ResultMarkerKeepsRunsIdentical) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  ASSERT_EQ(RunCommand(RunCmd(s, tmp.path() / "a")).exit_code, 0);
  ASSERT_EQ(RunCommand(RunCmd(s, tmp.path() / "b")).exit_code, 0);
  auto a = Files(tmp.path() / "a"), b = Files(tmp.path() / "b");
  ASSERT_EQ(a.size(), b.size());
  for (const auto& [rel, bytes] : a) {
    ASSERT_TRUE(b.count(rel)) << rel;
    if (rel != "summary.json" && rel != "report.html") {
      EXPECT_EQ(bytes, b.at(rel)) << rel;
    }
  }
}

// --force never replaces a folder that holds a file the run read (here the model
// the scenario names, not the scenario itself).
TEST(OutputFolder, ForceNeverReplacesAFolderHoldingAnInput) {
  TempDir tmp;
  const fs::path w2 = tmp.path() / "W2";
  fs::create_directories(w2 / "scenarios");
  fs::create_directories(w2 / "models");
  fs::copy_file(SourceDir() + "/scenarios/smoke.yaml", w2 / "scenarios" / "smoke.yaml");
  fs::copy_file(SourceDir() + "/models/planar3.xml", w2 / "models" / "planar3.xml");
  const std::string model = ReadFile(w2 / "models" / "planar3.xml");
  for (const char* extra : {"--force", ""}) {
    const CommandResult r =
        RunCommand(RunCmd(w2 / "scenarios" / "smoke.yaml", w2 / "models", extra));
    EXPECT_EQ(r.exit_code, 2) << extra << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("holds an input of this run"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("planar3.xml"), std::string::npos) << r.err;
    EXPECT_EQ(ReadFile(w2 / "models" / "planar3.xml"), model);
    EXPECT_EQ(Temporaries(w2 / "models"), std::vector<std::string>{});
  }
  // The folder above both is refused too.
  const CommandResult r = RunCommand(RunCmd(w2 / "scenarios" / "smoke.yaml", w2, "--force"));
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(ReadFile(w2 / "models" / "planar3.xml"), model);
}

// a 250-character --out works (its temporary's name is cut and hashed to fit).
TEST(OutputFolder, LongOutNameFitsItsTemporary) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  for (const size_t length : {size_t{235}, size_t{250}, size_t{255}}) {
    const fs::path out = tmp.path() / std::string(length, 'a');
    CommandResult r = RunCommand(RunCmd(s, out));
    ASSERT_EQ(r.exit_code, 0) << length << ": " << r.err;
    EXPECT_TRUE(fs::is_regular_file(out / "summary.json"));
    r = RunCommand(RunCmd(s, out));  // replacing it: the ".old-" folder fits too
    ASSERT_EQ(r.exit_code, 0) << length << ": " << r.err;
    EXPECT_EQ(Temporaries(out), std::vector<std::string>{});
    fs::remove_all(out);
  }
  EXPECT_LE(TemporaryName(std::string(255, 'a'), "old", 2147483647, 99).size(), size_t{NAME_MAX});
  EXPECT_NE(TemporaryName(std::string(250, 'a'), "tmp", 7),
            TemporaryName(std::string(249, 'a') + "b", "tmp", 7));
}

// `--out ''` is refused naming --out (it wrote ./out/<scenario>).
TEST(OutputFolder, EmptyOutIsRefused) {
  TempDir tmp;
  const fs::path s = tmp.path() / "s.yaml";
  WriteFile(s, SmokeYaml());
  const std::string cd = "cd " + tmp.path().string() + " && ";
  for (const std::string& cmd :
       {Flexbench() + " run " + s.string() + " --out ''",
        Flexbench() + " run " + s.string() + " --out=",
        Flexbench() + " identify --declared " + SourceDir() +
            "/models/planar3.declared.yaml --calibration a.csv --validation b.csv --out ''"}) {
    const CommandResult r = RunCommand(cd + cmd + " </dev/null");
    if (cmd.find("--out ''") != std::string::npos) {
      EXPECT_EQ(r.err,
                "flexbench: error: --out '': an empty folder name; name a folder, or omit "
                "--out for the default\n");
    }
    EXPECT_EQ(r.exit_code, 2) << cmd << ": " << r.err;
    EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;  // CLI11 refuses `--out=`
    EXPECT_FALSE(fs::exists(tmp.path() / "out")) << cmd;
  }
}

// Waits until `ready()` (then sends `sig` to `pid`) or until `waited` exits by itself;
// returns its wait status.
int SignalWhen(pid_t pid, int sig, pid_t waited, const std::function<bool()>& ready, bool* sent) {
  int status = 0;
  *sent = false;
  const Clock::time_point start = Clock::now();
  for (;;) {
    if (::waitpid(waited, &status, WNOHANG) == waited) return status;
    if (!*sent && ready()) {
      ::kill(pid, sig);
      *sent = true;
    }
    if (Clock::now() - start > std::chrono::seconds(120)) ::kill(waited, SIGKILL);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

// a run ended by SIGTERM or SIGINT mid-run removes its temporary and ends by the
// signal (exit status 128 + signal in a shell); a previous result at --out stays as it was.
TEST(OutputFolder, SigtermAndSigintRemoveTheTemporary) {
  TempDir tmp;
  const fs::path out = tmp.path() / "out";
  const fs::path log = tmp.path() / "log.txt";
  const std::vector<std::string> args = {
      Flexbench(), "run",        SourceDir() + "/scenarios/rover_apriltag_exp2.yaml",
      "--out",     out.string(), "--quiet"};
  for (const int sig : {SIGTERM, SIGINT}) {
    for (const bool replace : {false, true}) {
      SCOPED_TRACE(std::string(strsignal(sig)) + (replace ? ", replacing a result" : ""));
      fs::remove_all(out);
      std::map<std::string, std::string> previous;
      if (replace) {
        WriteFile(out / "summary.json",
                  "{\"scenario\": \"s\", \"kind\": \"k\", \"seed\": 1, "
                  "\"metrics\": {}, \"gates\": []}\n");
        WriteFile(out / kResultMarker, "x");
        previous = Files(out);
      }
      const pid_t pid = Spawn(args, log);
      const fs::path work = tmp.path() / TemporaryName("out", "tmp", pid);
      bool sent = false;
      // Mid-run: a few rendered frames written.
      const int status = SignalWhen(
          pid, sig, pid, [&] { return FilesIn(work) >= 4; }, &sent);
      ASSERT_TRUE(sent) << "the run ended before the signal: " << ReadFile(log);
      EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig) << status << ReadFile(log);
      EXPECT_EQ(Temporaries(out), std::vector<std::string>{});
      if (replace) {
        EXPECT_TRUE(Files(out) == previous) << "the previous result changed";
      } else {
        EXPECT_FALSE(fs::exists(out));
      }
    }
  }
}

// A sweep's worker (a forked child running the scenario, no exec) killed by SIGTERM removes its
// temporary too: the handler acts for the child's own temporaries only.
TEST(OutputFolder, SigtermOfASweepWorkerRemovesItsTemporary) {
  TempDir tmp;
  const fs::path file = tmp.path() / "sweep.yaml";
  WriteFile(file, "sweep: sig\nscenario: " + SourceDir() +
                      "/scenarios/rover_apriltag_exp2.yaml\nseeds: {from: 1, to: 1}\n");
  const fs::path out = tmp.path() / "sweep";
  const fs::path log = tmp.path() / "log.txt";
  const pid_t sweep =
      Spawn({Flexbench(), "sweep", file.string(), "--out", out.string(), "-j", "1"}, log);
  // The worker's PID is in its temporary's marker.
  pid_t worker = 0;
  fs::path work;
  const auto find_worker = [&] {
    std::error_code ec;
    for (fs::recursive_directory_iterator it(out, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string f = it->path().filename().string();
      if (f.find(".tmp-") == std::string::npos || FilesIn(it->path()) < 4) continue;
      const std::string m = ReadFile(it->path() / kTemporaryMarker);
      const size_t at = m.find("\npid=");
      if (at == std::string::npos) continue;
      worker = static_cast<pid_t>(std::stol(m.substr(at + 5)));
      work = it->path();
      return true;
    }
    return false;
  };
  bool sent = false;
  int status = 0;
  for (const Clock::time_point start = Clock::now(); !sent;) {
    if (::waitpid(sweep, &status, WNOHANG) == sweep) break;
    if (find_worker()) {
      ASSERT_NE(worker, sweep);
      ::kill(worker, SIGTERM);
      sent = true;
    }
    ASSERT_LT(Clock::now() - start, std::chrono::seconds(120));
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_TRUE(sent) << "the sweep ended before the signal: " << ReadFile(log);
  ::waitpid(sweep, &status, 0);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 1) << ReadFile(log);  // a failed run
  EXPECT_FALSE(fs::exists(work)) << work;
  EXPECT_NE(ReadFile(log).find("signal 15"), std::string::npos) << ReadFile(log);
}

}  // namespace
}  // namespace flexbench::testing
