// Sweeps under hostile use, through the CLI: a resumed sweep reuses only results made with the
// same settings, sizes that overflow are refused, Slurm options cannot inject shell commands
// into the job script, and a SIGTERM stops the sweep's workers with it.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string Quoted(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Every command under a memory cap and a timeout, as a hostile user's would be: a defect that
// allocates without end or loops ends as a failed test, not a stuck machine.
CommandResult Sweep(const fs::path& file, const fs::path& out, const std::string& extra = "",
                    const std::string& env = "") {
  return RunCommand("ulimit -v 4000000; " + env + "timeout 120 " + Flexbench() + " sweep " +
                    Quoted(file.string()) + " --out " + Quoted(out.string()) + " " + extra +
                    " </dev/null");
}

// A copy of the contact scenario (about 0.1 s a run) and of its declared model, which a test
// may edit.
fs::path ContactScenario(const fs::path& dir) {
  const auto copy = [](std::string text, const std::string& from, const std::string& to) {
    for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + 1)) {
      text.replace(at, from.size(), to);
    }
    return text;
  };
  const fs::path declared = dir / "humanoid_upper.declared.yaml";
  WriteFile(declared, copy(ReadFile(SourceDir() + "/models/humanoid_upper.declared.yaml"),
                           "model: humanoid_upper.xml",
                           "model: " + SourceDir() + "/models/humanoid_upper.xml"));
  std::string text = ReadFile(SourceDir() + "/scenarios/humanoid_table_contact.yaml");
  text = copy(text, "../models/humanoid_upper.declared.yaml", declared.string());
  text = copy(text, "../models/", SourceDir() + "/models/");
  const fs::path s = dir / "contact.yaml";
  WriteFile(s, text);
  return s;
}

std::string SweepYaml(const fs::path& scenario, const std::string& rest) {
  return "sweep: resume_test\nscenario: " + scenario.string() + "\nseeds: [1, 2]\n" + rest;
}

// A grid value long enough for its point to be named by index (p<i>): 0.00X then zeros.
std::string LongValue(char digit) { return "0.00" + std::string(1, digit) + std::string(110, '0'); }

TEST(SweepReliability, ResumeRerunsRunsMadeWithOtherSettings) {
  TempDir tmp;
  const fs::path scenario = ContactScenario(tmp.path());
  const fs::path file = tmp.path() / "s.yaml";
  const std::string grid = "grid:\n  distance_std_m: [0.001, 0.002]\n";
  WriteFile(file, SweepYaml(scenario, grid));
  const fs::path out = tmp.path() / "out";
  CommandResult r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::is_regular_file(out / "runs/distance_std_m_0.001/seed_1/run.key"));
  const std::string csv = ReadFile(out / "sweep.csv");
  const std::string agg = ReadFile(out / "aggregate.json");

  // Unchanged: nothing to do, the same bytes.
  r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("0 runs to do"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("rerun"), std::string::npos) << r.err;
  EXPECT_EQ(ReadFile(out / "sweep.csv"), csv);
  EXPECT_EQ(ReadFile(out / "aggregate.json"), agg);

  // The scenario file edited (one comment is enough: its bytes define the runs).
  std::ofstream(scenario, std::ios::app) << "# edited\n";
  r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("4 runs rerun: scenario file changed"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("4 runs to do"), std::string::npos) << r.err;

  // A file the scenario names edited (here its declared model).
  std::ofstream(tmp.path() / "humanoid_upper.declared.yaml", std::ios::app) << "# edited\n";
  r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("4 runs rerun: an input file changed"), std::string::npos) << r.err;

  // The sweep's set: changed; the new results, not the old ones, are reported.
  WriteFile(file, SweepYaml(scenario, "set: {iterations: 5}\n" + grid));
  r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("4 runs rerun: overrides changed"), std::string::npos) << r.err;
  const fs::path fresh = tmp.path() / "fresh";
  ASSERT_EQ(Sweep(file, fresh, "-j 2").exit_code, 0);
  EXPECT_EQ(ReadFile(out / "sweep.csv"), ReadFile(fresh / "sweep.csv"));
  EXPECT_EQ(ReadFile(out / "aggregate.json"), ReadFile(fresh / "aggregate.json"));
  EXPECT_NE(ReadFile(out / "aggregate.json"), agg);

  // --collect reports no result made with other settings.
  WriteFile(file, SweepYaml(scenario, "set: {iterations: 6}\n" + grid));
  r = Sweep(file, out, "--collect");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("4 results made with other settings not collected (overrides changed)"),
            std::string::npos)
      << r.err;
}

