#include "scenarios/runner/output.h"

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
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

std::string ReadSmallFile(const fs::path& p, std::uintmax_t max_bytes, bool* ok) {
  *ok = false;
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(p, ec);
  if (ec || !fs::is_regular_file(st)) return "";
  const std::uintmax_t size = fs::file_size(p, ec);
  if (ec || size > max_bytes) return "";
  std::ifstream in(p, std::ios::binary);
  if (!in) return "";
  std::ostringstream ss;
  ss << in.rdbuf();
  if (ss.str().size() > max_bytes) return "";
  *ok = true;
  return ss.str();
}

// --- Who made a temporary -------------------------------------------------------------------

// A process as a temporary's marker names it. The start time (clock ticks since boot, field 22
// of /proc/PID/stat) tells a reused PID from the process that wrote the marker; host and PID
// namespace tell whether that PID can be looked up from here at all.
struct Maker {
  std::string host;
  std::string pid_namespace;
  long pid = 0;
  unsigned long long start_time = 0;
};

// The state letter and start time of process `pid` from /proc; false when unreadable.
bool ReadStat(long pid, char* state, unsigned long long* start_time) {
  std::ifstream stat("/proc/" + (pid == 0 ? std::string("self") : std::to_string(pid)) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return false;
  // "pid (comm) state ...": comm may hold spaces and parentheses, so read after the last ')'.
  const size_t paren = line.rfind(')');
  if (paren == std::string::npos || paren + 2 >= line.size()) return false;
  std::istringstream fields(line.substr(paren + 2));
  std::string f;
  for (int field = 3; field <= 22 && fields >> f; ++field) {
    if (field == 3) *state = f.empty() ? '?' : f[0];
    if (field == 22) {
      char* end = nullptr;
      errno = 0;
      *start_time = std::strtoull(f.c_str(), &end, 10);
      return errno == 0 && end && *end == '\0' && !f.empty();
    }
  }
  return false;
}

Maker Self() {
  Maker m;
  char host[HOST_NAME_MAX + 1] = {};
  if (gethostname(host, sizeof(host) - 1) == 0) m.host = host;
  char ns[256];
  const ssize_t n = readlink("/proc/self/ns/pid", ns, sizeof(ns) - 1);
  if (n > 0) m.pid_namespace.assign(ns, static_cast<size_t>(n));
  m.pid = static_cast<long>(getpid());
  char state = 0;
  if (!ReadStat(0, &state, &m.start_time)) m.start_time = 0;
  return m;
}

constexpr const char* kMarkerHeader = "flexbench temporary folder";

std::string MarkerText(const Maker& m) {
  return std::string(kMarkerHeader) + "\nhost=" + m.host + "\npid_namespace=" + m.pid_namespace +
         "\npid=" + std::to_string(m.pid) + "\nstart_time=" + std::to_string(m.start_time) + "\n";
}

std::optional<Maker> ReadMarker(const fs::path& dir) {
  bool ok = false;
  const std::string text = ReadSmallFile(dir / kTemporaryMarker, 4096, &ok);
  if (!ok) return std::nullopt;
  std::istringstream lines(text);
  std::string line;
  if (!std::getline(lines, line) || line != kMarkerHeader) return std::nullopt;
  Maker m;
  int seen = 0;
  const auto number = [](const std::string& v, unsigned long long* out) {
    if (v.empty() || v.size() > 20 || v.find_first_not_of("0123456789") != std::string::npos) {
      return false;
    }
    errno = 0;
    *out = std::strtoull(v.c_str(), nullptr, 10);
    return errno == 0;
  };
  while (std::getline(lines, line)) {
    const size_t eq = line.find('=');
    if (eq == std::string::npos) return std::nullopt;
    const std::string key = line.substr(0, eq), value = line.substr(eq + 1);
    unsigned long long v = 0;
    if (key == "host" && !(seen & 1)) {
      m.host = value;
      seen |= 1;
    } else if (key == "pid_namespace" && !(seen & 2)) {
      m.pid_namespace = value;
      seen |= 2;
    } else if (key == "pid" && !(seen & 4) && number(value, &v) && v > 0 && v < (1ull << 31)) {
      m.pid = static_cast<long>(v);
      seen |= 4;
    } else if (key == "start_time" && !(seen & 8) && number(value, &v)) {
      m.start_time = v;
      seen |= 8;
    } else {
      return std::nullopt;
    }
  }
  if (seen != 15) return std::nullopt;
  return m;
}

// True when the process a marker names has ended: no such PID, a PID reused by a process that
// started at another time, or a zombie (killed with its parent, e.g. a sweep's worker, it waits
// for init to reap it and kill(pid, 0) still succeeds). When it cannot be told, it runs.
bool MakerGone(const Maker& m) {
  errno = 0;
  if (kill(static_cast<pid_t>(m.pid), 0) != 0 && errno == ESRCH) return true;
  char state = 0;
  unsigned long long start = 0;
  if (!ReadStat(m.pid, &state, &start)) return false;
  if (start != m.start_time) return true;
  return state == 'Z' || state == 'X';
}

// True for a temporary killed between its mkdir and the end of its marker's write: it holds
// nothing (or only a partial marker), so it holds nothing of anyone's, and no process of the
// PID its name holds runs in this PID namespace. Were it a live run of another host or
// container on a shared file system, in that moment: it finds its marker gone once it has
// written frames/ (IsOwnTemporary) and takes the next name.
bool IsUnmarkedAbandoned(const fs::path& dir, long pid) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code type_ec;
    if (it->path().filename() != kTemporaryMarker ||
        !fs::is_regular_file(fs::symlink_status(it->path(), type_ec)) ||
        fs::file_size(it->path(), type_ec) > 4096 || type_ec) {
      return false;
    }
  }
  if (ec) return false;
  errno = 0;
  return kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
}

