// A sweep on a real Slurm. The fixture starts a single-node cluster (munged,
// slurmctld, slurmd from Debian's packages) inside the test's temporary folder and stops it at
// the end; the sweep's tasks are scheduled by Slurm itself. When a daemon cannot start, the test
// fails with the daemon's log line; it never skips.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <nlohmann/json.hpp>
#include <thread>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string Trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s;
}

std::string Tail(const fs::path& log, int lines = 3) {
  const CommandResult r = RunCommand("tail -n " + std::to_string(lines) + " " + log.string());
  return r.out.empty() ? "(no log at " + log.string() + ")" : r.out;
}

class SlurmCluster : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* tool : {"munged", "mungekey", "slurmctld", "slurmd", "sbatch", "squeue"}) {
      ASSERT_EQ(RunCommand(std::string("command -v ") + tool).exit_code, 0)
          << tool << " is not installed (scripts/setup.sh installs munge, slurmctld, slurmd, "
          << "slurm-client)";
    }
    dir_ = tmp_.path();
    for (const char* d : {"munge", "state", "spool", "log"}) fs::create_directories(dir_ / d);
    fs::permissions(dir_ / "munge", fs::perms::owner_all);
    const fs::path key = dir_ / "munge" / "munge.key";
    CommandResult r = RunCommand("mungekey -c -k " + key.string());
    ASSERT_EQ(r.exit_code, 0) << "mungekey: " << r.err;
    fs::permissions(key, fs::perms::owner_read | fs::perms::owner_write);
    socket_ = dir_ / "munge" / "munge.sock";
    r = RunCommand("munged -f --key-file=" + key.string() + " --socket=" + socket_.string() +
                   " --pid-file=" + (dir_ / "munge" / "munged.pid").string() +
                   " --log-file=" + (dir_ / "log" / "munged.log").string() +
                   " --seed-file=" + (dir_ / "munge" / "munged.seed").string());
    ASSERT_EQ(r.exit_code, 0) << "munged did not start: " << r.err
                              << Tail(dir_ / "log" / "munged.log");
    munged_ = true;
    char host[256] = {};
    gethostname(host, sizeof(host) - 1);
    std::string short_host = host;
    short_host = short_host.substr(0, short_host.find('.'));
    // Ports of this test process: two clusters on one machine do not meet.
    const int port = 20000 + static_cast<int>(getpid() % 10000) * 2;
    conf_ = dir_ / "slurm.conf";
    const unsigned cpus = std::max(1u, std::thread::hardware_concurrency());
    WriteFile(conf_,
              "ClusterName=flexbench\nSlurmctldHost=" + short_host +
                  "\nSlurmUser=root\nSlurmdUser=root\nAuthType=auth/munge\n"
                  "AuthInfo=socket=" +
                  socket_.string() +
                  "\nCredType=cred/munge\n"
                  "ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\n"
                  "SelectType=select/cons_tres\nSchedulerType=sched/backfill\n"
                  "MpiDefault=none\nReturnToService=2\nJobAcctGatherType=jobacct_gather/none\n"
                  "AccountingStorageType=accounting_storage/none\n"
                  "StateSaveLocation=" +
                  (dir_ / "state").string() + "\nSlurmdSpoolDir=" + (dir_ / "spool").string() +
                  "\nSlurmctldPidFile=" + (dir_ / "slurmctld.pid").string() +
                  "\nSlurmdPidFile=" + (dir_ / "slurmd.pid").string() +
                  "\nSlurmctldLogFile=" + (dir_ / "log" / "slurmctld.log").string() +
                  "\nSlurmdLogFile=" + (dir_ / "log" / "slurmd.log").string() + "\nSlurmctldPort=" +
                  std::to_string(port) + "\nSlurmdPort=" + std::to_string(port + 1) +
                  "\nNodeName=" + short_host + " CPUs=" + std::to_string(cpus) +
                  " RealMemory=2000 State=UNKNOWN\n"
                  "PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n");
    r = RunCommand("slurmctld -f " + conf_.string());
    ASSERT_EQ(r.exit_code, 0) << "slurmctld did not start: " << r.err
                              << Tail(dir_ / "log" / "slurmctld.log");
    ctld_ = true;
    r = RunCommand("slurmd -f " + conf_.string());
    ASSERT_EQ(r.exit_code, 0) << "slurmd did not start: " << r.err
                              << Tail(dir_ / "log" / "slurmd.log");
    slurmd_ = true;
    // The node reports idle within seconds.
    std::string state;
    for (int i = 0; i < 100; ++i) {
      state = Trim(RunCommand(Env() + "sinfo -h -o %t").out);
      if (state == "idle") break;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
    ASSERT_EQ(state, "idle") << "the node did not come up; slurmctld: "
                             << Tail(dir_ / "log" / "slurmctld.log")
                             << " slurmd: " << Tail(dir_ / "log" / "slurmd.log");
  }

  void TearDown() override {
    for (const auto& [up, pid_file] :
         {std::pair{slurmd_, dir_ / "slurmd.pid"}, std::pair{ctld_, dir_ / "slurmctld.pid"}}) {
      if (!up) continue;
      const int pid = std::atoi(ReadFile(pid_file).c_str());
      if (pid > 0) kill(pid, SIGTERM);
    }
    if (munged_) RunCommand("munged -s --socket=" + socket_.string());
    // The daemons are gone before their folder is.
    for (int i = 0; i < 50; ++i) {
      if (RunCommand("pgrep -f " + conf_.string()).exit_code != 0) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }

  std::string Env() const { return "SLURM_CONF=" + conf_.string() + " "; }
  std::string Flexbench() const { return BinDir() + "/flexbench"; }

  fs::path SweepFile(const std::string& name, const std::string& grid) {
    const fs::path f = dir_ / (name + ".yaml");
    WriteFile(f, "sweep: " + name + "\nscenario: " + SourceDir() +
                     "/scenarios/humanoid_table_contact.yaml\nseeds: {from: 1, to: 4}\n" + grid);
    return f;
  }

  TempDir tmp_;
  fs::path dir_, conf_, socket_;
  bool munged_ = false, ctld_ = false, slurmd_ = false;
};