// Points named by index: a value inserted before the others renumbers them; each run whose
// point now has another value is rerun, and the result equals a fresh sweep's.
TEST(SweepReliability, IndexNamedPointsAreNotPairedWithTheWrongRuns) {
  TempDir tmp;
  const fs::path scenario = ContactScenario(tmp.path());
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, SweepYaml(scenario, "grid:\n  distance_std_m: [" + LongValue('1') + ", " +
                                          LongValue('2') + "]\n"));
  const fs::path out = tmp.path() / "out";
  CommandResult r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(fs::is_directory(out / "runs/p1")) << r.err;
  WriteFile(file, SweepYaml(scenario, "grid:\n  distance_std_m: [" + LongValue('3') + ", " +
                                          LongValue('1') + ", " + LongValue('2') + "]\n"));
  r = Sweep(file, out, "-j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("4 runs rerun: overrides changed"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("6 runs to do"), std::string::npos) << r.err;
  const fs::path fresh = tmp.path() / "fresh";
  ASSERT_EQ(Sweep(file, fresh, "-j 2").exit_code, 0);
  EXPECT_EQ(ReadFile(out / "sweep.csv"), ReadFile(fresh / "sweep.csv"));
  EXPECT_EQ(ReadFile(out / "aggregate.json"), ReadFile(fresh / "aggregate.json"));
}

TEST(SweepReliability, OverflowingSizesAndCountsAreRefused) {
  TempDir tmp;
  const fs::path scenario = ContactScenario(tmp.path());
  const fs::path file = tmp.path() / "s.yaml";
  // 2^64 points: the product wrapped to 0 and passed the run cap.
  std::string grid = "grid:\n";
  for (int k = 0; k < 64; ++k) grid += "  key" + std::to_string(k) + ": [1, 2]\n";
  WriteFile(file, SweepYaml(scenario, grid));
  CommandResult r = Sweep(file, tmp.path() / "big");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(file.string()), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("more than 1000000 runs"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "big"));

  // A seed range ending at the largest int: two runs, not an endless loop.
  WriteFile(file, "sweep: top\nscenario: " + scenario.string() +
                      "\nseeds: {from: 2147483646, to: 2147483647}\n");
  r = Sweep(file, tmp.path() / "top", "-j 2");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("2 runs to do"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::is_regular_file(tmp.path() / "top/runs/base/seed_2147483647/summary.json"));

  // Counts that used to mean a default silently.
  WriteFile(file, SweepYaml(scenario, ""));
  const std::pair<const char*, const char*> bad[] = {
      {"--tasks 0", "--tasks 0: must be between 1 and"},
      {"--tasks -3", "--tasks -3: must be between 1 and"},
      {"--tasks=-3", "--tasks -3: must be between 1 and"},
      {"-j -1", "-j -1: must be between 1 and 1024"},
      {"-j 2000", "-j 2000: must be between 1 and 1024"}};
  for (const auto& [arg, expected] : bad) {
    const fs::path out = tmp.path() / "counts";
    r = Sweep(file, out, arg);
    EXPECT_EQ(r.exit_code, 2) << arg << ": " << r.err;
    EXPECT_NE(LastLine(r.err).find(expected), std::string::npos) << arg << ": " << r.err;
    EXPECT_FALSE(fs::exists(out / "runs")) << arg;
  }
}

// A stand-in for Slurm's clients: sbatch runs every array task of the script with bash (as
// slurmd would) and prints a job id; squeue says the job has left the queue.
void FakeSlurm(const fs::path& bin) {
  WriteFile(bin / "sbatch",
            "#!/bin/bash\n"
            "script=\"${@: -1}\"\n"
            "cp \"$script\" \"$FAKE_SLURM_COPY\"\n"
            "last=$(sed -n 's/^#SBATCH --array=0-\\([0-9]*\\)$/\\1/p' \"$script\")\n"
            "for i in $(seq 0 \"$last\"); do SLURM_ARRAY_TASK_ID=$i bash \"$script\" "
            ">/dev/null 2>&1; done\n"
            "echo 4242\n");
  WriteFile(bin / "squeue", "#!/bin/sh\nexit 0\n");
  for (const char* tool : {"sbatch", "squeue"}) {
    fs::permissions(bin / tool, fs::perms::owner_all);
  }
}