// Whether `dir` holds this process's complete marker.
bool IsOwnTemporary(const fs::path& dir, const Maker& self) {
  const std::optional<Maker> m = ReadMarker(dir);
  return m && m->pid == self.pid && m->start_time == self.start_time && m->host == self.host &&
         m->pid_namespace == self.pid_namespace;
}

// True only for a temporary of a flexbench run of this host and this PID namespace (so its
// PID means the same process here) whose process has ended, `pid` being the PID its name holds.
bool IsStaleTemporary(const fs::path& dir, long pid, const Maker& self) {
  std::error_code ec;
  if (!fs::is_directory(fs::symlink_status(dir, ec)) || ec) return false;
  const std::optional<Maker> m = ReadMarker(dir);
  if (!m) return pid != self.pid && IsUnmarkedAbandoned(dir, pid);
  if (m->pid != pid) return false;
  if (self.host.empty() || self.pid_namespace.empty() || self.start_time == 0) return false;
  if (m->host != self.host || m->pid_namespace != self.pid_namespace) return false;
  if (m->pid == self.pid && m->start_time == self.start_time) return false;  // this process's
  return MakerGone(*m);
}

// --- Names ----------------------------------------------------------------------------------

// The longest suffix TemporaryName appends: ".tmp-" + a 10-digit PID + "-" + 2 digits.
constexpr size_t kSuffixReserve = 20;
constexpr size_t kNameMax = NAME_MAX;

std::string Stem(const std::string& name) {
  if (name.size() + kSuffixReserve <= kNameMax) return name;
  std::uint64_t h = 1469598103934665603ull;  // FNV-1a over the whole name
  for (unsigned char c : name) {
    h ^= c;
    h *= 1099511628211ull;
  }
  size_t cut = 200;
  while (cut > 0 && (static_cast<unsigned char>(name[cut]) & 0xC0) == 0x80) --cut;
  char hex[17];
  std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(h));
  return name.substr(0, cut) + "-" + hex;
}

// The PID in a name made by TemporaryName for destination `name` and `tag`; 0 when it is not
// one.
long PidOfTemporaryName(const std::string& f, const std::string& stem, const char* tag) {
  const std::string prefix = stem + "." + tag + "-";
  if (f.size() <= prefix.size() || f.compare(0, prefix.size(), prefix) != 0) return 0;
  const std::string rest = f.substr(prefix.size());
  const size_t dash = rest.find('-');
  const std::string digits = rest.substr(0, dash);
  if (digits.empty() || digits.size() > 10 ||
      digits.find_first_not_of("0123456789") != std::string::npos) {
    return 0;
  }
  if (dash != std::string::npos) {
    const std::string k = rest.substr(dash + 1);
    if (k.empty() || k.size() > 2 || k.find_first_not_of("0123456789") != std::string::npos) {
      return 0;
    }
  }
  const unsigned long long pid = std::strtoull(digits.c_str(), nullptr, 10);
  return pid > 0 && pid < (1ull << 31) ? static_cast<long>(pid) : 0;
}

