// The pieces of a recorded log's readers and writer that its stream files share
// (recorded_log.cc: joints, IMUs, truth; recorded_log_tags.cc: cameras and tag detections).
// Internal to sim/.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "sim/config.h"
#include "sim/csv.h"
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

// Reads the stream file's header, which must be `want` exactly, or `want` without its last
// `optional` columns (InputError naming its line and the column count or the first column that
// differs). Returns its column count.
size_t ReadHeader(CsvLines* csv, const std::string& file, const std::vector<std::string>& want,
                  size_t optional = 0);

// A stream file's header line: the columns, comma-separated, and a newline.
std::string HeaderLine(const std::vector<std::string>& columns);

// InputError at `where` when a row has another column count than the header's `want`.
void CheckRowColumns(const std::vector<std::string>& cells, size_t want, const std::string& where);

// The times of a stream several sensors share, each told apart by a pair of indices (a camera
// and a tag, a point and a plane): RowTime per sensor, and the stream's statistics.
class PairedTimes {
 public:
  double Take(std::pair<int, int> sensor, const std::string& cell, const std::string& where,
              double offset);
  StreamStats Stats(const std::string& file, double offset) const;

 private:
  std::map<std::pair<int, int>, std::vector<double>> times_;
  std::map<std::pair<int, int>, double> last_;
};

// Index of the first item `is` holds for, -1 when none.
template <typename T, typename Pred>
int IndexOf(const std::vector<T>& items, Pred is) {
  for (size_t i = 0; i < items.size(); ++i) {
    if (is(items[i])) return static_cast<int>(i);
  }
  return -1;
}

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

// log.yaml's `orientations`, `positions` and `postures` and their CSVs (recorded_log_poses.cc),
// and their writers.
void ReadOrientations(const ConfigNode& node, RecordedLog* log, double* used);
void ReadPositions(const ConfigNode& node, RecordedLog* log, double* used);
void ReadPostures(const ConfigNode& node, RecordedLog* log, double* used);
std::string PosturesCsv(const RecordedLog& log);
std::string PosesYaml(const RecordedLog& log);
std::string OrientationsCsv(const RecordedLog& log);
std::string PositionsCsv(const RecordedLog& log);

}  // namespace flexbench::sim::log_internal
