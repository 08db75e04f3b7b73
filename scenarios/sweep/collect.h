// Collecting a sweep: every run's summary.json (or its failure record) -> sweep.csv (a row per
// run), aggregate.json (statistics per point, the sweep's gates) and sweep.png. Only the
// run folders are read, in the sweep's own order, so the output is the same bytes whichever
// executor ran the runs and in whatever order they finished.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "scenarios/runner/scenario_kind.h"
#include "scenarios/sweep/run_key.h"
#include "scenarios/sweep/sweep_file.h"

namespace flexbench::scenarios::sweep {

struct RunOutcome {
  bool present = false;  // a summary.json or a failure record
  bool ok = false;       // summary.json
  Json summary;
  Json failure;  // {exit_code, signal, error}
};

// Where a run's stderr and its failure record go, relative to the sweep's output folder.
std::string LogPath(const SweepRun& run, const std::vector<SweepPoint>& points);
std::string FailurePath(const SweepRun& run, const std::vector<SweepPoint>& points);

// A summary.json whose run.key is not `keys.Of(run)` was made with other settings: it is not
// read (the run counts as failed when it has a failure record, else as missing), and `stale`
// counts it under its reason.
std::vector<RunOutcome> ReadOutcomes(const std::filesystem::path& out,
                                     const std::vector<SweepPoint>& points,
                                     const std::vector<SweepRun>& runs, const RunKeys& keys,
                                     std::map<std::string, size_t>* stale);

struct Collected {
  std::string csv;
  Json aggregate;
  bool gates_passed = true;
  // The first point's successful runs (seed, scalar metrics), for the plot of a grid-less sweep.
  std::vector<std::pair<std::uint64_t, std::map<std::string, double>>> first_point;
};

// Throws InputError "<sweep>:<line>: gate '<name>': metric '<path>' is in no run's results"
// for a gate that names a metric no successful run has.
Collected Collect(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                  const std::vector<SweepRun>& runs, const std::vector<RunOutcome>& outcomes);

// Writes sweep.csv, aggregate.json and (when there is something to plot) sweep.png.
void WriteCollected(const std::filesystem::path& out, const SweepSpec& spec,
                    const std::vector<SweepPoint>& points, const Collected& c);

}  // namespace flexbench::scenarios::sweep