// Removes the temporaries beside `final_dir` of runs that ended (IsStaleTemporary).
void RemoveStaleTemporaries(const fs::path& final_dir, const Maker& self) {
  const std::string stem = Stem(final_dir.filename().string());
  std::error_code ec;
  for (fs::directory_iterator it(final_dir.parent_path(), ec), end; !ec && it != end;
       it.increment(ec)) {
    const std::string f = it->path().filename().string();
    for (const char* tag : {"tmp", "old"}) {
      const long pid = PidOfTemporaryName(f, stem, tag);
      if (pid == 0 || !IsStaleTemporary(it->path(), pid, self)) continue;
      std::error_code rm;
      if (ReadMarker(it->path())) {
        fs::remove_all(it->path(), rm);
      } else {
        // Unmarked: never more than the partial marker, and the folder only while empty (a
        // run that was only slow has written frames/ by now, and rmdir leaves it).
        fs::remove(it->path() / kTemporaryMarker, rm);
        ::rmdir(it->path().c_str());
      }
    }
  }
}

// --- Signals --------------------------------------------------------------------------------

// The temporaries of this process, for the signal handler: fixed storage, written before a
// slot is published (state 2) and read by the handler only then. `owner` keeps a forked
// child (a sweep's worker) from removing its parent's temporaries.
struct Slot {
  std::atomic<int> state{0};  // 0 free, 1 being written, 2 in use
  std::atomic<pid_t> owner{0};
  char path[PATH_MAX];
};
constexpr int kSlots = 32;
Slot g_slots[kSlots];

// While a temporary is being made or moved into place, a signal is held (the handler records
// it) and acted on afterwards: removing the temporary between the two renames of a commit
// would lose the previous result as well.
std::mutex g_critical_mutex;
std::atomic<pid_t> g_critical_owner{0};
volatile sig_atomic_t g_held_signal = 0;

constexpr int kCleanupSignals[] = {SIGTERM, SIGINT, SIGHUP};

int RegisterTemporary(const fs::path& path) {
  const std::string p = path.string();
  if (p.size() >= PATH_MAX) return -1;
  for (int i = 0; i < kSlots; ++i) {
    int expected = 0;
    if (!g_slots[i].state.compare_exchange_strong(expected, 1)) continue;
    std::memcpy(g_slots[i].path, p.c_str(), p.size() + 1);
    g_slots[i].owner.store(getpid());
    g_slots[i].state.store(2);
    return i;
  }
  return -1;  // more live temporaries than slots: that one is left to the next run
}

void UnregisterTemporary(int slot) {
  if (slot >= 0) g_slots[slot].state.store(0);
}

struct LinuxDirent64 {
  std::uint64_t d_ino;
  std::int64_t d_off;
  unsigned short d_reclen;
  unsigned char d_type;
  char d_name[1];
};

