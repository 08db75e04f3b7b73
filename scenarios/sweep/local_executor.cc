#include "scenarios/sweep/local_executor.h"

#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>
#include <string>
#include <thread>

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

// The child: the signal mask the sweep had before it blocked the signals it waits for, the
// run's stdout and stderr into its log, RunScenario in this process (the parent already checked
// the scenario), the run key beside a result, _exit with its code so no parent state is flushed.
[[noreturn]] void RunChild(const SweepSpec& spec, const SweepPoint& point, const SweepRun& run,
                           const fs::path& out, const fs::path& log, const RunKey& key,
                           const sigset_t& mask) {
  ::sigprocmask(SIG_SETMASK, &mask, nullptr);
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
  o.frames = spec.frames;
  o.data_files = spec.run_data_files;
  o.set = spec.set;
  o.set.insert(o.set.end(), point.set.begin(), point.set.end());
  int rc = RunScenario(o);
  if (rc == kExitOk) {
    try {
      WriteRunKey(out / run.dir, key);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "flexbench: error: the run's key was not written: %s\n", e.what());
      rc = kExitInternal;
    }
  }
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

PendingRunList PendingRuns(const fs::path& out, const std::vector<SweepRun>& runs,
                           const RunKeys& keys, int shard_index, int shard_count) {
  PendingRunList p;
  for (size_t k = 0; k < runs.size(); ++k) {
    if (shard_count > 0 && static_cast<int>(k % shard_count) != shard_index) continue;
    std::error_code ec;
    if (!fs::is_regular_file(out / runs[k].dir / "summary.json", ec)) {
      p.todo.push_back(k);
      continue;
    }
    const std::string why = StaleReason(out / runs[k].dir, keys.Of(runs[k]));
    if (why.empty()) continue;
    p.todo.push_back(k);
    ++p.rerun[why];
  }
  return p;
}

std::string RerunReasons(const std::map<std::string, size_t>& counts) {
  if (counts.size() == 1) return counts.begin()->first;
  std::string text;
  for (const auto& [why, n] : counts) {
    text += (text.empty() ? "" : ", ") + std::to_string(n) + " " + why;
  }
  return text;
}

std::string RerunMessage(const std::map<std::string, size_t>& rerun) {
  size_t total = 0;
  for (const auto& [why, n] : rerun) total += n;
  if (total == 0) return "";
  return std::to_string(total) + (total == 1 ? " run" : " runs") + " rerun: " + RerunReasons(rerun);
}

