// Helpers shared by the test suites: running the flexbench binary, temporary folders, files.
#pragma once

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <climits>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "estimators/error.h"

namespace flexbench::testing {

inline std::string SourceDir() { return FLEXBENCH_SOURCE_DIR; }
inline std::string BinDir() { return FLEXBENCH_BIN_DIR; }
inline std::string Flexbench() { return BinDir() + "/flexbench"; }

// The last non-empty line of a command's stderr: the error line.
inline std::string LastLine(std::string err) {
  while (!err.empty() && err.back() == '\n') err.pop_back();
  const size_t nl = err.rfind('\n');
  return nl == std::string::npos ? err : err.substr(nl + 1);
}

// A child running `args` (args[0] a path), stdin from /dev/null, stdout and stderr into `log`,
// SIGTERM, SIGINT and SIGHUP at their default action (as from a shell). `own_group`: in a process
// group of its own, so that a kill of the group reaches a sweep's workers too, as a power cut or
// the OOM killer taking the group would.
inline pid_t Spawn(const std::vector<std::string>& args, const std::filesystem::path& log,
                   bool own_group = false) {
  std::fflush(stdout);  // or the child's freopen writes this process's buffered lines again
  std::fflush(stderr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    if (own_group) ::setpgid(0, 0);
    for (int sig : {SIGTERM, SIGINT, SIGHUP}) ::signal(sig, SIG_DFL);
    std::freopen("/dev/null", "r", stdin);
    std::freopen(log.c_str(), "w", stdout);
    std::freopen(log.c_str(), "a", stderr);
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

// The children of `parent` now (a sweep's workers), from /proc/<pid>/stat.
inline std::vector<pid_t> ChildrenOf(pid_t parent) {
  std::vector<pid_t> children;
  std::error_code ec;
  for (std::filesystem::directory_iterator it("/proc", ec), end; !ec && it != end;
       it.increment(ec)) {
    const std::string name = it->path().filename();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream stat(it->path() / "stat");
    std::string line;
    if (!std::getline(stat, line)) continue;
    // pid (comm) state ppid ...: comm may hold spaces, so read after the last ')'.
    std::istringstream rest(line.substr(line.rfind(')') + 1));
    std::string state;
    pid_t ppid = 0;
    if (rest >> state >> ppid && ppid == parent) children.push_back(std::stoi(name));
  }
  return children;
}

// Regular files below `dir` now (0 when it does not exist or is moved away meanwhile).
inline int FilesIn(const std::filesystem::path& dir) {
  int n = 0;
  std::error_code ec;
  for (std::filesystem::recursive_directory_iterator it(dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    n += it->is_regular_file(ec);
  }
  return n;
}

// The message of the InputError that f throws; "" when it throws none.
inline std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

struct CommandResult {
  int exit_code = -1;
  std::string out;  // stdout
  std::string err;  // stderr
};

// Runs a shell command, capturing stdout and stderr separately.
inline CommandResult RunCommand(const std::string& command) {
  const std::filesystem::path err_file =
      std::filesystem::temp_directory_path() /
      ("flexbench_stderr_" + std::to_string(std::random_device{}()) + ".txt");
  CommandResult r;
  const std::string full = command + " 2>" + err_file.string();
  FILE* pipe = popen(full.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(err_file);
  std::stringstream ss;
  ss << in.rdbuf();
  r.err = ss.str();
  std::filesystem::remove(err_file);
  return r;
}

inline std::string ReadFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline void WriteFile(const std::filesystem::path& p, const std::string& text) {
  std::filesystem::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

// A fresh temporary folder, removed at scope exit.
class TempDir {
 public:
  TempDir() {
    path_ = std::filesystem::temp_directory_path() /
            ("flexbench_test_" + std::to_string(std::random_device{}()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline int CountLines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

// A process as an output temporary's marker names it (scenarios/runner/output.h): this host,
// this PID namespace, and the start time of a live process.
inline std::string Host() {
  char h[HOST_NAME_MAX + 1] = {};
  gethostname(h, sizeof(h) - 1);
  return h;
}
inline std::string PidNamespace() {
  char ns[256];
  const ssize_t n = readlink("/proc/self/ns/pid", ns, sizeof(ns) - 1);
  return n > 0 ? std::string(ns, static_cast<size_t>(n)) : "";
}
inline unsigned long long StartTime(pid_t pid) {
  const std::string stat = ReadFile("/proc/" + std::to_string(pid) + "/stat");
  std::istringstream f(stat.substr(stat.rfind(')') + 2));
  std::string field;
  for (int k = 3; k <= 22; ++k) f >> field;
  return std::stoull(field);
}
// The text of a temporary's marker.
inline std::string Marker(const std::string& host, const std::string& ns, long pid,
                          unsigned long long start) {
  return "flexbench temporary folder\nhost=" + host + "\npid_namespace=" + ns +
         "\npid=" + std::to_string(pid) + "\nstart_time=" + std::to_string(start) + "\n";
}

}  // namespace flexbench::testing
