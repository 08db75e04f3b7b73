#include "scenarios/sweep/slurm_executor.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
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

constexpr int kMaxSlurmTasks = 100000;

bool AllDigits(const std::string& s, size_t max_len = 9) {
  return !s.empty() && s.size() <= max_len &&
         std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (;;) {
    const size_t at = s.find(sep, start);
    parts.push_back(s.substr(start, at == std::string::npos ? std::string::npos : at - start));
    if (at == std::string::npos) return parts;
    start = at + 1;
  }
}

bool IsPartitionList(const std::string& s) {
  if (s.size() > 1000) return false;
  for (const std::string& name : Split(s, ',')) {
    if (name.empty() || !std::all_of(name.begin(), name.end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-';
        })) {
      return false;
    }
  }
  return true;
}

// sbatch --time: MINUTES, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS.
bool IsSlurmTime(const std::string& s) {
  if (s == "UNLIMITED" || s == "INFINITE") return true;
  std::string clock = s;
  const size_t dash = s.find('-');
  if (dash != std::string::npos) {
    if (!AllDigits(s.substr(0, dash))) return false;
    clock = s.substr(dash + 1);
  }
  const std::vector<std::string> parts = Split(clock, ':');
  if (parts.size() > 3) return false;
  return std::all_of(parts.begin(), parts.end(), [](const std::string& p) { return AllDigits(p); });
}

bool IsSlurmMemory(const std::string& s) {
  std::string digits = s;
  if (!s.empty() && std::string("KMGTkmgt").find(s.back()) != std::string::npos) {
    digits.pop_back();
  }
  return AllDigits(digits, 15);
}

bool IsIndexList(const std::string& s) {
  if (s.size() > 10000) return false;
  for (const std::string& item : Split(s, ',')) {
    const size_t dash = item.find('-');
    if (dash == std::string::npos
            ? !AllDigits(item)
            : !AllDigits(item.substr(0, dash)) || !AllDigits(item.substr(dash + 1))) {
      return false;
    }
  }
  return true;
}

// Slurm expands %a, %j, ... in --output; a literal % is %%.
std::string EscapeSlurmPattern(const std::string& s) {
  std::string out;
  for (char c : s) out += c == '%' ? std::string("%%") : std::string(1, c);
  return out;
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

void CheckSlurmOptions(const SlurmOptions& o) {
  const auto fail = [](const std::string& option, const std::string& value,
                       const std::string& expected) {
    throw InputError(option + " '" + CapForMessage(value) + "': expected " + expected);
  };
  if (o.tasks_given && (o.tasks < 1 || o.tasks > kMaxSlurmTasks)) {
    throw InputError("--tasks " + std::to_string(o.tasks) + ": must be between 1 and " +
                     std::to_string(kMaxSlurmTasks));
  }
  if (!o.partition.empty() && !IsPartitionList(o.partition)) {
    fail("--partition", o.partition,
         "partition names of letters, digits, '_', '.' and '-', "
         "comma-separated");
  }
  if (!o.time.empty() && !IsSlurmTime(o.time)) {
    fail("--time", o.time, "MINUTES, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS or UNLIMITED");
  }
  if (!o.mem.empty() && !IsSlurmMemory(o.mem)) {
    fail("--mem", o.mem, "a size in megabytes, or digits with a K, M, G or T suffix");
  }
  if (!o.array.empty() && !IsIndexList(o.array)) {
    fail("--array", o.array, "task indices and ranges, comma-separated (e.g. 3,5,7-9)");
  }
}

void CheckSlurmOut(const fs::path& out) {
  const std::string path = fs::absolute(out).lexically_normal().string();
  for (unsigned char c : path) {
    // An #SBATCH line ends at a newline, and a backslash turns off Slurm's %a in --output.
    if (c < 0x20 || c == 0x7f || c == '\\') {
      throw InputError("--out " + CapForMessage(path) +
                       ": a control character or a backslash cannot be passed to Slurm's "
                       "--output; choose another folder");
    }
  }
}

std::string SlurmJobScript(const SweepSpec& spec, const fs::path& out, const SlurmOptions& o, int n,
                           const std::string& exe) {
  const fs::path abs_out = fs::absolute(out).lexically_normal();
  const fs::path dir = abs_out / "slurm";
  // sbatch reads an #SBATCH line as words with the shell's quotes (and a backslash escape), so
  // ShellQuote suits it as well as bash; % is Slurm's file-name pattern character.
  const std::string output = EscapeSlurmPattern(dir.string()) + "/task_%a.out";
  std::ostringstream job;
  job << "#!/bin/bash\n"
      << "# flexbench sweep " << spec.name << ": task i of the array runs shard i/" << n << ".\n"
      << "#SBATCH --job-name=" << ShellQuote("flexbench-" + spec.name) << "\n"
      << "#SBATCH --array=0-" << n - 1 << "\n"
      << "#SBATCH --output=" << ShellQuote(output) << "\n"
      << "#SBATCH --error=" << ShellQuote(output) << "\n"
      << "#SBATCH --cpus-per-task=1\n";
  if (!o.partition.empty()) job << "#SBATCH --partition=" << ShellQuote(o.partition) << "\n";
  if (!o.time.empty()) job << "#SBATCH --time=" << ShellQuote(o.time) << "\n";
  if (!o.mem.empty()) job << "#SBATCH --mem=" << ShellQuote(o.mem) << "\n";
  job << ShellQuote(exe) << " sweep "
      << ShellQuote(fs::absolute(spec.file).lexically_normal().string()) << " --out "
      << ShellQuote(abs_out.string()) << (spec.run_data_files ? "" : " --run-files summary")
      << " --shard \"$SLURM_ARRAY_TASK_ID/" << n << "\" -j 1\n"
      << "rc=$?\n"
      << "echo $rc > " << ShellQuote((dir / "task_").string()) << "\"$SLURM_ARRAY_TASK_ID"
      << ".exit\"\n"
      << "exit $rc\n";
  return job.str();
}

std::string SubmitSlurm(const SweepSpec& spec, size_t run_count, const fs::path& out,
                        const SlurmOptions& o, int* task_count) {
  CheckSlurmOptions(o);
  CheckSlurmOut(out);
  const int n = o.tasks > 0 ? o.tasks : static_cast<int>(std::min<size_t>(run_count, 64));
  *task_count = n;
  const fs::path abs_out = fs::absolute(out).lexically_normal();
  const fs::path dir = abs_out / "slurm";
  fs::create_directories(dir);
  WriteFileAtomic(dir / "job.sh", SlurmJobScript(spec, out, o, n, SelfExe()));
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
