// `flexbench summary`: the table a person reads after many runs. One row per result folder (a
// run's summary.json or a sweep's aggregate.json): scenario, gates passed of total, a headline
// metric in its unit, time and size on disk.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

struct ResultRow {
  std::string scenario;  // the run's scenario or the sweep's name
  std::string folder;    // as given
  int gates_passed = 0;
  int gates_total = 0;
  std::string headline;  // "<what> <value> <unit>", or "" when no gate holds a number
  double seconds = -1;   // a run's timing.total_s; -1 when the folder does not say
  bool summed = false;   // seconds is the sum of a sweep's runs
  std::uintmax_t bytes = 0;
};

// The headline of a result: its first gate whose value is a number and whose metric name ends
// in a unit (_m, _deg, _px, ...), else its first gate whose value is a number. Metres are shown
// in mm and radians in mrad: the sizes of a flexible arm's errors.
std::string Headline(const Json& gates);

// Reads `dir`. Throws InputError naming the folder when it holds neither result file, or naming
// the file when it is not a result.
ResultRow ReadResultRow(const std::filesystem::path& dir);

// The rows as an aligned table with a header line.
std::string FormatResultTable(const std::vector<ResultRow>& rows);

// The row as tab-separated fields: scenario, passed, total, headline (for scripts).
std::string FormatResultTsv(const ResultRow& row);

// Prints the table (or with `tsv`, one tab-separated line per folder) of `dirs` on stdout.
// Returns an exit code (2: a folder is not a result; one line on stderr).
int SummaryCommand(const std::vector<std::string>& dirs, bool tsv);

}  // namespace flexbench::scenarios