TEST_F(SlurmCluster, SweepOnSlurmEqualsTheLocalSweep) {
  const fs::path file = SweepFile("on_slurm", "grid:\n  distance_std_m: [0.001, 0.002]\n");
  CommandResult local = RunCommand(Flexbench() + " sweep " + file.string() + " --out " +
                                   (dir_ / "local").string() + " -j 2");
  ASSERT_EQ(local.exit_code, 0) << local.err;
  const CommandResult r =
      RunCommand(Env() + "timeout 300 " + Flexbench() + " sweep " + file.string() + " --out " +
                 (dir_ / "slurm").string() +
                 " --executor slurm --tasks 4 --partition debug --time 10 " + "--mem 200");
  ASSERT_EQ(r.exit_code, 0) << r.err << Tail(dir_ / "log" / "slurmctld.log");
  EXPECT_NE(r.err.find("submitted Slurm job"), std::string::npos) << r.err;
  const std::string job = ReadFile(dir_ / "slurm" / "slurm" / "job.sh");
  for (const char* line :
       {"#SBATCH --array=0-3", "#SBATCH --partition='debug'", "#SBATCH --time='10'",
        "#SBATCH --mem='200'", "--shard \"$SLURM_ARRAY_"}) {
    EXPECT_NE(job.find(line), std::string::npos) << line << "\n" << job;
  }
  for (int i = 0; i < 4; ++i) {  // every task ran its shard
    EXPECT_EQ(Trim(ReadFile(dir_ / "slurm" / "slurm" / ("task_" + std::to_string(i) + ".exit"))),
              "0");
  }
  EXPECT_EQ(ReadFile(dir_ / "slurm" / "sweep.csv"), ReadFile(dir_ / "local" / "sweep.csv"));
  EXPECT_EQ(ReadFile(dir_ / "slurm" / "aggregate.json"),
            ReadFile(dir_ / "local" / "aggregate.json"));
}

// sbatch reads the job script's quoted #SBATCH values and the escaped % of an --out with
// spaces, quotes, $(...) and Slurm's own patterns: every task's output lands in its own file
// in that folder, and nothing in the name is run.
TEST_F(SlurmCluster, AnOutWithSpacesQuotesAndPercentWorks) {
  const fs::path file = SweepFile("hostile_out", "");
  const fs::path out = dir_ / "my results %j %a 'q' $(touch PWNED)";
  const std::string quoted =
      "'" + (dir_ / "my results %j %a ").string() + "'\\''q'\\'' " + "$(touch PWNED)'";
  const CommandResult r =
      RunCommand("cd " + dir_.string() + " && " + Env() + "timeout 300 " + Flexbench() + " sweep " +
                 file.string() + " --out " + quoted +
                 " --executor slurm --tasks 2 --partition debug --time 0:10:00 --mem 200M");
  ASSERT_EQ(r.exit_code, 0) << r.err << Tail(dir_ / "log" / "slurmctld.log");
  EXPECT_FALSE(fs::exists(dir_ / "PWNED"));
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(Trim(ReadFile(out / "slurm" / ("task_" + std::to_string(i) + ".exit"))), "0");
    EXPECT_TRUE(fs::is_regular_file(out / "slurm" / ("task_" + std::to_string(i) + ".out")))
        << "task " << i;
  }
  Json a = Json::parse(ReadFile(out / "aggregate.json"));
  EXPECT_EQ(a["succeeded"], 4);
}

TEST_F(SlurmCluster, AFailedTaskIsListedAndResubmittedAlone) {
  const fs::path file = SweepFile("resubmit", "");
  const fs::path out = dir_ / "out";
  // Run 1 (seed 2) belongs to task 1 of 2; a file in place of its folder makes it fail.
  WriteFile(out / ".flexbench-sweep", "resubmit\n");
  WriteFile(out / "runs/base/seed_2", "in the way\n");
  const std::string cmd = Env() + "timeout 300 " + Flexbench() + " sweep " + file.string() +
                          " --out " + out.string() + " --executor slurm --tasks 2";
  CommandResult r = RunCommand(cmd);
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("task 1 ended FAILED"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("task 0 ended"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--tasks 2 --array 1"), std::string::npos) << r.err;
  Json a = Json::parse(ReadFile(out / "aggregate.json"));
  ASSERT_EQ(a["failed"].size(), 1u);
  EXPECT_EQ(a["failed"][0]["seed"], 2);

  fs::remove(out / "runs/base/seed_2");
  r = RunCommand(cmd + " --array 1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  a = Json::parse(ReadFile(out / "aggregate.json"));
  EXPECT_EQ(a["failed"].size(), 0u);
  EXPECT_EQ(a["succeeded"], 4);
  const CommandResult local = RunCommand(Flexbench() + " sweep " + file.string() + " --out " +
                                         (dir_ / "local").string() + " -j 2");
  ASSERT_EQ(local.exit_code, 0) << local.err;
  EXPECT_EQ(ReadFile(out / "sweep.csv"), ReadFile(dir_ / "local" / "sweep.csv"));
}

}  // namespace
}  // namespace flexbench::testing