// Removes what folder `dir_fd` holds with async-signal-safe calls only (no allocation), links
// never followed. Removing while reading may skip entries, so it reads again until a pass
// finds nothing or removes nothing.
void RemoveContentsSignalSafe(int dir_fd, int depth) {
  if (depth > 24) return;
  for (int pass = 0; pass < 16; ++pass) {
    if (lseek(dir_fd, 0, SEEK_SET) != 0) return;
    bool any = false, removed = false;
    alignas(8) char buf[1024];
    for (;;) {
      const long n = syscall(SYS_getdents64, dir_fd, buf, sizeof(buf));
      if (n <= 0) break;
      for (long off = 0; off < n;) {
        const auto* d = reinterpret_cast<const LinuxDirent64*>(buf + off);
        off += d->d_reclen;
        const char* name = d->d_name;
        if (name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'))) continue;
        any = true;
        if (unlinkat(dir_fd, name, 0) == 0) {
          removed = true;
          continue;
        }
        const int sub = openat(dir_fd, name, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
        if (sub >= 0) {
          RemoveContentsSignalSafe(sub, depth + 1);
          close(sub);
        }
        if (unlinkat(dir_fd, name, AT_REMOVEDIR) == 0) removed = true;
      }
    }
    if (!any || !removed) return;
  }
}

void RemoveTreeSignalSafe(const char* path) {
  const int fd = open(path, O_RDONLY | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
  if (fd < 0) return;
  RemoveContentsSignalSafe(fd, 0);
  close(fd);
  rmdir(path);
}

void CleanupHandler(int sig) {
  const int saved_errno = errno;
  const pid_t me = getpid();
  if (g_critical_owner.load() == me) {
    g_held_signal = sig;
    errno = saved_errno;
    return;
  }
  for (int i = kSlots - 1; i >= 0; --i) {
    if (g_slots[i].state.load() == 2 && g_slots[i].owner.load() == me) {
      RemoveTreeSignalSafe(g_slots[i].path);
    }
  }
  // The signal's own action: the process ends by it (a shell shows 128 + the signal).
  struct sigaction dfl = {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  sigaction(sig, &dfl, nullptr);
  raise(sig);  // delivered when the handler returns (the signal is blocked while it runs)
  errno = saved_errno;
}

// Installs CleanupHandler for the signals whose action is the default (the process would end
// anyway); a handler someone else installed, or an ignored signal (nohup, a background job),
// is left as it is.
void EnsureSignalCleanup() {
  for (int sig : kCleanupSignals) {
    struct sigaction current = {};
    if (sigaction(sig, nullptr, &current) != 0) continue;
    if (current.sa_flags & SA_SIGINFO) continue;
    if (current.sa_handler != SIG_DFL) continue;
    struct sigaction mine = {};
    mine.sa_handler = CleanupHandler;
    sigemptyset(&mine.sa_mask);
    for (int s : kCleanupSignals) sigaddset(&mine.sa_mask, s);
    mine.sa_flags = SA_RESTART;
    sigaction(sig, &mine, nullptr);
  }
}

// Holds the cleanup signals for a critical section; one that arrived meanwhile is raised again
// at its end.
class SignalsHeld {
 public:
  SignalsHeld() : lock_(g_critical_mutex) { g_critical_owner.store(getpid()); }
  ~SignalsHeld() {
    g_critical_owner.store(0);
    const int held = g_held_signal;
    g_held_signal = 0;
    lock_.unlock();
    if (held != 0) raise(held);
  }
  SignalsHeld(const SignalsHeld&) = delete;
  SignalsHeld& operator=(const SignalsHeld&) = delete;

 private:
  std::unique_lock<std::mutex> lock_;
};

// Writes the marker of a temporary; 0, or the errno of the failure.
int WriteMarker(const fs::path& dir, const Maker& m) {
  errno = 0;
  std::ofstream out(dir / kTemporaryMarker, std::ios::binary);
  if (out) {
    errno = 0;
    out << MarkerText(m);
    out.close();
  }
  if (out) return 0;
  return errno != 0 ? errno : EIO;
}

// The replaced folder's name: the first of "<name>.old-PID[-K]" that does not exist.
fs::path FreeOldName(const fs::path& final_dir, long pid) {
  std::error_code ec;
  for (int k = 0; k < 100; ++k) {
    const fs::path p =
        final_dir.parent_path() / TemporaryName(final_dir.filename().string(), "old", pid, k);
    if (!fs::exists(fs::symlink_status(p, ec))) return p;
  }
  throw InputError(Shown(final_dir) + ": too many folders named like its replaced results (" +
                   TemporaryName(final_dir.filename().string(), "old", pid) + "...); remove them");
}

// rename() that never replaces an existing `to` (rename(2) replaces an empty folder).
bool RenameNoReplace(const fs::path& from, const fs::path& to, std::error_code* ec) {
#ifdef RENAME_NOREPLACE
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) {
    return true;
  }
  if (errno != EINVAL && errno != ENOSYS) {
    *ec = std::error_code(errno, std::generic_category());
    return false;
  }
#endif
  if (fs::exists(fs::symlink_status(to, *ec))) {
    *ec = std::make_error_code(std::errc::file_exists);
    return false;
  }
  fs::rename(from, to, *ec);
  return !*ec;
}

// Nesting depth of JSON text (brackets outside strings) up to `limit`; limit + 1 beyond.
int JsonDepth(const std::string& text, int limit) {
  int depth = 0, deepest = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') {
        ++i;
      } else if (c == '"') {
        in_string = false;
      }
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
      if (deepest > limit) return limit + 1;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return deepest;
}

}  // namespace

std::string TemporaryName(const std::string& name, const char* tag, long pid, int k) {
  return Stem(name) + "." + tag + "-" + std::to_string(pid) +
         (k > 0 ? "-" + std::to_string(k) : std::string());
}

bool IsFlexbenchResult(const fs::path& dir) {
  std::error_code ec;
  if (fs::is_regular_file(fs::symlink_status(dir / kResultMarker, ec))) return true;
  bool ok = false;
  // A run's summary is a few kilobytes; a bigger or deeper file is not one.
  const std::string text = ReadSmallFile(dir / "summary.json", kMaxConfigFileBytes, &ok);
  if (!ok || JsonDepth(text, 64) > 64) return false;
  const nlohmann::json s = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (s.is_discarded() || !s.is_object()) return false;
  const auto has = [&s](const char* key, bool (nlohmann::json::*is)() const noexcept) {
    const auto it = s.find(key);
    return it != s.end() && ((*it).*is)();
  };
  return has("scenario", &nlohmann::json::is_string) && has("kind", &nlohmann::json::is_string) &&
         has("seed", &nlohmann::json::is_number_integer) &&
         has("metrics", &nlohmann::json::is_object) && has("gates", &nlohmann::json::is_array);
}

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
  std::vector<fs::path> all = inputs;
  for (const std::string& f : RecordedInputFiles()) all.emplace_back(f);
  for (const fs::path& in : all) {
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
  if (IsFlexbenchResult(dir)) return;  // a previous result
  if (force) return;
  throw InputError("--out " + Shown(dir) + ": exists and is not a flexbench result (no " +
                   kResultMarker +
                   ", no flexbench summary.json); refusing to replace it (choose another --out, "
                   "or --force)");
}

OutputDir::OutputDir(const fs::path& final_dir, bool force, const std::vector<fs::path>& inputs)
    : final_(fs::absolute(final_dir).lexically_normal()), force_(force), inputs_(inputs) {
  if (final_.filename().empty()) final_ = final_.parent_path();  // "out/" -> "out"
  if (final_.filename().empty() || final_ == final_.root_path()) {
    throw InputError("--out " + Shown(final_dir) + ": not a usable output folder");
  }
  // Before any work: the results could never be moved to a name the file system refuses.
  if (final_.filename().string().size() > kNameMax) {
    throw InputError("--out " + Shown(final_dir) + ": its last name is longer than " +
                     std::to_string(kNameMax) + " bytes");
  }
  CheckReplaceable(final_, force_, inputs_);
  std::error_code ec;
  fs::create_directories(final_.parent_path(), ec);
  if (ec)
    throw InputError(Shown(final_.parent_path()) +
                     ": cannot create output folder: " + ec.message());
  EnsureSignalCleanup();
  const Maker self = Self();
  RemoveStaleTemporaries(final_, self);
  const std::string name = final_.filename().string();
  SignalsHeld held;
  bool retried = false;
  int err = 0;
  for (int k = 0; k < 100 && tmp_.empty(); ++k) {
    const fs::path candidate = final_.parent_path() / TemporaryName(name, "tmp", self.pid, k);
    if (::mkdir(candidate.c_str(), 0777) == 0) {
      // The marker first (an unmarked temporary is removed only while it holds nothing), and
      // it is the probe write: permissions can allow mkdir yet refuse files (read-only mounts,
      // a full disk).
      err = WriteMarker(candidate, self);
      if (err == 0 && !fs::create_directories(candidate / "frames", ec))
        err = ec ? ec.value() : EIO;
      if (err == ENOENT || (err == 0 && !IsOwnTemporary(candidate, self))) {
        // Another run took the folder for an abandoned one before its marker was complete:
        // what is there now is this run's (frames/ made again), the next name is taken.
        fs::remove_all(candidate, ec);
        err = 0;
        continue;
      }
      tmp_ = candidate;
      if (err != 0) {
        fs::remove_all(tmp_, ec);
        throw InputError(Shown(final_) + ": output folder is not writable: " + std::strerror(err));
      }
    } else if (errno == EEXIST) {
      // A folder of that name that is not a temporary of an ended run (its PID reused) is
      // someone's: the next name.
      if (!retried && IsStaleTemporary(candidate, self.pid, self)) {
        retried = true;
        fs::remove_all(candidate, ec);
        --k;
      }
    } else {
      throw InputError(Shown(final_) + ": cannot write output folder: " + std::strerror(errno));
    }
  }
  if (tmp_.empty()) {
    throw InputError(Shown(final_) + ": too many folders named like its temporaries (" +
                     TemporaryName(name, "tmp", self.pid) + "...); remove them");
  }
  signal_slot_ = RegisterTemporary(tmp_);
}

void RemoveEndedTemporaries(const std::vector<fs::path>& final_dirs) {
  const Maker self = Self();
  for (const fs::path& d : final_dirs) RemoveStaleTemporaries(d, self);
}

OutputDir::~OutputDir() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(tmp_, ec);
  }
  UnregisterTemporary(signal_slot_);
}

