#include "scenarios/sweep/local_executor.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <string>

#include "scenarios/runner/output.h"
#include "scenarios/runner/runner.h"
#include "scenarios/runner/scenario_kind.h"
#include "scenarios/sweep/collect.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios::sweep {
namespace {

std::string LastLine(const fs::path& log) {
  std::ifstream in(log);
  std::string line, last;
  while (std::getline(in, line)) {
    if (!line.empty()) last = line;
  }
  return CapForMessage(last, 500);
}

// The child: the run's stdout and stderr into its log, RunScenario in this process (the
// parent already checked the scenario), _exit with its code so no parent state is flushed.
[[noreturn]] void RunChild(const SweepSpec& spec, const SweepPoint& point, const SweepRun& run,
                           const fs::path& out, const fs::path& log) {
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd >= 0) {
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::close(fd);
  }
  RunOptions o;
  o.scenario_path = spec.scenario;
  o.out_dir = (out / run.dir).string();
  o.seed = run.seed;
  o.set = spec.set;
  o.set.insert(o.set.end(), point.set.begin(), point.set.end());
  const int rc = RunScenario(o);
  std::fflush(stdout);
  std::fflush(stderr);
  ::_exit(rc);
}

class Progress {
 public:
  explicit Progress(size_t total)
      : total_(total), tty_(isatty(fileno(stderr))), start_(std::chrono::steady_clock::now()) {}

  void Update(size_t done, size_t failed) {
    const double t =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double rate = t > 0 ? done / t : 0.0;
    const double eta = rate > 0 ? (total_ - done) / rate : 0.0;
    // On a terminal every run; in a log about every 10% and the last.
    const size_t decile = total_ ? done * 10 / total_ : 10;
    if (!tty_ && decile == last_decile_ && done != total_) return;
    last_decile_ = decile;
    std::fprintf(stderr, "%s[sweep] %zu/%zu runs%s, %.2f runs/s, ETA %.0f s%s", tty_ ? "\r" : "",
                 done, total_, failed ? (", " + std::to_string(failed) + " failed").c_str() : "",
                 rate, eta, tty_ && done != total_ ? "" : "\n");
    std::fflush(stderr);
  }

 private:
  size_t total_;
  bool tty_;
  std::chrono::steady_clock::time_point start_;
  size_t last_decile_ = static_cast<size_t>(-1);
};

void RecordOutcome(const SweepRun& run, const std::vector<SweepPoint>& points, const fs::path& out,
                   int status, size_t* failed) {
  const fs::path failure = out / FailurePath(run, points);
  std::error_code ec;
  const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0 &&
                  fs::is_regular_file(out / run.dir / "summary.json", ec);
  if (ok) {
    fs::remove(failure, ec);
    return;
  }
  ++*failed;
  Json f;
  f["exit_code"] = WIFEXITED(status) ? Json(WEXITSTATUS(status)) : Json();
  f["signal"] = WIFSIGNALED(status) ? Json(WTERMSIG(status)) : Json();
  f["error"] = LastLine(out / LogPath(run, points));
  f["log"] = LogPath(run, points);
  fs::create_directories(failure.parent_path());
  WriteFileAtomic(failure, f.dump(2) + "\n");
  std::fprintf(stderr, "%s[sweep] run %s failed (%s): %s\n", isatty(fileno(stderr)) ? "\n" : "",
               run.dir.c_str(),
               WIFEXITED(status) ? ("exit " + std::to_string(WEXITSTATUS(status))).c_str()
                                 : ("signal " + std::to_string(WTERMSIG(status))).c_str(),
               f["error"].get<std::string>().c_str());
}

}  // namespace

std::vector<size_t> PendingRuns(const fs::path& out, const std::vector<SweepRun>& runs,
                                int shard_index, int shard_count) {
  std::vector<size_t> todo;
  for (size_t k = 0; k < runs.size(); ++k) {
    if (shard_count > 0 && static_cast<int>(k % shard_count) != shard_index) continue;
    std::error_code ec;
    if (!fs::is_regular_file(out / runs[k].dir / "summary.json", ec)) todo.push_back(k);
  }
  return todo;
}

int RunLocal(const SweepSpec& spec, const std::vector<SweepPoint>& points,
             const std::vector<SweepRun>& runs, const std::vector<size_t>& todo,
             const fs::path& out, int jobs) {
  Progress progress(todo.size());
  std::map<pid_t, size_t> running;
  size_t next = 0, done = 0, failed = 0;
  std::fflush(stdout);
  std::fflush(stderr);
  while (done < todo.size()) {
    while (next < todo.size() && static_cast<int>(running.size()) < jobs) {
      const SweepRun& run = runs[todo[next]];
      const fs::path log = out / LogPath(run, points);
      fs::create_directories(log.parent_path());
      fs::create_directories((out / run.dir).parent_path());
      const pid_t pid = ::fork();
      if (pid < 0) throw std::runtime_error("fork failed");
      if (pid == 0) RunChild(spec, points[run.point], run, out, log);
      running[pid] = todo[next++];
    }
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, 0);
    if (pid < 0) throw std::runtime_error("waitpid failed");
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    RecordOutcome(runs[it->second], points, out, status, &failed);
    running.erase(it);
    progress.Update(++done, failed);
  }
  return static_cast<int>(failed);
}

}  // namespace flexbench::scenarios::sweep
