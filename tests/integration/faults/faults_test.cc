// Faults mid-run. `flexbench run` and `flexbench sweep` are killed with
// SIGKILL at random points (a fixed seed draws the times); the output is then either absent or
// a complete result, never a partial one, and the next run leaves no temporary folder behind.
// A killed sweep, resumed, ends with the same sweep.csv as an uninterrupted one. A full disk
// (a small tmpfs) is one error line and leaves nothing partial.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using Json = nlohmann::json;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

struct Ended {
  bool killed = false;  // false: it exited by itself before the kill time
  int status = 0;
};

// Waits until the child exits, or `stop()` says so (then SIGKILL to its group).
template <class Stop>
Ended KillWhen(pid_t pid, Stop stop) {
  Ended e;
  for (;;) {
    if (::waitpid(pid, &e.status, WNOHANG) == pid) return e;
    if (stop()) break;
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
  if (::kill(-pid, SIGKILL) != 0) ::kill(pid, SIGKILL);
  ::waitpid(pid, &e.status, 0);
  e.killed = WIFSIGNALED(e.status) && WTERMSIG(e.status) == SIGKILL;
  return e;
}

// Every regular file below `dir`, by relative path, with its bytes.
std::map<std::string, std::string> Files(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = ReadFile(e.path());
  }
  return out;
}

// summary.json without its wall-clock timing (the one part that differs between runs).
Json Untimed(const std::string& summary) {
  Json j = Json::parse(summary);
  j.erase("timing");
  return j;
}

// Names next to `dir` that a run of it leaves while it works: <dir>.tmp-PID, <dir>.old-PID.
std::vector<std::string> Temporaries(const fs::path& dir) {
  std::vector<std::string> out;
  const std::string name = dir.filename().string();
  for (const auto& e : fs::directory_iterator(dir.parent_path())) {
    const std::string f = e.path().filename().string();
    if (f.rfind(name + ".tmp-", 0) == 0 || f.rfind(name + ".old-", 0) == 0) out.push_back(f);
  }
  return out;
}

// A result folder is complete: summary.json parses, every file report.html links exists, and
// no half-written ".part" file is inside.
void ExpectComplete(const fs::path& dir) {
  ASSERT_TRUE(fs::is_regular_file(dir / "summary.json")) << dir;
  EXPECT_NO_THROW(Json::parse(ReadFile(dir / "summary.json"))) << dir;
  const std::string report = ReadFile(dir / "report.html");
  ASSERT_FALSE(report.empty()) << dir;
  const std::regex link("(?:href|src)=\"([^\"#:]+)\"");
  int links = 0;
  for (std::sregex_iterator it(report.begin(), report.end(), link), end; it != end; ++it) {
    ++links;
    EXPECT_TRUE(fs::exists(dir / (*it)[1].str())) << dir << ": report links " << (*it)[1];
  }
  EXPECT_GT(links, 1) << dir;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    EXPECT_NE(e.path().extension(), ".part") << e.path();
  }
}

