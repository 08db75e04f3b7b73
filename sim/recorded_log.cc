#include "sim/recorded_log.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/config.h"
#include "sim/csv.h"
#include "sim/recorded_log_streams.h"

namespace flexbench::sim {
namespace log_internal {

StreamStats Stats(const std::string& file, double offset,
                  const std::vector<const std::vector<double>*>& t) {
  StreamStats s;
  s.file = file;
  s.clock_offset_s = offset;
  std::vector<double> steps;
  bool any = false;
  for (const std::vector<double>* sensor : t) {
    const std::vector<double>& ts = *sensor;
    s.rows += static_cast<int>(ts.size());
    if (ts.empty()) continue;
    s.t_first = any ? std::min(s.t_first, ts.front()) : ts.front();
    s.t_last = any ? std::max(s.t_last, ts.back()) : ts.back();
    any = true;
    for (size_t i = 1; i < ts.size(); ++i) {
      if (ts[i] == ts[i - 1]) {
        ++s.duplicates;
      } else {
        steps.push_back(ts[i] - ts[i - 1]);
      }
    }
  }
  if (steps.empty()) return s;
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  s.median_dt_s = steps[steps.size() / 2];
  for (double d : steps) s.gaps += d > 2.0 * s.median_dt_s;
  return s;
}

double ClockOffset(const ConfigNode& node) {
  const double offset = node.GetDouble("clock_offset_s", 0.0);
  if (!(std::abs(offset) <= kMaxLogTime)) {
    node.Child("clock_offset_s").Fail("must be a finite time in seconds, |offset| <= 1e12");
  }
  return offset;
}

// The most memory a log's rows may take (the streams together), checked from their line counts
// before a row is read: the byte cap alone lets a file of short rows take gigabytes.
constexpr double kMaxLogMemoryBytes = 2e9;

std::uintmax_t CheckRows(const std::string& file, double bytes_per_row, double* used) {
  const std::uintmax_t lines = CountLines(file);
  *used += static_cast<double>(lines) * bytes_per_row;
  if (*used > kMaxLogMemoryBytes) {
    char gb[64];
    std::snprintf(gb, sizeof(gb), "%.1f GB; the limit is %.1f GB", *used / 1e9,
                  kMaxLogMemoryBytes / 1e9);
    throw InputError(CapForMessage(file) + ": " + std::to_string(lines) +
                     " rows; the log would need about " + gb + " (split it or thin it)");
  }
  return lines;
}

// `v` in the fewest digits that read back as v.
std::string Shortest(double v) {
  char b[40];
  for (int digits = 15; digits <= 17; ++digits) {
    std::snprintf(b, sizeof(b), "%.*g", digits, v);
    if (std::strtod(b, nullptr) == v) break;
  }
  return b;
}

double RowTime(const std::string& cell, const std::string& where, double offset, double* last,
               bool has_last) {
  const double t = ParseCsvNumber(cell, where, "t_s", kMaxLogTime);
  if (has_last && t < *last) {
    throw InputError(where + ": column 't_s': " + Shortest(t) + " is before the previous row's " +
                     Shortest(*last) + " (times may not go backwards)");
  }
  *last = t;
  return t + offset;
}

size_t ReadHeader(CsvLines* csv, const std::string& file, const std::vector<std::string>& want,
                  size_t optional) {
  std::vector<std::string> header;
  if (!csv->Next(&header)) throw InputError(CapForMessage(file) + ": no header row");
  std::string names;
  for (size_t c = 0; c < want.size(); ++c) {
    names += (c ? "," : "") + std::string(c == want.size() - optional ? "[" : "") + want[c];
  }
  if (optional > 0) names += "]";
  if (header.size() != want.size() && header.size() != want.size() - optional) {
    throw InputError(csv->Where() + ": the header must be " + names + " (it has " +
                     std::to_string(header.size()) + " columns)");
  }
  for (size_t c = 0; c < header.size(); ++c) {
    if (header[c] != want[c]) {
      throw InputError(csv->Where() + ": the header must be " + names + " (column " +
                       std::to_string(c + 1) + " is '" + CapForMessage(header[c]) + "')");
    }
  }
  return header.size();
}

std::string HeaderLine(const std::vector<std::string>& columns) {
  std::string line;
  for (size_t i = 0; i < columns.size(); ++i) line += (i ? "," : "") + columns[i];
  return line + "\n";
}

void CheckRowColumns(const std::vector<std::string>& cells, size_t want, const std::string& where) {
  if (cells.size() != want) {
    throw InputError(where + ": " + std::to_string(cells.size()) + " columns, the header has " +
                     std::to_string(want));
  }
}

double PairedTimes::Take(std::pair<int, int> sensor, const std::string& cell,
                         const std::string& where, double offset) {
  std::vector<double>& ts = times_[sensor];
  const double t = RowTime(cell, where, offset, &last_[sensor], !ts.empty());
  ts.push_back(t);
  return t;
}

StreamStats PairedTimes::Stats(const std::string& file, double offset) const {
  std::vector<const std::vector<double>*> streams;
  for (const auto& [sensor, ts] : times_) streams.push_back(&ts);
  return log_internal::Stats(file, offset, streams);
}

}  // namespace log_internal

namespace {

using log_internal::CheckRowColumns;
using log_internal::CheckRows;
using log_internal::ClockOffset;
using log_internal::ContactsCsv;
using log_internal::ContactsYaml;
using log_internal::kMaxLogTime;
using log_internal::OrientationsCsv;
using log_internal::PosesYaml;
using log_internal::PositionsCsv;
using log_internal::PosturesCsv;
using log_internal::ReadCameras;
using log_internal::ReadContacts;
using log_internal::ReadHeader;
using log_internal::ReadImages;
using log_internal::ReadOrientations;
using log_internal::ReadPositions;
using log_internal::ReadPostures;
using log_internal::ReadTags;
using log_internal::RowTime;
using log_internal::Stats;
using log_internal::TagsCsv;
using log_internal::TagsYaml;

// A file of a time column and one column per joint, <joint>_rad (<joint>_m for a slide):
// joints.csv and commands.csv.
struct JointColumnsFile {
  std::vector<std::string> names;
  std::vector<char> is_slide;
  std::vector<double> t;
  std::vector<double> values;  // row-major, names.size() a row
  StreamStats stats;
};

// The unit suffixes of a joint-columns file: angles (rad, m) or torques (N m, N).
struct ColumnUnits {
  const char* hinge;
  const char* slide;
};
constexpr ColumnUnits kAngleUnits{"_rad", "_m"};
constexpr ColumnUnits kTorqueUnits{"_Nm", "_N"};

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() > suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

JointColumnsFile ReadJointColumnsFile(const ConfigNode& node, double* used,
                                      ColumnUnits units = kAngleUnits) {
  JointColumnsFile f;
  const std::string file = node.ResolvePath(node.GetString("file"));
  const double offset = ClockOffset(node);
  CsvLines csv(file, kMaxLogStreamBytes);
  std::vector<std::string> header;
  if (!csv.Next(&header)) throw InputError(CapForMessage(file) + ": no header row");
  const std::string hdr = csv.Where();
  if (header[0] != "t_s") {
    throw InputError(hdr + ": column 1 is '" + CapForMessage(header[0]) + "', expected 't_s'");
  }
  for (size_t c = 1; c < header.size(); ++c) {
    const std::string& h = header[c];
    const bool rad = EndsWith(h, units.hinge);
    const bool m = !rad && EndsWith(h, units.slide);
    if (!rad && !m) {
      throw InputError(hdr + ": column '" + CapForMessage(h) + "': expected <joint>" + units.hinge +
                       " or <joint>" + units.slide + " (the unit in the name)");
    }
    const std::string joint =
        h.substr(0, h.size() - std::string(rad ? units.hinge : units.slide).size());
    if (std::count(f.names.begin(), f.names.end(), joint) > 0) {
      throw InputError(hdr + ": joint '" + CapForMessage(joint) + "' has two columns");
    }
    f.names.push_back(joint);
    f.is_slide.push_back(!rad);
  }
  if (f.names.empty()) throw InputError(hdr + ": no joint column after 't_s'");
  // A row: its time, its angles, and its step in the statistics.
  const std::uintmax_t lines = CheckRows(file, 8.0 * (2 + f.names.size()), used);
  f.t.reserve(lines);
  f.values.reserve(lines * f.names.size());
  std::vector<std::string> cells;
  double last = 0.0;
  while (csv.Next(&cells)) {
    const std::string where = csv.Where();
    if (cells.size() != header.size()) {
      throw InputError(where + ": " + std::to_string(cells.size()) + " columns, the header has " +
                       std::to_string(header.size()));
    }
    f.t.push_back(RowTime(cells[0], where, offset, &last, !f.t.empty()));
    for (size_t c = 1; c < cells.size(); ++c) {
      f.values.push_back(ParseCsvNumber(cells[c], where, header[c], 1e3));
    }
  }
  if (f.t.empty()) throw InputError(CapForMessage(file) + ": no data rows");
  f.stats = Stats(file, offset, {&f.t});
  return f;
}

void ReadJoints(const ConfigNode& node, RecordedLog* log, double* used) {
  log->joint_std = node.GetDouble("std_rad", 0.0);
  if (!(log->joint_std >= 0.0 && log->joint_std <= 1.0)) {
    node.Child("std_rad").Fail("must be in [0, 1]");
  }
  JointColumnsFile f = ReadJointColumnsFile(node, used);
  log->joints = std::move(f.names);
  log->joint_is_slide = std::move(f.is_slide);
  log->joint_t = std::move(f.t);
  log->joint_q = std::move(f.values);
  log->joint_stats = f.stats;
}

void ReadCommands(const ConfigNode& node, RecordedLog* log, double* used) {
  const std::string type = node.GetString("type", "position");
  if (type != "position" && type != "torque") {
    node.Child("type").Fail("'" + CapForMessage(type) +
                            "': position (the servos' targets) or torque (the motors')");
  }
  log->command_torque = type == "torque";
  JointColumnsFile f =
      ReadJointColumnsFile(node, used, log->command_torque ? kTorqueUnits : kAngleUnits);
  log->command_joints = std::move(f.names);
  log->command_is_slide = std::move(f.is_slide);
  log->command_t = std::move(f.t);
  log->command_q = std::move(f.values);
  log->command_stats = f.stats;
}

void ReadImuSensors(const ConfigNode& sensors, RecordedLog* log) {
  for (const std::string& name : sensors.Keys()) {
    const ConfigNode s = sensors.Child(name);
    LogImu imu;
    imu.name = name;
    imu.frame = s.GetString("frame");
    if (const auto q = s.Optional("initial_wxyz")) {
      const std::vector<double> v = q->AsDoubleList();
      const Eigen::Vector4d w(v.size() == 4 ? v[0] : 0.0, v.size() == 4 ? v[1] : 0.0,
                              v.size() == 4 ? v[2] : 0.0, v.size() == 4 ? v[3] : 0.0);
      if (v.size() != 4 || !w.allFinite() || !(w.norm() > 0.0)) {
        q->Fail("expected [w, x, y, z], finite and not zero");
      }
      imu.has_initial = true;
      imu.q_base_frame_initial = Quat(w[0], w[1], w[2], w[3]);  // the filter normalises it
    }
    imu.filter_beta = s.GetDouble("filter_beta", imu.filter_beta);
    if (!(imu.filter_beta > 0.0 && imu.filter_beta < 1e3)) {
      s.Child("filter_beta").Fail("must be > 0 (Madgwick's gain, rad/s)");
    }
    log->imus.push_back(imu);
  }
  if (log->imus.empty()) sensors.Fail("names no sensor");
}

void ReadImu(const ConfigNode& node, RecordedLog* log, double* used) {
  const std::string file = node.ResolvePath(node.GetString("file"));
  const double offset = ClockOffset(node);
  log->gyro_std = node.GetDouble("gyro_std_rad_s", 0.0);
  log->accel_std = node.GetDouble("accel_std_m_s2", 0.0);
  if (!(log->gyro_std >= 0.0 && log->gyro_std <= 1e3)) {
    node.Child("gyro_std_rad_s").Fail("must be in [0, 1000]");
  }
  if (!(log->accel_std >= 0.0 && log->accel_std <= 1e4)) {
    node.Child("accel_std_m_s2").Fail("must be in [0, 10000]");
  }
  ReadImuSensors(node.Child("sensors"), log);
  CsvLines csv(file, kMaxLogStreamBytes);
  static const std::vector<std::string> kHeader = {"t_s",      "sensor",  "gx_rad_s", "gy_rad_s",
                                                   "gz_rad_s", "ax_m_s2", "ay_m_s2",  "az_m_s2"};
  ReadHeader(&csv, file, kHeader);
  // A row: the reading, its time among its sensor's, its step in the statistics.
  log->imu.reserve(CheckRows(file, sizeof(estimators::ImuReading) + 16.0, used));
  std::vector<std::vector<double>> times(log->imus.size());
  std::vector<double> last(log->imus.size(), 0.0);
  std::vector<std::string> cells;
  while (csv.Next(&cells)) {
    const std::string where = csv.Where();
    CheckRowColumns(cells, kHeader.size(), where);
    int k = -1;
    std::string names;
    for (size_t i = 0; i < log->imus.size(); ++i) {
      if (log->imus[i].name == cells[1]) k = static_cast<int>(i);
      names += (names.empty() ? "" : ", ") + log->imus[i].name;
    }
    if (k < 0) {
      throw InputError(where + ": column 'sensor': '" + CapForMessage(cells[1]) +
                       "' is not a sensor of the log's imu.sensors (" + names + ")");
    }
    std::vector<double>& ts = times[k];
    estimators::ImuReading z;
    z.imu = k;
    z.t = RowTime(cells[0], where, offset, &last[k], !ts.empty());
    for (int a = 0; a < 3; ++a) {
      z.gyro[a] = ParseCsvNumber(cells[2 + a], where, kHeader[2 + a], 1e3);
      z.accel[a] = ParseCsvNumber(cells[5 + a], where, kHeader[5 + a], 1e4);
    }
    ts.push_back(z.t);
    log->imu.push_back(z);
  }
  std::vector<const std::vector<double>*> sensors;
  for (const std::vector<double>& ts : times) sensors.push_back(&ts);
  log->imu_stats = Stats(file, offset, sensors);
}

void ReadTruth(const ConfigNode& node, RecordedLog* log, double* used) {
  const std::string file = node.ResolvePath(node.GetString("file"));
  log->truth_frame = node.GetString("frame");
  CheckInputFile(file, kMaxLogStreamBytes);
  const std::uintmax_t lines = CheckRows(file, sizeof(lie::SE3) + 16.0, used);
  log->truth_t.reserve(lines);
  log->truth.reserve(lines);
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(CapForMessage(file) + ": cannot open");
  static const char* kNames[8] = {"t", "x", "y", "z", "qx", "qy", "qz", "qw"};
  std::string line;
  for (int line_no = 1; std::getline(in, line); ++line_no) {
    const std::string t = TrimBlanks(line);
    if (t.empty() || t[0] == '#') continue;
    const std::string where = CapForMessage(file) + ":" + std::to_string(line_no);
    std::istringstream ss(t);
    std::vector<std::string> cells;
    for (std::string cell; ss >> cell;) cells.push_back(cell);
    if (cells.size() != 8) {
      throw InputError(where + ": " + std::to_string(cells.size()) +
                       " values, expected 8 (t x y z qx qy qz qw)");
    }
    double v[8];
    for (int i = 0; i < 8; ++i) v[i] = ParseCsvNumber(cells[i], where, kNames[i], kMaxLogTime);
    if (!log->truth_t.empty() && v[0] < log->truth_t.back()) {
      throw InputError(where +
                       ": column 't': the time is before the previous line's (times may "
                       "not go backwards)");
    }
    const Quat q(v[7], v[4], v[5], v[6]);
    if (!(q.norm() > 0.0)) throw InputError(where + ": the quaternion is zero");
    log->truth_t.push_back(v[0]);
    log->truth.emplace_back(q.normalized().toRotationMatrix(), Vec3(v[1], v[2], v[3]));
  }
  log->truth_stats = Stats(file, 0.0, {&log->truth_t});
}

}  // namespace

RecordedLog ReadRecordedLog(const std::string& dir) {
  RecordedLog log;
  log.dir = dir;
  const ConfigNode root = ConfigNode::LoadFile(dir + "/log.yaml");
  log.robot = root.GetString("robot", "");
  log.declared_path = root.ResolvePath(root.GetString("declared"));
  log.static_postures = root.GetBool("static_postures", false);
  log.estimate_in = root.GetString("estimate_in", "");
  double used = 0.0;  // bytes the streams' rows take
  ReadJoints(root.Child("joints"), &log, &used);
  if (const auto c = root.Optional("commands")) ReadCommands(*c, &log, &used);
  if (const auto imu = root.Optional("imu")) ReadImu(*imu, &log, &used);
  if (const auto truth = root.Optional("truth")) ReadTruth(*truth, &log, &used);
  if (const auto cameras = root.Optional("cameras")) ReadCameras(*cameras, &log);
  if (const auto tags = root.Optional("tags")) ReadTags(*tags, &log, &used);
  if (const auto contacts = root.Optional("contacts")) ReadContacts(*contacts, &log, &used);
  if (const auto o = root.Optional("orientations")) ReadOrientations(*o, &log, &used);
  if (const auto p = root.Optional("positions")) ReadPositions(*p, &log, &used);
  if (const auto p = root.Optional("postures")) ReadPostures(*p, &log, &used);
  if (const auto images = root.Optional("images")) {
    if (!log.tag_rows.empty() || (root.Has("tags") && root.Child("tags").Has("file"))) {
      images->Fail("a log has tags.csv or images, not both");
    }
    ReadImages(*images, &log);
  } else if (!log.tags.empty() && !root.Child("tags").Has("file")) {
    root.Child("tags").Fail("needs `file` (tags.csv), or the log's `images`");
  }
  root.CheckNoUnknownKeys();
  return log;
}

namespace {

void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out.flush()) throw InputError(CapForMessage(path.string()) + ": cannot write");
}