TEST(SweepReliability, SlurmOptionsCannotInjectCommandsIntoTheJobScript) {
  TempDir tmp;
  const fs::path scenario = ContactScenario(tmp.path());
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, SweepYaml(scenario, "grid:\n  distance_std_m: [0.001, 0.002]\n"));
  FakeSlurm(tmp.path() / "bin");
  const fs::path copy = tmp.path() / "job_copy.sh";
  const std::string env = "cd " + Quoted(tmp.path().string()) +
                          " && PATH=" + Quoted((tmp.path() / "bin").string()) +
                          ":$PATH FAKE_SLURM_COPY=" + Quoted(copy.string()) + " ";
  const std::pair<std::string, std::string> bad[] = {
      {"--partition \"$(printf 'debug\\ntouch PWNED')\"", "--partition 'debug touch PWNED'"},
      {"--partition 'debug;touch PWNED'", "--partition 'debug;touch PWNED'"},
      {"--partition debug,", "--partition 'debug,'"},
      {"--time \"$(printf '10\\ntouch PWNED')\"", "--time '10 touch PWNED'"},
      {"--time 1-2-3", "--time '1-2-3'"},
      {"--time 1:2:3:4", "--time '1:2:3:4'"},
      {"--mem '200 --wrap=touch'", "--mem '200 --wrap=touch'"},
      {"--mem 2X", "--mem '2X'"},
      {"--array '1;touch PWNED'", "--array '1;touch PWNED'"}};
  for (const auto& [arg, expected] : bad) {
    const fs::path out = tmp.path() / "bad";
    const CommandResult r = Sweep(file, out, "--executor slurm " + arg, env);
    EXPECT_EQ(r.exit_code, 2) << arg << ": " << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << arg << ": " << r.err;
    EXPECT_NE(r.err.find(expected), std::string::npos) << arg << ": " << r.err;
    EXPECT_FALSE(fs::exists(out)) << arg;
    EXPECT_FALSE(fs::exists(tmp.path() / "PWNED")) << arg;
  }
  // An --out Slurm's --output line cannot hold.
  CommandResult r =
      Sweep(file, tmp.path() / "new\nline", "--executor slurm --partition debug", env);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("cannot be passed to Slurm's --output"), std::string::npos) << r.err;

  // A hostile but legal --out: spaces, quotes, $(...), Slurm's % patterns. The job runs the
  // sweep there, nothing else, and the results equal a local sweep's.
  const fs::path out = tmp.path() / "my results %j %a 'q' \"d\" $(touch PWNED) `touch PWNED`";
  r = Sweep(file, out,
            "--executor slurm --tasks 2 --partition debug,gpu.x_1 --time 1-00:30 "
            "--mem 2G",
            env);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(tmp.path() / "PWNED"));
  const std::string job = ReadFile(out / "slurm" / "job.sh");
  EXPECT_EQ(ReadFile(copy), job);
  EXPECT_EQ(RunCommand("bash -n " + Quoted((out / "slurm" / "job.sh").string())).exit_code, 0)
      << job;
  const std::string slurm_dir = (out / "slurm").string();
  std::string escaped;  // % doubled, then quoted for bash and sbatch alike
  for (char c : slurm_dir) escaped += c == '%' ? std::string("%%") : std::string(1, c);
  for (const std::string& line :
       {std::string("#SBATCH --array=0-1\n"), std::string("#SBATCH --partition='debug,gpu.x_1'\n"),
        std::string("#SBATCH --time='1-00:30'\n"), std::string("#SBATCH --mem='2G'\n"),
        "#SBATCH --output=" + Quoted(escaped + "/task_%a.out") + "\n",
        " --out " + Quoted(out.string()) + " --shard \"$SLURM_ARRAY_TASK_ID/2\" -j 1\n"}) {
    EXPECT_NE(job.find(line), std::string::npos) << line << "\n" << job;
  }
  // Every line is an #SBATCH line, a comment, or one of the four commands.
  std::istringstream lines(job);
  std::string line;
  int commands = 0;
  while (std::getline(lines, line)) commands += line.empty() || line[0] == '#' ? 0 : 1;
  EXPECT_EQ(commands, 4) << job;
  const fs::path local = tmp.path() / "local";
  ASSERT_EQ(Sweep(file, local, "-j 2").exit_code, 0);
  EXPECT_EQ(ReadFile(out / "sweep.csv"), ReadFile(local / "sweep.csv"));
  EXPECT_EQ(ReadFile(out / "aggregate.json"), ReadFile(local / "aggregate.json"));
}

