// The pieces of a recorded log's readers and writer that its stream files share
// (recorded_log.cc: joints, IMUs, truth; recorded_log_tags.cc: cameras and tag detections).
// Internal to sim/.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "sim/config.h"
#include "sim/recorded_log.h"

namespace flexbench::sim::log_internal {

// Times (s) and clock offsets beyond any recording (a Unix time is 1.7e9 s), so that sums and
// differences of them stay finite.
constexpr double kMaxLogTime = 1e12;

// Rows, duplicates, gaps and the median step of a stream whose rows of each sensor are `t`
// (already checked not to go backwards).
StreamStats Stats(const std::string& file, double offset,
                  const std::vector<const std::vector<double>*>& t);

// A stream's clock_offset_s (0 when absent), checked.
double ClockOffset(const ConfigNode& node);

// Lines of `file` (at most its rows plus a header), refused when they would take, with the
// streams read before (`*used` bytes), more than the log's memory limit; `*used` grows by theirs.
std::uintmax_t CheckRows(const std::string& file, double bytes_per_row, double* used);

// The time of a row on the log's clock: its t_s cell plus the stream's clock offset. The cell
// may not be before `*last` (the sensor's previous row's cell), which it then becomes.
double RowTime(const std::string& cell, const std::string& where, double offset, double* last,
               bool has_last);

// 17 significant digits: a number written reads back as itself.
std::string Num(double v);

// log.yaml's `cameras`, `tags` and `images` (recorded_log_tags.cc), tags.csv, and their writers.
void ReadCameras(const ConfigNode& node, RecordedLog* log);
void ReadTags(const ConfigNode& node, RecordedLog* log, double* used);
void ReadImages(const ConfigNode& node, RecordedLog* log);
std::string TagsYaml(const RecordedLog& log);
std::string TagsCsv(const RecordedLog& log);

// log.yaml's `contacts` and contacts.csv (recorded_log_contacts.cc), and their writers.
void ReadContacts(const ConfigNode& node, RecordedLog* log, double* used);
std::string ContactsYaml(const RecordedLog& log);
std::string ContactsCsv(const RecordedLog& log);

}  // namespace flexbench::sim::log_internal
