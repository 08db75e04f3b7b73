// A recorded log's orientation and position readings of observed frames and its postures
// (recorded_log.h): log.yaml's `orientations`, `positions` and `postures`, their CSVs, and their
// writers.
#include <cmath>
#include <sstream>

#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/csv.h"
#include "sim/recorded_log_streams.h"

namespace flexbench::sim::log_internal {
namespace {

const std::vector<std::string>& OrientationsHeader() {
  static const std::vector<std::string> h = {"t_s", "frame", "qw", "qx", "qy", "qz"};
  return h;
}

const std::vector<std::string>& PositionsHeader() {
  static const std::vector<std::string> h = {"t_s", "frame", "x_m", "y_m", "z_m", "std_m"};
  return h;
}

// The row's frame: its index in log->sensed_frames, appended when new.
int SensedFrame(const std::string& cell, const std::string& where, RecordedLog* log) {
  if (cell.empty()) throw InputError(where + ": column 'frame' is empty");
  int f = IndexOf(log->sensed_frames, [&](const std::string& s) { return s == cell; });
  if (f < 0) {
    log->sensed_frames.push_back(cell);
    f = static_cast<int>(log->sensed_frames.size()) - 1;
  }
  return f;
}

// Reads one of the two files: `row(cells, where)` parses a row's readings after its frame.
template <typename Row, typename Parse>
StreamStats ReadRows(const ConfigNode& node, const std::vector<std::string>& want,
                     std::vector<Row>* rows, RecordedLog* log, double* used, Parse parse) {
  const std::string file = node.ResolvePath(node.GetString("file"));
  const double offset = ClockOffset(node);
  CsvLines csv(file, kMaxLogStreamBytes);
  ReadHeader(&csv, file, want);
  rows->reserve(CheckRows(file, sizeof(Row) + 16.0, used));
  PairedTimes times;  // a frame's readings are a stream of their own
  std::vector<std::string> cells;
  while (csv.Next(&cells)) {
    const std::string where = csv.Where();
    CheckRowColumns(cells, want.size(), where);
    Row row;
    row.frame = SensedFrame(cells[1], where, log);
    row.t = times.Take({row.frame, 0}, cells[0], where, offset);
    parse(cells, where, &row);
    rows->push_back(row);
  }
  return times.Stats(file, offset);
}

}  // namespace

void ReadOrientations(const ConfigNode& node, RecordedLog* log, double* used) {
  log->orientation_stats = ReadRows(
      node, OrientationsHeader(), &log->orientations, log, used,
      [](const std::vector<std::string>& c, const std::string& where, LogOrientationRow* row) {
        Quat q(ParseCsvNumber(c[2], where, "qw", 2.0), ParseCsvNumber(c[3], where, "qx", 2.0),
               ParseCsvNumber(c[4], where, "qy", 2.0), ParseCsvNumber(c[5], where, "qz", 2.0));
        if (std::abs(q.norm() - 1.0) > 1e-6) {
          throw InputError(where + ": (qw, qx, qy, qz) is not of unit length");
        }
        // A quaternion written unit to the last digits is kept as it is (a replay's bits).
        if (std::abs(q.norm() - 1.0) > 1e-15) q.normalize();
        row->q_base_frame = q;
      });
}

void ReadPositions(const ConfigNode& node, RecordedLog* log, double* used) {
  log->position_stats = ReadRows(
      node, PositionsHeader(), &log->positions, log, used,
      [](const std::vector<std::string>& c, const std::string& where, LogPositionRow* row) {
        for (int a = 0; a < 3; ++a) {
          row->p_base[a] = ParseCsvNumber(c[2 + a], where, PositionsHeader()[2 + a], 1e3);
        }
        row->std_m = ParseCsvNumber(c[5], where, "std_m", 1e3);
        if (!(row->std_m > 0.0)) throw InputError(where + ": column 'std_m' must be > 0");
      });
}

void ReadPostures(const ConfigNode& node, RecordedLog* log, double* used) {
  const std::string file = node.ResolvePath(node.GetString("file"));
  const double offset = ClockOffset(node);
  CsvLines csv(file, kMaxLogStreamBytes);
  ReadHeader(&csv, file, {"t_s"});
  log->posture_starts.reserve(CheckRows(file, 16.0, used));
  std::vector<std::string> cells;
  double last = 0.0;
  while (csv.Next(&cells)) {
    CheckRowColumns(cells, 1, csv.Where());
    log->posture_starts.push_back(
        RowTime(cells[0], csv.Where(), offset, &last, !log->posture_starts.empty()));
  }
}

std::string PosesYaml(const RecordedLog& log) {
  std::string y;
  if (!log.orientations.empty()) y += "orientations: {file: orientations.csv}\n";
  if (!log.positions.empty()) y += "positions: {file: positions.csv}\n";
  if (!log.posture_starts.empty()) y += "postures: {file: postures.csv}\n";
  return y;
}

std::string PosturesCsv(const RecordedLog& log) {
  std::string c = HeaderLine({"t_s"});
  for (double t : log.posture_starts) c += ExactNum(t) + "\n";
  return c;
}

std::string OrientationsCsv(const RecordedLog& log) {
  std::ostringstream c;
  const std::vector<std::string>& h = OrientationsHeader();
  c << HeaderLine(h);
  for (const LogOrientationRow& r : log.orientations) {
    const Quat& q = r.q_base_frame;
    c << ExactNum(r.t) << "," << log.sensed_frames[r.frame] << "," << ExactNum(q.w()) << ","
      << ExactNum(q.x()) << "," << ExactNum(q.y()) << "," << ExactNum(q.z()) << "\n";
  }
  return c.str();
}

std::string PositionsCsv(const RecordedLog& log) {
  std::ostringstream c;
  const std::vector<std::string>& h = PositionsHeader();
  c << HeaderLine(h);
  for (const LogPositionRow& r : log.positions) {
    c << ExactNum(r.t) << "," << log.sensed_frames[r.frame] << "," << ExactNum(r.p_base.x()) << ","
      << ExactNum(r.p_base.y()) << "," << ExactNum(r.p_base.z()) << "," << ExactNum(r.std_m)
      << "\n";
  }
  return c.str();
}

}  // namespace flexbench::sim::log_internal
