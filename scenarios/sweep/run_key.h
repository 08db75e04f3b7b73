// What defines a sweep run's result, recorded in its folder as `run.key` beside summary.json, so
// that a resumed sweep reuses a result only when it was made with the same settings: the
// scenario file's bytes, the bytes of the other files the sweep's points read (models, declared
// models, CSVs: every file the checks of the points accepted), the overrides (the sweep's `set:`
// then the point's grid values), the seed, and the flexbench binary (its version and, when the
// linker wrote one, its GNU build id). Each part is an FNV-1a 64 hash; `key` hashes them all.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "scenarios/sweep/sweep_file.h"

namespace flexbench::scenarios::sweep {

inline constexpr const char* kRunKeyFile = "run.key";

struct RunKey {
  std::string scenario;   // hash of the scenario file's bytes
  std::string inputs;     // hash of the bytes of the other input files, in path order
  std::string overrides;  // hash of the KEY=VALUE overrides, in order
  std::uint64_t seed = 0;
  std::string flexbench;  // "flexbench <version>[ build <id>]"
  std::string key;        // hash of all the above
};

// FNV-1a 64 of `bytes`, continuing from `hash`, as used for every part of a key.
std::uint64_t Fnv1a64(const std::string& bytes, std::uint64_t hash = 14695981039346656037ull);

// "flexbench <version>", plus " build <hex>" when the running executable has a GNU build id.
std::string BinaryIdentity();

// The keys of a sweep's runs; reads the scenario file and `input_files` once. `input_files`:
// the files the points read besides the scenario (the sweep file itself is left out, so that a
// changed gate does not redo the runs).
class RunKeys {
 public:
  RunKeys(const SweepSpec& spec, const std::vector<SweepPoint>& points,
          const std::vector<std::string>& input_files);
  RunKey Of(const SweepRun& run) const;

 private:
  std::vector<std::string> fixed_set_;
  std::vector<SweepPoint> points_;
  std::string scenario_hash_;
  std::string inputs_hash_;
  std::string binary_;
};

// Writes <run_dir>/run.key; throws InputError naming it when it cannot.
void WriteRunKey(const std::filesystem::path& run_dir, const RunKey& key);

// Why the result in `run_dir` was not made with `expected`: "" when its run.key matches, else
// one of "no run key", "damaged run key", "scenario file changed", "an input file changed",
// "overrides changed", "seed changed", "flexbench binary changed".
std::string StaleReason(const std::filesystem::path& run_dir, const RunKey& expected);

}  // namespace flexbench::scenarios::sweep