// A long run (rover_apriltag_exp2: ~3-5 s, 40 files written as it goes: 29 rendered frames,
// then a plot, trajectories, CSV, summary, report) is killed with and without a previous result
// at --out. The kill points (seed 19) are: one random time in the first 0.3 s (loading, before
// the temporary folder exists); five random counts of files written into the temporary
// folder, from 0 to the number of frames, so that they land at the same stage on a fast or a
// slow machine; and one as summary.json appears (best effort: the last milliseconds before
// the results move into place; the run may finish first).
TEST(Faults, KilledRunLeavesNothingOrACompleteResult) {
  TempDir tmp;
  const fs::path out = tmp.path() / "out";
  const fs::path log = tmp.path() / "log.txt";
  const std::vector<std::string> args = {
      Flexbench(), "run",        SourceDir() + "/scenarios/rover_apriltag_exp2.yaml",
      "--out",     out.string(), "--quiet",
      "--frames",  "all"};
  // The reference: an uninterrupted run to the same --out (the command it records names it).
  const Clock::time_point t0 = Clock::now();
  const Ended ref = KillWhen(Spawn(args, log, true), [] { return false; });
  const double duration = Seconds(Clock::now() - t0);
  ASSERT_TRUE(WIFEXITED(ref.status) && WEXITSTATUS(ref.status) == 0) << ReadFile(log);
  ExpectComplete(out);
  const std::map<std::string, std::string> reference = Files(out);
  int frames = 0;
  for (const auto& [rel, bytes] : reference) frames += rel.rfind("frames/config_", 0) == 0;
  ASSERT_GT(frames, 10);
  const fs::path previous = tmp.path() / "previous";  // a previous result, put back at --out
  fs::copy(out, previous, fs::copy_options::recursive);

  auto expect_absent_or_reference = [&](const std::string& when) {
    SCOPED_TRACE(when);
    if (!fs::exists(out)) return;
    ExpectComplete(out);
    const std::map<std::string, std::string> now = Files(out);
    ASSERT_EQ(now.size(), reference.size());
    for (const auto& [rel, bytes] : reference) {
      ASSERT_TRUE(now.count(rel)) << rel;
      if (rel == "summary.json") {
        EXPECT_EQ(Untimed(now.at(rel)), Untimed(bytes));
      } else {
        EXPECT_TRUE(now.at(rel) == bytes) << rel << " differs from the uninterrupted run's";
      }
    }
  };

  std::mt19937 rng(19);
  std::uniform_real_distribution<double> early_s(0.0, 0.3);
  std::uniform_int_distribution<int> files_written(0, frames);
  constexpr int kRounds = 7;
  int killed = 0, absent = 0;
  for (int k = 0; k < kRounds; ++k) {
    const bool early = k == 0, targeted = k == kRounds - 1;
    // Odd rounds start from nothing at --out; even ones replace a previous result.
    const bool replace = k % 2 == 0;
    fs::remove_all(out);
    if (replace) fs::copy(previous, out, fs::copy_options::recursive);
    const double at_s = early ? early_s(rng) : 0.0;
    const int at_files = early || targeted ? 0 : files_written(rng);
    const pid_t pid = Spawn(args, log, true);
    const fs::path work =
        out.parent_path() / (out.filename().string() + ".tmp-" + std::to_string(pid));
    const Clock::time_point start = Clock::now();
    const Ended e = KillWhen(pid, [&] {
      if (early) return Seconds(Clock::now() - start) >= at_s;
      if (targeted) return fs::exists(work / "summary.json");
      return fs::exists(work) && FilesIn(work) >= at_files;
    });
    killed += e.killed;
    absent += !fs::exists(out);
    std::string point = early      ? "at " + std::to_string(at_s).substr(0, 4) + " s"
                        : targeted ? "as summary.json appeared"
                                   : "after " + std::to_string(at_files) + " files";
    std::printf("[ faults   ] run %d (%s): %s %s (%.2f s; uninterrupted %.2f s): --out %s\n", k,
                replace ? "replacing a result" : "new --out", e.killed ? "killed" : "ended",
                point.c_str(), Seconds(Clock::now() - start), duration,
                fs::exists(out) ? "holds a result" : "does not exist");
    if (!targeted) {
      EXPECT_TRUE(e.killed) << "run " << k << " ended before its kill point";
    }
    if (!e.killed) {
      EXPECT_TRUE(WIFEXITED(e.status) && WEXITSTATUS(e.status) == 0) << ReadFile(log);
    }
    expect_absent_or_reference("after kill " + std::to_string(k));
  }
  // The next run completes and removes the killed runs' temporaries (their processes are gone).
  const Ended last = KillWhen(Spawn(args, log, true), [] { return false; });
  ASSERT_TRUE(WIFEXITED(last.status) && WEXITSTATUS(last.status) == 0) << ReadFile(log);
  expect_absent_or_reference("after the last run");
  EXPECT_TRUE(fs::exists(out));
  EXPECT_EQ(Temporaries(out), std::vector<std::string>{});
  std::printf("[ faults   ] %d of %d runs killed, --out absent after %d\n", killed, kRounds,
              absent);
}