std::string LogYaml(const RecordedLog& log) {
  std::ostringstream y;
  y << "# A recorded log (flexbench replay reads it).\n";
  if (!log.robot.empty()) y << "robot: " << log.robot << "\n";
  y << "declared: " << log.declared_path << "\njoints: {file: joints.csv";
  if (log.joint_std > 0.0) y << ", std_rad: " << ExactNum(log.joint_std);
  y << "}\n";
  if (!log.imus.empty()) {
    y << "imu:\n  file: imu.csv\n";
    if (log.gyro_std > 0.0) y << "  gyro_std_rad_s: " << ExactNum(log.gyro_std) << "\n";
    if (log.accel_std > 0.0) y << "  accel_std_m_s2: " << ExactNum(log.accel_std) << "\n";
    y << "  sensors:\n";
    for (const LogImu& imu : log.imus) {
      y << "    " << imu.name << ": {frame: " << imu.frame
        << ", filter_beta: " << ExactNum(imu.filter_beta);
      if (imu.has_initial) {
        const Quat& q = imu.q_base_frame_initial;
        y << ", initial_wxyz: [" << ExactNum(q.w()) << ", " << ExactNum(q.x()) << ", "
          << ExactNum(q.y()) << ", " << ExactNum(q.z()) << "]";
      }
      y << "}\n";
    }
  }
  if (!log.command_t.empty()) {
    y << "commands: {file: commands.csv, type: " << (log.command_torque ? "torque" : "position")
      << "}\n";
  }
  if (!log.truth_t.empty()) y << "truth: {file: truth.tum, frame: " << log.truth_frame << "}\n";
  if (log.static_postures) y << "static_postures: true\n";
  if (!log.estimate_in.empty()) y << "estimate_in: " << log.estimate_in << "\n";
  y << TagsYaml(log) << ContactsYaml(log) << PosesYaml(log);
  return y.str();
}

