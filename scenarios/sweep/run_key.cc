#include "scenarios/sweep/run_key.h"

#include <elf.h>
#include <errno.h>
#include <fcntl.h>
#include <link.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>

#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios::sweep {
namespace {

std::string Hex(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

// Each string with its length first, so that ["a=1", "b=2"] and ["a=1b=2"] differ.
std::uint64_t HashList(const std::vector<std::string>& items) {
  std::uint64_t h = Fnv1a64(std::to_string(items.size()) + ";");
  for (const std::string& s : items) h = Fnv1a64(std::to_string(s.size()) + ":" + s, h);
  return h;
}

// The GNU build id note of the main program (the first object dl_iterate_phdr reports).
int FindBuildId(dl_phdr_info* info, size_t, void* data) {
  auto* id = static_cast<std::string*>(data);
  for (int i = 0; i < info->dlpi_phnum; ++i) {
    const ElfW(Phdr)& ph = info->dlpi_phdr[i];
    if (ph.p_type != PT_NOTE) continue;
    const char* p = reinterpret_cast<const char*>(info->dlpi_addr + ph.p_vaddr);
    const char* end = p + ph.p_memsz;
    while (p + sizeof(ElfW(Nhdr)) <= end) {
      const auto* note = reinterpret_cast<const ElfW(Nhdr)*>(p);
      const char* name = p + sizeof(ElfW(Nhdr));
      const char* desc = name + ((note->n_namesz + 3u) & ~3u);
      const char* next = desc + ((note->n_descsz + 3u) & ~3u);
      if (next > end) break;
      if (note->n_type == NT_GNU_BUILD_ID && note->n_namesz == 4 &&
          std::memcmp(name, "GNU", 4) == 0) {
        for (size_t k = 0; k < note->n_descsz; ++k) {
          char buf[3];
          std::snprintf(buf, sizeof(buf), "%02x", static_cast<unsigned char>(desc[k]));
          *id += buf;
        }
        return 1;
      }
      p = next;
    }
  }
  return 1;
}

}  // namespace

std::uint64_t Fnv1a64(const std::string& bytes, std::uint64_t hash) {
  for (unsigned char c : bytes) {
    hash ^= c;
    hash *= 1099511628211ull;
  }
  return hash;
}

std::string BinaryIdentity() {
  std::string build_id;
  dl_iterate_phdr(FindBuildId, &build_id);
  return std::string("flexbench ") + FLEXBENCH_VERSION +
         (build_id.empty() ? std::string() : " build " + build_id);
}

RunKeys::RunKeys(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                 const std::vector<std::string>& input_files)
    : fixed_set_(spec.set), points_(points), binary_(BinaryIdentity()) {
  // The sweep's checks have already accepted these files (regular, within their size caps).
  const auto read = [](const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    if (!in) throw InputError(CapForMessage(path) + ": cannot read this input of the sweep");
    return bytes.str();
  };
  scenario_hash_ = Hex(Fnv1a64(read(spec.scenario)));
  std::vector<std::string> contents;
  for (const std::string& f : input_files) contents.push_back(read(f));
  inputs_hash_ = Hex(HashList(contents));
}

RunKey RunKeys::Of(const SweepRun& run) const {
  std::vector<std::string> set = fixed_set_;
  const SweepPoint& point = points_.at(run.point);
  set.insert(set.end(), point.set.begin(), point.set.end());
  RunKey k;
  k.scenario = scenario_hash_;
  k.inputs = inputs_hash_;
  k.overrides = Hex(HashList(set));
  k.seed = run.seed;
  k.flexbench = binary_;
  k.key = Hex(HashList({k.scenario, k.inputs, k.overrides, std::to_string(k.seed), k.flexbench}));
  return k;
}

void WriteRunKey(const fs::path& run_dir, const RunKey& k) {
  Json j;
  j["key"] = k.key;
  j["scenario"] = k.scenario;
  j["inputs"] = k.inputs;
  j["overrides"] = k.overrides;
  j["seed"] = k.seed;
  j["flexbench"] = k.flexbench;
  // One write of a few hundred bytes, without WriteFileAtomic's ".part": a run killed here
  // leaves a result with no key or a cut one, which only makes the next sweep redo it, while a
  // ".part" file would stay inside a finished result.
  const std::string text = j.dump(2) + "\n";
  const fs::path path = run_dir / kRunKeyFile;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw InputError(CapForMessage(path.string()) + ": " + std::strerror(errno));
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(fd);
      throw InputError(CapForMessage(path.string()) + ": " + std::strerror(err));
    }
    done += static_cast<size_t>(n);
  }
  if (::close(fd) != 0) {
    throw InputError(CapForMessage(path.string()) + ": " + std::strerror(errno));
  }
}

std::string StaleReason(const fs::path& run_dir, const RunKey& expected) {
  std::error_code ec;
  const fs::path file = run_dir / kRunKeyFile;
  if (!fs::is_regular_file(file, ec)) return "no run key";
  // A key is a few hundred bytes; anything much bigger is not one.
  if (fs::file_size(file, ec) > 4096 || ec) return "damaged run key";
  std::ifstream in(file);
  const Json j = Json::parse(in, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return "damaged run key";
  const auto text = [&](const char* name) {
    return j.contains(name) && j[name].is_string() ? j[name].get<std::string>() : std::string();
  };
  if (text("key") == expected.key) return "";
  if (text("scenario") != expected.scenario) return "scenario file changed";
  if (text("inputs") != expected.inputs) return "an input file changed";
  if (text("overrides") != expected.overrides) return "overrides changed";
  if (!j.contains("seed") || !j["seed"].is_number_unsigned() ||
      j["seed"].get<std::uint64_t>() != expected.seed) {
    return "seed changed";
  }
  if (text("flexbench") != expected.flexbench) return "flexbench binary changed";
  return "damaged run key";
}

}  // namespace flexbench::scenarios::sweep