// Runs of a sweep folder that have their summary.json.
int RunsDone(const fs::path& sweep, int seeds) {
  int done = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    done += fs::exists(sweep / "runs/base" / ("seed_" + std::to_string(seed)) / "summary.json");
  }
  return done;
}

// A sweep (24 short runs, 2 workers) is killed three times, its workers with it, and resumed
// each time; the final sweep.csv and aggregate.json are the bytes of an uninterrupted sweep,
// every run folder is absent or complete after each kill, and nothing temporary is left at the
// end. The kill points (seed 1919) are counts of runs finished since the start of that attempt
// (0 to 6, so each attempt is killed before the sweep can end), which puts them at the same
// stage on a fast or a slow machine; the other worker is then mid-run.
TEST(Faults, KilledSweepResumesToTheSameBytes) {
  TempDir tmp;
  constexpr int kSeeds = 24;
  const fs::path file = tmp.path() / "sweep.yaml";
  WriteFile(file, "sweep: faults\nscenario: " + SourceDir() +
                      "/scenarios/humanoid_table_contact.yaml\nseeds: {from: 1, to: " +
                      std::to_string(kSeeds) + "}\n");
  const fs::path log = tmp.path() / "log.txt";
  auto args = [&](const fs::path& out) {
    return std::vector<std::string>{Flexbench(), "sweep", file.string(), "--out", out.string(),
                                    "-j",        "2"};
  };
  const fs::path ref = tmp.path() / "ref";
  const Ended r = KillWhen(Spawn(args(ref), log, true), [] { return false; });
  ASSERT_TRUE(WIFEXITED(r.status) && WEXITSTATUS(r.status) == 0) << ReadFile(log);

  const fs::path out = tmp.path() / "killed";
  std::mt19937 rng(1919);
  std::uniform_int_distribution<int> runs_finished(0, 6);
  for (int k = 0; k < 3; ++k) {
    const int before = RunsDone(out, kSeeds);
    const int more = runs_finished(rng);
    const Clock::time_point start = Clock::now();
    const Ended e = KillWhen(Spawn(args(out), log, true),
                             [&] { return RunsDone(out, kSeeds) >= before + more; });
    EXPECT_TRUE(e.killed) << "sweep " << k << " ended before its kill point";
    int present = 0;
    for (int seed = 1; seed <= kSeeds; ++seed) {
      const fs::path run = out / "runs/base" / ("seed_" + std::to_string(seed));
      if (!fs::exists(run)) continue;
      ++present;
      SCOPED_TRACE("after kill " + std::to_string(k));
      ExpectComplete(run);
    }
    std::printf("[ faults   ] sweep %d: %s after %d more runs (%.2f s), %d of %d runs done\n", k,
                e.killed ? "killed" : "ended", more, Seconds(Clock::now() - start), present,
                kSeeds);
  }
  const Ended resumed = KillWhen(Spawn(args(out), log, true), [] { return false; });
  ASSERT_TRUE(WIFEXITED(resumed.status) && WEXITSTATUS(resumed.status) == 0) << ReadFile(log);
  const std::string csv = ReadFile(out / "sweep.csv");
  EXPECT_EQ(CountLines(csv), kSeeds + 1);  // the header and a row per run
  EXPECT_TRUE(csv == ReadFile(ref / "sweep.csv")) << csv;
  EXPECT_TRUE(ReadFile(out / "aggregate.json") == ReadFile(ref / "aggregate.json"));
  for (const auto& e : fs::recursive_directory_iterator(out)) {
    const std::string name = e.path().filename().string();
    EXPECT_EQ(name.find(".tmp-"), std::string::npos) << e.path();
    EXPECT_EQ(name.find(".old-"), std::string::npos) << e.path();
    EXPECT_NE(e.path().extension(), ".part") << e.path();
  }
}