fs::path OutputDir::File(const std::string& relative) const {
  const fs::path p = tmp_ / relative;
  std::error_code ec;
  fs::create_directories(p.parent_path(), ec);
  return p;
}

void OutputDir::RemoveImages() {
  std::vector<fs::path> images;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(tmp_, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    std::error_code type_ec;
    if (it->is_regular_file(type_ec) && it->path().extension() == ".png") {
      images.push_back(it->path());
    }
  }
  for (const fs::path& p : images) fs::remove(p, ec);
}

void OutputDir::RemoveDataFiles() {
  std::vector<fs::path> files, dirs;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(tmp_, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    std::error_code type_ec;
    if (it->is_directory(type_ec)) {
      dirs.push_back(it->path());
    } else if (it->path().filename() != kTemporaryMarker) {
      files.push_back(it->path());
    }
  }
  for (const fs::path& p : files) fs::remove(p, ec);
  // Deepest first; frames/ stays, as the folder was made.
  std::sort(dirs.begin(), dirs.end(), [](const fs::path& a, const fs::path& b) {
    return a.native().size() > b.native().size();
  });
  for (const fs::path& d : dirs) {
    if (d != FramesDir() && fs::is_empty(d, ec)) fs::remove(d, ec);
  }
}

void OutputDir::Commit() {
  CheckReplaceable(final_, force_, inputs_);
  // Fixed bytes: two runs of the same command stay identical, file for file.
  WriteFileAtomic(tmp_ / kResultMarker,
                  "This folder is a flexbench result: a later run may replace it.\n");
  std::error_code ec;
  fs::path old;
  {
    SignalsHeld held;
    const Maker self = Self();
    if (fs::exists(fs::symlink_status(final_, ec))) {
      old = FreeOldName(final_, self.pid);
      if (!RenameNoReplace(final_, old, &ec)) {
        throw InputError(Shown(final_) + ": cannot replace output folder: " + ec.message());
      }
      // Marked as this run's, so that a run killed before removing it is cleaned up after.
      WriteMarker(old, self);
    }
    fs::remove(tmp_ / kTemporaryMarker, ec);
    fs::rename(tmp_, final_, ec);
    if (ec) {
      const std::string reason = ec.message();
      WriteMarker(tmp_, self);
      if (!old.empty()) {
        // The previous result back in place, or at least never removed as a temporary.
        std::error_code back;
        fs::remove(old / kTemporaryMarker, back);
        RenameNoReplace(old, final_, &back);
      }
      throw InputError(Shown(final_) + ": cannot move results into place: " + reason);
    }
    committed_ = true;
    UnregisterTemporary(signal_slot_);
    signal_slot_ = -1;
  }
  if (!old.empty()) fs::remove_all(old, ec);
}

FrameOutput ParseFrameOutput(const std::string& text, const std::string& option) {
  if (text == "all") return FrameOutput::kAll;
  if (text == "key") return FrameOutput::kKey;
  if (text == "none") return FrameOutput::kNone;
  throw InputError(option + " '" + CapForMessage(text) + "': expected all, key or none");
}

const char* FrameOutputName(FrameOutput f) {
  return f == FrameOutput::kAll ? "all" : f == FrameOutput::kKey ? "key" : "none";
}

bool WritesFrame(FrameOutput f, int index, int count, int key_count) {
  if (f != FrameOutput::kKey) return f == FrameOutput::kAll;
  for (int i = 0; i < key_count && count > 0; ++i) {
    if (static_cast<int>((static_cast<long>(i) * count) / key_count) == index) return true;
  }
  return false;
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