std::string JointColumnsCsv(const std::vector<std::string>& names, const std::vector<char>& slide,
                            const std::vector<double>& t, const std::vector<double>& values,
                            ColumnUnits units = kAngleUnits) {
  std::ostringstream j;
  j << "t_s";
  for (size_t k = 0; k < names.size(); ++k) {
    j << "," << names[k] << (slide[k] ? units.slide : units.hinge);
  }
  j << "\n";
  for (size_t r = 0; r < t.size(); ++r) {
    j << ExactNum(t[r]);
    for (size_t k = 0; k < names.size(); ++k) j << "," << ExactNum(values[r * names.size() + k]);
    j << "\n";
  }
  return j.str();
}

// The files of WriteRecordedLog into the folder `tmp`.
void WriteLogFiles(const RecordedLog& log, const std::filesystem::path& tmp,
                   const std::vector<std::pair<std::string, std::string>>& files);

}  // namespace

void WriteRecordedLog(const RecordedLog& log, const std::string& dir,
                      const std::vector<std::pair<std::string, std::string>>& files) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::path target = fs::absolute(dir).lexically_normal();
  if (target.filename().empty()) target = target.parent_path();
  if (fs::exists(target, ec)) {
    throw InputError(CapForMessage(dir) + ": exists; a log is written into a new folder");
  }
  const fs::path tmp = target.string() + ".tmp";
  if (fs::exists(tmp, ec)) {
    throw InputError(CapForMessage(tmp.string()) +
                     ": exists (another log being written?); remove it or name another folder");
  }
  fs::create_directories(tmp);
  try {
    WriteLogFiles(log, tmp, files);
    fs::rename(tmp, target);
  } catch (const std::exception& e) {
    fs::remove_all(tmp, ec);  // ours alone: it did not exist before
    if (dynamic_cast<const InputError*>(&e)) throw;
    throw InputError(CapForMessage(dir) + ": cannot write the log (" + e.what() + ")");
  }
}

