#include "scenarios/sweep/slurm_executor.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "scenarios/runner/output.h"
#include "sim/config.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios::sweep {
namespace {

std::string ShellQuote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

bool OnPath(const std::string& program) {
  const char* path = std::getenv("PATH");
  std::stringstream ss(path ? path : "");
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (!dir.empty() && ::access((fs::path(dir) / program).c_str(), X_OK) == 0) return true;
  }
  return false;
}

// Runs a shell command; its stdout, and its exit status in *status.
std::string Capture(const std::string& command, int* status) {
  std::string out;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (!p) {
    *status = -1;
    return out;
  }
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int rc = ::pclose(p);
  *status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  return out;
}

std::string Trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ' || s.back() == '\r')) s.pop_back();
  return s;
}

std::string SelfExe() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw std::runtime_error("cannot find the flexbench executable (/proc/self/exe)");
  return p.string();
}

// "key=value" tokens of one `scontrol -o` line.
std::map<std::string, std::string> Tokens(const std::string& line) {
  std::map<std::string, std::string> t;
  std::stringstream ss(line);
  std::string tok;
  while (ss >> tok) {
    const size_t eq = tok.find('=');
    if (eq != std::string::npos) t[tok.substr(0, eq)] = tok.substr(eq + 1);
  }
  return t;
}

}  // namespace

void CheckSlurmClients() {
  for (const char* tool : {"sbatch", "squeue"}) {
    if (!OnPath(tool)) {
      throw InputError(std::string("--executor slurm: ") + tool +
                       " not found on PATH (install Slurm's clients: apt-get install "
                       "slurm-client)");
    }
  }
}

std::string SubmitSlurm(const SweepSpec& spec, size_t run_count, const fs::path& out,
                        const SlurmOptions& o, int* task_count) {
  const int n = o.tasks > 0 ? o.tasks : static_cast<int>(std::min<size_t>(run_count, 64));
  *task_count = n;
  const fs::path abs_out = fs::absolute(out).lexically_normal();
  const fs::path dir = abs_out / "slurm";
  fs::create_directories(dir);
  std::ostringstream job;
  job << "#!/bin/bash\n"
      << "# flexbench sweep " << spec.name << ": task i of the array runs shard i/" << n << ".\n"
      << "#SBATCH --job-name=flexbench-" << spec.name << "\n"
      << "#SBATCH --array=0-" << n - 1 << "\n"
      << "#SBATCH --output=" << (dir / "task_%a.out").string() << "\n"
      << "#SBATCH --cpus-per-task=1\n";
  if (!o.partition.empty()) job << "#SBATCH --partition=" << o.partition << "\n";
  if (!o.time.empty()) job << "#SBATCH --time=" << o.time << "\n";
  if (!o.mem.empty()) job << "#SBATCH --mem=" << o.mem << "\n";
  job << ShellQuote(SelfExe()) << " sweep "
      << ShellQuote(fs::absolute(spec.file).lexically_normal().string()) << " --out "
      << ShellQuote(abs_out.string()) << " --shard \"$SLURM_ARRAY_TASK_ID/" << n << "\" -j 1\n"
      << "rc=$?\n"
      << "echo $rc > " << ShellQuote((dir / "task_").string()) << "\"$SLURM_ARRAY_TASK_ID"
      << ".exit\"\n"
      << "exit $rc\n";
  WriteFileAtomic(dir / "job.sh", job.str());
  // A resubmitted task writes its exit file again.
  for (int i = 0; i < n; ++i) {
    std::error_code ec;
    if (o.array.empty()) fs::remove(dir / ("task_" + std::to_string(i) + ".exit"), ec);
  }
  std::string cmd = "sbatch --parsable";
  if (!o.array.empty()) cmd += " --array=" + ShellQuote(o.array);
  cmd += " " + ShellQuote((dir / "job.sh").string());
  int status = 0;
  const std::string reply = Trimmed(Capture(cmd, &status));
  if (status != 0) throw InputError("sbatch refused the sweep's job: " + CapForMessage(reply));
  const std::string id = reply.substr(0, reply.find(';'));  // "id;cluster" on some setups
  std::ofstream(dir / "jobs.txt", std::ios::app)
      << id << (o.array.empty() ? "" : " " + o.array) << "\n";
  return id;
}

std::vector<SlurmTaskEnd> WaitForSlurm(const std::string& job_id, int task_count,
                                       const fs::path& out) {
  for (;;) {
    int status = 0;
    const std::string q = Trimmed(Capture("squeue -h -o %i -j " + ShellQuote(job_id), &status));
    // squeue exits non-zero for a job id it no longer knows: the job has left the queue.
    if (status != 0 || q.empty()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
  }
  std::map<int, SlurmTaskEnd> ends;
  int status = 0;
  const std::string shown = Capture("scontrol -o show job " + ShellQuote(job_id), &status);
  if (status == 0) {
    std::stringstream ss(shown);
    std::string line;
    while (std::getline(ss, line)) {
      const auto t = Tokens(line);
      if (!t.count("ArrayTaskId") || !t.count("JobState")) continue;
      SlurmTaskEnd e;
      e.index = std::atoi(t.at("ArrayTaskId").c_str());
      e.state = t.at("JobState");
      if (t.count("ExitCode")) e.exit_code = std::atoi(t.at("ExitCode").c_str());
      ends[e.index] = e;
    }
  }
  // Tasks the controller no longer reports: their exit files.
  for (int i = 0; i < task_count; ++i) {
    std::ifstream in(out / "slurm" / ("task_" + std::to_string(i) + ".exit"));
    int rc = -1;
    if (!(in >> rc)) continue;
    if (!ends.count(i)) ends[i] = {i, rc == 0 ? "COMPLETED" : "FAILED", rc};
  }
  std::vector<SlurmTaskEnd> v;
  for (const auto& [i, e] : ends) v.push_back(e);
  return v;
}

}  // namespace flexbench::scenarios::sweep
