#include "scenarios/runner/output.h"

#include <unistd.h>

#include <fstream>
#include <system_error>

#include "estimators/error.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios {

OutputDir::OutputDir(const fs::path& final_dir) : final_(fs::absolute(final_dir)) {
  std::error_code ec;
  fs::create_directories(final_.parent_path(), ec);
  if (ec) throw InputError(final_.parent_path().string() + ": cannot create output folder: " +
                           ec.message());
  tmp_ = final_.parent_path() / (final_.filename().string() + ".tmp-" + std::to_string(getpid()));
  fs::remove_all(tmp_, ec);
  fs::create_directories(tmp_ / "frames", ec);
  if (ec) throw InputError(final_.string() + ": cannot write output folder: " + ec.message());
  // A probe write: permissions can allow mkdir yet refuse files (e.g. read-only mounts).
  std::ofstream probe(tmp_ / ".probe");
  if (!probe) {
    fs::remove_all(tmp_, ec);
    throw InputError(final_.string() + ": output folder is not writable");
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
  const fs::path old = final_.parent_path() /
                       (final_.filename().string() + ".old-" + std::to_string(getpid()));
  if (fs::exists(final_)) {
    fs::rename(final_, old, ec);
    if (ec) throw InputError(final_.string() + ": cannot replace output folder: " + ec.message());
  }
  fs::rename(tmp_, final_, ec);
  if (ec) throw InputError(final_.string() + ": cannot move results into place: " + ec.message());
  committed_ = true;
  fs::remove_all(old, ec);
}

void WriteFileAtomic(const fs::path& path, const std::string& text) {
  const fs::path tmp = path.string() + ".part";
  {
    std::ofstream out(tmp, std::ios::binary);
    if (!out) throw InputError(path.string() + ": cannot write");
    out << text;
    if (!out) throw InputError(path.string() + ": write failed");
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) throw InputError(path.string() + ": cannot write: " + ec.message());
}

}  // namespace flexbench::scenarios