namespace {

// The signals a sweep passes on to its workers; one the sweep was started ignoring (as a
// background job of a script ignores SIGINT) stays ignored.
sigset_t ForwardedSignals() {
  sigset_t set;
  sigemptyset(&set);
  for (int sig : {SIGTERM, SIGINT}) {
    struct sigaction current {};
    if (::sigaction(sig, nullptr, &current) == 0 && current.sa_handler == SIG_IGN) continue;
    sigaddset(&set, sig);
  }
  return set;
}

// Passes `sig` to every running worker and waits for them; a worker still there after 10 s is
// killed. Their runs are not recorded as failures: a resumed sweep runs them again.
void StopWorkers(const std::map<pid_t, size_t>& running, int sig) {
  for (const auto& [pid, run] : running) ::kill(pid, sig);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  std::map<pid_t, size_t> left = running;
  while (!left.empty()) {
    for (auto it = left.begin(); it != left.end();) {
      int status = 0;
      const pid_t r = ::waitpid(it->first, &status, WNOHANG);
      it = r == it->first || (r < 0 && errno != EINTR) ? left.erase(it) : std::next(it);
    }
    if (left.empty()) break;
    if (std::chrono::steady_clock::now() > deadline) {
      for (const auto& [pid, run] : left) ::kill(pid, SIGKILL);
      for (const auto& [pid, run] : left) {
        int status = 0;
        while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
        }
      }
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

bool EndedBySignal(int status) {
  const auto stopping = [](int sig) { return sig == SIGINT || sig == SIGTERM; };
  return (WIFSIGNALED(status) && stopping(WTERMSIG(status))) ||
         (WIFEXITED(status) && WEXITSTATUS(status) > 128 && stopping(WEXITSTATUS(status) - 128));
}

// Blocks the signals RunLocal waits for while it lives (SIGCHLD, and the forwarded ones), so
// that none is lost between a check and the wait; restores the mask at scope exit.
class BlockedSignals {
 public:
  BlockedSignals() : forwarded_(ForwardedSignals()) {
    waited_ = forwarded_;
    sigaddset(&waited_, SIGCHLD);
    ::sigprocmask(SIG_BLOCK, &waited_, &old_);
  }
  ~BlockedSignals() { ::sigprocmask(SIG_SETMASK, &old_, nullptr); }
  const sigset_t& old() const { return old_; }
  // A forwarded signal that has arrived (taken), or 0.
  int Poll() const {
    siginfo_t info;
    const timespec now{0, 0};
    const int sig = ::sigtimedwait(&forwarded_, &info, &now);
    return sig > 0 ? sig : 0;
  }
  // Waits for a worker's end (0) or a forwarded signal (its number).
  int Wait() const {
    for (;;) {
      siginfo_t info;
      const int sig = ::sigwaitinfo(&waited_, &info);
      if (sig < 0) {
        if (errno == EINTR) continue;
        return 0;
      }
      return sig == SIGCHLD ? 0 : sig;
    }
  }

 private:
  sigset_t forwarded_, waited_, old_;
};

}  // namespace

LocalOutcome RunLocal(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                      const std::vector<SweepRun>& runs, const std::vector<size_t>& todo,
                      const fs::path& out, int jobs, const RunKeys& keys) {
  Progress progress(todo.size());
  std::map<pid_t, size_t> running;
  size_t next = 0, done = 0;
  size_t failed = 0;
  std::fflush(stdout);
  std::fflush(stderr);
  const BlockedSignals signals;
  int stop = 0;
  while (done < todo.size() && !(stop = signals.Poll())) {
    while (next < todo.size() && static_cast<int>(running.size()) < jobs) {
      const SweepRun& run = runs[todo[next]];
      const fs::path log = out / LogPath(run, points);
      fs::create_directories(log.parent_path());
      fs::create_directories((out / run.dir).parent_path());
      const RunKey key = keys.Of(run);
      const pid_t pid = ::fork();
      if (pid < 0) throw std::runtime_error("fork failed");
      if (pid == 0) RunChild(spec, points[run.point], run, out, log, key, signals.old());
      running[pid] = todo[next++];
    }
    // Every worker that has ended; when none has, wait for one to end or for a signal.
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, WNOHANG);
    if (pid < 0) throw std::runtime_error("waitpid failed");
    if (pid == 0) {
      stop = signals.Wait();
      if (stop) break;
      continue;
    }
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const size_t index = it->second;
    running.erase(it);
    // A terminal's Ctrl-C reaches the workers too: one ended by the signal that stops the
    // sweep (killed by it, or exiting 128 + it after its own clean-up) was interrupted, not
    // failed.
    if (EndedBySignal(status) && (stop = signals.Poll())) break;
    RecordOutcome(runs[index], points, out, status, &failed);
    progress.Update(++done, failed);
  }
  if (stop == 0) stop = signals.Poll();  // arrived as the last run ended
  if (stop) {
    std::fprintf(stderr, "%s[sweep] %s: stopping %zu running runs\n",
                 isatty(fileno(stderr)) ? "\n" : "", stop == SIGINT ? "SIGINT" : "SIGTERM",
                 running.size());
    StopWorkers(running, stop);
    return {static_cast<int>(failed), stop};
  }
  return {static_cast<int>(failed), 0};
}

}  // namespace flexbench::scenarios::sweep
