#include "scenarios/runner/output.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <system_error>

#include "estimators/error.h"
#include "sim/config.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios {

namespace {

std::string Shown(const fs::path& p) { return CapForMessage(p.string()); }

// True when `inner` is `outer` or lies below it (both absolute and normal).
bool Inside(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

fs::path Normal(const fs::path& p) {
  std::error_code ec;
  const fs::path a = fs::weakly_canonical(fs::absolute(p), ec);
  return ec ? fs::absolute(p).lexically_normal() : a;
}

// True while process `pid` runs. A zombie has ended: killed with its parent (a sweep's workers
// when the sweep is killed), it waits to be reaped by init, and kill(pid, 0) still succeeds,
// which kept a killed run's temporaries as if it were alive.
bool ProcessRunning(pid_t pid) {
  if (kill(pid, 0) != 0 && errno == ESRCH) return false;
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return true;  // no /proc: trust kill()
  // "pid (comm) state ...": comm may hold spaces and parentheses, so read after the last ')'.
  const size_t paren = line.rfind(')');
  if (paren == std::string::npos || paren + 2 >= line.size()) return true;
  const char state = line[paren + 2];
  return state != 'Z' && state != 'X';
}

// Removes "<name>.tmp-PID" and "<name>.old-PID" beside `final_dir` whose process is gone.
void RemoveStaleTemporaries(const fs::path& final_dir) {
  const std::string name = final_dir.filename().string();
  std::error_code ec;
  for (fs::directory_iterator it(final_dir.parent_path(), ec), end; !ec && it != end;
       it.increment(ec)) {
    const std::string f = it->path().filename().string();
    for (const char* tag : {".tmp-", ".old-"}) {
      const std::string prefix = name + tag;
      if (f.size() <= prefix.size() || f.compare(0, prefix.size(), prefix) != 0) continue;
      const std::string digits = f.substr(prefix.size());
      if (digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos) {
        continue;
      }
      const pid_t pid = static_cast<pid_t>(std::stol(digits));
      if (pid <= 0 || pid == getpid()) continue;
      if (ProcessRunning(pid)) continue;  // a live run's
      std::error_code rm;
      fs::remove_all(it->path(), rm);
    }
  }
}

}  // namespace

void CheckReplaceable(const fs::path& dir, bool force, const std::vector<fs::path>& inputs) {
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(dir, ec);
  if (ec || !fs::exists(st)) return;  // nothing there
  if (!fs::is_directory(st)) {
    throw InputError("--out " + Shown(dir) +
                     ": exists and is not a folder; refusing to replace it (choose another "
                     "--out)");
  }
  const fs::path norm = Normal(dir);
  for (const fs::path& in : inputs) {
    if (!in.empty() && Inside(Normal(in), norm)) {
      throw InputError("--out " + Shown(dir) + ": holds an input of this run (" + Shown(in) +
                       "); refusing to replace it");
    }
  }
  if (Inside(Normal(fs::current_path(ec)), norm)) {
    throw InputError("--out " + Shown(dir) +
                     ": is the working folder or holds it; refusing to replace it");
  }
  if (fs::is_empty(dir, ec) && !ec) return;
  if (fs::is_regular_file(dir / "summary.json", ec)) return;  // a previous result
  if (force) return;
  throw InputError("--out " + Shown(dir) +
                   ": exists and is not a flexbench result (no summary.json); refusing to "
                   "replace it (choose another --out, or --force)");
}

OutputDir::OutputDir(const fs::path& final_dir, bool force, const std::vector<fs::path>& inputs)
    : final_(fs::absolute(final_dir).lexically_normal()), force_(force), inputs_(inputs) {
  if (final_.filename().empty()) final_ = final_.parent_path();  // "out/" -> "out"
  if (final_.filename().empty() || final_ == final_.root_path()) {
    throw InputError("--out " + Shown(final_dir) + ": not a usable output folder");
  }
  CheckReplaceable(final_, force_, inputs_);
  std::error_code ec;
  fs::create_directories(final_.parent_path(), ec);
  if (ec)
    throw InputError(Shown(final_.parent_path()) +
                     ": cannot create output folder: " + ec.message());
  RemoveStaleTemporaries(final_);
  tmp_ = final_.parent_path() / (final_.filename().string() + ".tmp-" + std::to_string(getpid()));
  fs::remove_all(tmp_, ec);
  fs::create_directories(tmp_ / "frames", ec);
  if (ec) throw InputError(Shown(final_) + ": cannot write output folder: " + ec.message());
  // A probe write: permissions can allow mkdir yet refuse files (e.g. read-only mounts).
  std::ofstream probe(tmp_ / ".probe");
  if (!probe) {
    fs::remove_all(tmp_, ec);
    throw InputError(Shown(final_) + ": output folder is not writable");
  }
  probe.close();
  fs::remove(tmp_ / ".probe", ec);
}

OutputDir::~OutputDir() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(tmp_, ec);
  }
}

fs::path OutputDir::File(const std::string& relative) const {
  const fs::path p = tmp_ / relative;
  std::error_code ec;
  fs::create_directories(p.parent_path(), ec);
  return p;
}

void OutputDir::Commit() {
  std::error_code ec;
  const fs::path old =
      final_.parent_path() / (final_.filename().string() + ".old-" + std::to_string(getpid()));
  CheckReplaceable(final_, force_, inputs_);
  if (fs::exists(fs::symlink_status(final_, ec))) {
    fs::rename(final_, old, ec);
    if (ec) throw InputError(Shown(final_) + ": cannot replace output folder: " + ec.message());
  }
  fs::rename(tmp_, final_, ec);
  if (ec) throw InputError(Shown(final_) + ": cannot move results into place: " + ec.message());
  committed_ = true;
  fs::remove_all(old, ec);
}

void WriteFileAtomic(const fs::path& path, const std::string& text) {
  const fs::path tmp = path.string() + ".part";
  // On failure the partial ".part" file is removed: a full disk must leave nothing half-written
  // (report.html.part was moved into a result; outside a run's temporary folder, e.g. a sweep's
  // sweep.csv, it would stay). errno after a failed stream operation is the system's reason
  // ("No space left on device").
  const auto fail = [&](const std::string& what, int err) {
    std::error_code rm;
    fs::remove(tmp, rm);
    const std::string reason = err ? ": " + std::string(std::strerror(err)) : "";
    throw InputError(Shown(path) + ": " + what + reason);
  };
  errno = 0;
  std::ofstream out(tmp, std::ios::binary);
  if (!out) fail("cannot write", errno);
  errno = 0;
  out << text;
  out.close();  // flushes; a write error shows here at the latest
  if (!out) fail("write failed", errno);
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) fail("cannot write", ec.value());
}

}  // namespace flexbench::scenarios