// Alive: in the process table and not a zombie.
bool Alive(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  std::istringstream rest(line.substr(line.rfind(')') + 1));
  std::string state;
  return rest >> state && state != "Z";
}

// Starts a sweep of runs of many seconds each (200 rendered configurations), two at a time, in
// a process group of its own; returns its pid once both workers run, and their pids.
pid_t StartSlowSweep(const fs::path& dir, std::vector<pid_t>* workers) {
  const fs::path file = dir / "s.yaml";
  WriteFile(file, "sweep: stopped\nscenario: " + SourceDir() +
                      "/scenarios/rover_apriltag_exp1.yaml\nseeds: {from: 1, to: 4}\n"
                      "set: {random_configurations.count: 200}\n");
  const std::string cmd = "exec " + Flexbench() + " sweep " + file.string() + " --out " +
                          (dir / "out").string() + " -j 2 </dev/null >/dev/null 2>" +
                          (dir / "err.txt").string();
  const pid_t sweep = ::fork();
  if (sweep == 0) {
    ::setpgid(0, 0);
    ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  for (int k = 0; k < 6000 && workers->size() < 2; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    *workers = ChildrenOf(sweep);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // both at work
  return sweep;
}

// Waits for the sweep; expects exit 128 + `sig`, no worker alive within a few seconds, and no
// run recorded as failed.
void ExpectStopped(pid_t sweep, const std::vector<pid_t>& workers, int sig, const fs::path& dir) {
  int status = 0;
  ASSERT_EQ(::waitpid(sweep, &status, 0), sweep);
  const std::string err = ReadFile(dir / "err.txt");
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 128 + sig)
      << (WIFSIGNALED(status) ? "killed by signal " + std::to_string(WTERMSIG(status))
                              : "exit " + std::to_string(WEXITSTATUS(status)))
      << "\n"
      << err;
  bool any_alive = true;
  for (int k = 0; k < 300 && any_alive; ++k) {
    any_alive = false;
    for (pid_t w : workers) any_alive = any_alive || Alive(w);
    if (any_alive) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_FALSE(any_alive) << err;
  for (pid_t w : workers) {
    if (Alive(w)) ::kill(w, SIGKILL);  // not left running by a failed test
  }
  EXPECT_NE(err.find(std::string(sig == SIGINT ? "SIGINT" : "SIGTERM") + ": stopping "),
            std::string::npos)
      << err;
  EXPECT_FALSE(fs::exists(dir / "out" / "failed")) << err;  // an interruption is no failed run
}

// SIGTERM to the sweep alone (as `kill` or a scheduler sends it).
TEST(SweepReliability, SigtermStopsTheWorkersAndExits143) {
  TempDir tmp;
  std::vector<pid_t> workers;
  const pid_t sweep = StartSlowSweep(tmp.path(), &workers);
  ASSERT_GT(sweep, 0);
  ASSERT_EQ(workers.size(), 2u) << "the workers did not start: "
                                << ReadFile(tmp.path() / "err.txt");
  ASSERT_EQ(::kill(sweep, SIGTERM), 0);
  ExpectStopped(sweep, workers, SIGTERM, tmp.path());
}

// SIGINT to the whole process group, as a terminal's Ctrl-C: the workers get it too.
TEST(SweepReliability, CtrlCStopsTheSweepWithoutRecordingFailures) {
  TempDir tmp;
  std::vector<pid_t> workers;
  const pid_t sweep = StartSlowSweep(tmp.path(), &workers);
  ASSERT_GT(sweep, 0);
  ASSERT_EQ(workers.size(), 2u) << "the workers did not start: "
                                << ReadFile(tmp.path() / "err.txt");
  ASSERT_EQ(::kill(-sweep, SIGINT), 0);
  ExpectStopped(sweep, workers, SIGINT, tmp.path());
}

}  // namespace
}  // namespace flexbench::testing