// A 2 MiB tmpfs at --out, mounted for this test (skipped where mounting is not permitted).
class TmpfsMount {
 public:
  explicit TmpfsMount(const fs::path& dir) : dir_(dir) {
    fs::create_directories(dir);
    const CommandResult r =
        RunCommand("mount -t tmpfs -o size=2m tmpfs " + dir.string() + " </dev/null");
    mounted_ = r.exit_code == 0;
    error_ = r.err;
  }
  ~TmpfsMount() {
    if (mounted_) RunCommand("umount " + dir_.string());
  }
  bool mounted() const { return mounted_; }
  const std::string& error() const { return error_; }

 private:
  fs::path dir_;
  bool mounted_ = false;
  std::string error_;
};

std::set<std::string> Entries(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
  return out;
}

// A full disk is an error of one line naming the file and the reason, exit 2, and leaves
// nothing at --out. First the 2 MiB tmpfs alone (rover_apriltag_exp2 writes 2.3 MB with every
// frame); then a short scenario (~180 KB of CSV, TUM, PNG, JSON, HTML) with a filler leaving 0
// to 200 KiB free, so that the disk fills up in each of its writers in turn. Where the run fits it
// is a complete result; only report.html may be missing (a report that cannot be written costs the
// page, not the run, and says so).
TEST(Faults, FullDiskIsOneLineAndLeavesNothingPartial) {
  TempDir tmp;
  const fs::path mnt = tmp.path() / "mnt";
  TmpfsMount mount(mnt);
  if (!mount.mounted()) GTEST_SKIP() << "mounting a tmpfs is not permitted here: " << mount.error();
  const fs::path out = mnt / "out";
  auto run = [&](const std::string& scenario) {
    return RunCommand(Flexbench() + " run " + SourceDir() + "/scenarios/" + scenario +
                      ".yaml --out " + out.string() + " --quiet --frames all </dev/null");
  };
  CommandResult r = run("rover_apriltag_exp2");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
  EXPECT_EQ(Entries(mnt), std::set<std::string>{});

  const std::regex failed_file("error: (\\S+): ");
  std::set<std::string> failed_in;
  int failures = 0, results = 0;
  for (int free_kib = 0; free_kib <= 200; free_kib += 8) {
    SCOPED_TRACE(std::to_string(free_kib) + " KiB free");
    fs::remove_all(out);
    {
      std::ofstream filler(mnt / "filler", std::ios::binary | std::ios::trunc);
      filler << std::string((2048 - free_kib) * 1024, '\0');
    }
    r = run("humanoid_table_contact");
    if (r.exit_code != 0) {
      ++failures;
      EXPECT_EQ(r.exit_code, 2) << r.err;
      EXPECT_EQ(CountLines(r.err), 1) << r.err;
      EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
      std::smatch m;
      if (std::regex_search(r.err, m, failed_file))
        failed_in.insert(fs::path(m[1].str()).filename().string());
      EXPECT_EQ(Entries(mnt), std::set<std::string>{"filler"});
      continue;
    }
    ++results;
    EXPECT_EQ(Entries(mnt), (std::set<std::string>{"filler", "out"}));
    ASSERT_NO_THROW(Json::parse(ReadFile(out / "summary.json")));
    for (const auto& e : fs::recursive_directory_iterator(out)) {
      EXPECT_NE(e.path().extension(), ".part") << e.path();
    }
    if (fs::exists(out / "report.html")) {
      ExpectComplete(out);
    } else {
      EXPECT_NE(r.err.find("report.html not written"), std::string::npos) << r.err;
      EXPECT_NE(r.err.find("No space left on device"), std::string::npos) << r.err;
    }
  }
  std::string writers;
  for (const std::string& f : failed_in) writers += " " + f;
  std::printf("[ faults   ] full disk: %d runs failed, %d fitted; failed writing:%s\n", failures,
              results, writers.c_str());
  // The filler steps cover both sides: runs that did not fit, and runs that did.
  EXPECT_GT(failures, 0);
  EXPECT_GT(results, 0);
  EXPECT_GE(failed_in.size(), 3u) << writers;
}

}  // namespace
}  // namespace flexbench::testing
