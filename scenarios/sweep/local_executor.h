// The local executor: a pool of forked worker processes, one run each, no daemon. A run that
// crashes or fails is recorded (exit code or signal, its last stderr line) and the sweep goes on.
#pragma once

#include <filesystem>
#include <vector>

#include "scenarios/sweep/sweep_file.h"

namespace flexbench::scenarios::sweep {

// Indices of the runs without a summary.json (a resumed sweep skips the others); with
// shard_count > 0 only those of shard `shard_index` (run k belongs to shard k % shard_count).
std::vector<size_t> PendingRuns(const std::filesystem::path& out, const std::vector<SweepRun>& runs,
                                int shard_index = 0, int shard_count = 0);

// Runs `todo` with at most `jobs` at a time; every run's stderr goes to its log file. Prints a
// progress line on stderr (done/total, rate, ETA). Returns the number of runs that failed.
int RunLocal(const SweepSpec& spec, const std::vector<SweepPoint>& points,
             const std::vector<SweepRun>& runs, const std::vector<size_t>& todo,
             const std::filesystem::path& out, int jobs);

}  // namespace flexbench::scenarios::sweep