namespace {

void WriteLogFiles(const RecordedLog& log, const std::filesystem::path& tmp,
                   const std::vector<std::pair<std::string, std::string>>& files) {
  namespace fs = std::filesystem;
  for (const auto& [name, text] : files) WriteText(tmp / name, text);
  WriteText(tmp / "joints.csv",
            JointColumnsCsv(log.joints, log.joint_is_slide, log.joint_t, log.joint_q));
  if (!log.command_t.empty()) {
    WriteText(tmp / "commands.csv",
              JointColumnsCsv(log.command_joints, log.command_is_slide, log.command_t,
                              log.command_q, log.command_torque ? kTorqueUnits : kAngleUnits));
  }
  if (!log.imus.empty()) {
    std::ostringstream i;
    i << "t_s,sensor,gx_rad_s,gy_rad_s,gz_rad_s,ax_m_s2,ay_m_s2,az_m_s2\n";
    for (const estimators::ImuReading& z : log.imu) {
      i << ExactNum(z.t) << "," << log.imus[z.imu].name;
      for (int a = 0; a < 3; ++a) i << "," << ExactNum(z.gyro[a]);
      for (int a = 0; a < 3; ++a) i << "," << ExactNum(z.accel[a]);
      i << "\n";
    }
    WriteText(tmp / "imu.csv", i.str());
  }
  if (!log.truth_t.empty()) {
    std::ostringstream t;
    t << "# t x y z qx qy qz qw (" << log.truth_frame << " in the base frame; m, s)\n";
    for (size_t r = 0; r < log.truth_t.size(); ++r) {
      const Vec3& p = log.truth[r].translation();
      const Quat q(log.truth[r].rotation());
      t << ExactNum(log.truth_t[r]) << " " << ExactNum(p.x()) << " " << ExactNum(p.y()) << " "
        << ExactNum(p.z()) << " " << ExactNum(q.x()) << " " << ExactNum(q.y()) << " "
        << ExactNum(q.z()) << " " << ExactNum(q.w()) << "\n";
    }
    WriteText(tmp / "truth.tum", t.str());
  }
  if (!log.tags.empty() && log.images.empty()) WriteText(tmp / "tags.csv", TagsCsv(log));
  if (!log.planes.empty()) WriteText(tmp / "contacts.csv", ContactsCsv(log));
  if (!log.orientations.empty()) WriteText(tmp / "orientations.csv", OrientationsCsv(log));
  if (!log.positions.empty()) WriteText(tmp / "positions.csv", PositionsCsv(log));
  if (!log.posture_starts.empty()) WriteText(tmp / "postures.csv", PosturesCsv(log));
  WriteText(tmp / "log.yaml", LogYaml(log));
}

}  // namespace

