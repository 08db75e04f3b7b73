// The local executor: a pool of forked worker processes, one run each, no daemon. A run that
// crashes or fails is recorded (exit code or signal, its last stderr line) and the sweep goes on.
#pragma once

#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "scenarios/sweep/run_key.h"
#include "scenarios/sweep/sweep_file.h"

namespace flexbench::scenarios::sweep {

struct PendingRunList {
  std::vector<size_t> todo;
  // Runs with a summary.json made with other settings (its run.key differs): why -> how many.
  std::map<std::string, size_t> rerun;
};

// Indices of the runs without a summary.json or whose run.key is not `keys.Of(run)` (a resumed
// sweep skips the others); with shard_count > 0 only those of shard `shard_index` (run k
// belongs to shard k % shard_count).
PendingRunList PendingRuns(const std::filesystem::path& out, const std::vector<SweepRun>& runs,
                           const RunKeys& keys, int shard_index = 0, int shard_count = 0);

// "scenario file changed" for one reason, "3 scenario file changed, 2 no run key" for several.
std::string RerunReasons(const std::map<std::string, size_t>& counts);
// "3 runs rerun: scenario file changed"; "" when none.
std::string RerunMessage(const std::map<std::string, size_t>& rerun);

struct LocalOutcome {
  int failed = 0;  // runs that failed
  int signal = 0;  // SIGTERM or SIGINT when the sweep was stopped by one; 0: it ran to the end
};

// Runs `todo` with at most `jobs` at a time; every run's stderr goes to its log file, and a
// successful run's folder gets its run.key. Prints a progress line on stderr (done/total, rate,
// ETA). A SIGTERM or SIGINT to the sweep is passed on to the running workers, which are waited
// for (killed after 10 s) before it returns with `signal` set; no run is started after it.
LocalOutcome RunLocal(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                      const std::vector<SweepRun>& runs, const std::vector<size_t>& todo,
                      const std::filesystem::path& out, int jobs, const RunKeys& keys);

}  // namespace flexbench::scenarios::sweep