bool TruthAt(const RecordedLog& log, double t, lie::SE3* T) {
  const std::vector<double>& ts = log.truth_t;
  if (ts.empty() || t < ts.front() || t > ts.back()) return false;
  const size_t i = std::upper_bound(ts.begin(), ts.end(), t) - ts.begin();
  if (i == ts.size()) {
    *T = log.truth.back();
    return true;
  }
  const size_t a = i - 1;
  const double span = ts[i] - ts[a];
  const double s = span > 0.0 ? (t - ts[a]) / span : 0.0;
  const Quat qa(log.truth[a].rotation()), qb(log.truth[i].rotation());
  *T = lie::SE3(qa.slerp(s, qb).toRotationMatrix(),
                (1.0 - s) * log.truth[a].translation() + s * log.truth[i].translation());
  return true;
}

std::vector<int> JointColumns(const RecordedLog& log, const std::vector<std::string>& q_joints,
                              const std::vector<char>& slide, const std::string& declared_file) {
  const std::string where = log.joint_stats.file + ":1";
  std::vector<int> column;
  for (size_t k = 0; k < q_joints.size(); ++k) {
    const std::string& j = q_joints[k];
    const auto it = std::find(log.joints.begin(), log.joints.end(), j);
    if (it == log.joints.end()) {
      throw InputError(where + ": no column for declared joint '" + j + "' (" + j +
                       "_rad, or _m for a slide)");
    }
    const int c = static_cast<int>(it - log.joints.begin());
    if (static_cast<bool>(slide[k]) != static_cast<bool>(log.joint_is_slide[c])) {
      throw InputError(where + ": column '" + j + (log.joint_is_slide[c] ? "_m" : "_rad") +
                       "': " + declared_file + " declares '" + j + "' " +
                       (slide[k] ? "a slide (" + j + "_m)" : "revolute (" + j + "_rad)"));
    }
    column.push_back(c);
  }
  for (const std::string& c : log.joints) {
    if (std::find(q_joints.begin(), q_joints.end(), c) == q_joints.end()) {
      throw InputError(where + ": column '" + c + "': " + declared_file +
                       " declares no joint of that name");
    }
  }
  return column;
}

bool JointsAt(const RecordedLog& log, const std::vector<int>& column, double t,
              Eigen::VectorXd* q) {
  const std::vector<double>& ts = log.joint_t;
  if (ts.empty() || t < ts.front() || t > ts.back()) return false;
  const size_t i = std::upper_bound(ts.begin(), ts.end(), t) - ts.begin();
  q->resize(static_cast<int>(column.size()));
  const size_t a = i - 1, b = std::min(i, ts.size() - 1);
  const double span = ts[b] - ts[a];
  const double s = span > 0.0 ? (t - ts[a]) / span : 0.0;
  for (size_t k = 0; k < column.size(); ++k) {
    (*q)[static_cast<int>(k)] = (1.0 - s) * log.q(a)[column[k]] + s * log.q(b)[column[k]];
  }
  return true;
}

}  // namespace flexbench::sim
