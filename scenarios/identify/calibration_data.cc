#include "scenarios/identify/calibration_data.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include "estimators/error.h"
#include "sim/config.h"
#include "sim/csv.h"

namespace flexbench::identify {
namespace {

// Largest magnitudes accepted: far beyond any arm (joint readings in rad or m, points in m,
// pixels), small enough that squares and sums of them stay finite.
constexpr double kMaxJoint = 1e3;
constexpr double kMaxCoordinate = 1e3;
constexpr double kMaxPixel = 1e6;

std::string Gigabytes(double bytes) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.1f GB", bytes / 1e9);
  return b;
}

// Refuses a file whose rows would need more than kMaxCalibrationMemoryBytes, before any is read:
// the byte cap alone lets a file of a million short rows take gigabytes. Returns its lines.
std::uintmax_t CheckRowMemory(const std::string& path, size_t num_joints) {
  const std::uintmax_t rows = sim::CountLines(path);
  const double need =
      static_cast<double>(rows) * static_cast<double>(CalibrationBytesPerRow(num_joints));
  if (need > static_cast<double>(kMaxCalibrationMemoryBytes)) {
    throw InputError(CapForMessage(path) + ": " + std::to_string(rows) + " rows need about " +
                     Gigabytes(need) + " of memory to identify; the limit is " +
                     Gigabytes(static_cast<double>(kMaxCalibrationMemoryBytes)) +
                     " (split the data or thin it)");
  }
  return rows;
}

// The data lines of a calibration CSV (sim::CsvLines), opened once the memory its rows would
// take to identify was checked (CheckRowMemory).
class CsvLines {
 public:
  // `num_joints`: the joint columns a row holds, for the memory estimate.
  CsvLines(const std::string& path, size_t num_joints)
      : lines_(CheckRows(path, num_joints)), csv_(path, kMaxCalibrationCsvBytes) {}
  bool Next(std::vector<std::string>* cells) { return csv_.Next(cells); }
  std::string Where() const { return csv_.Where(); }
  // Lines of the file: at most its data rows plus one (the header).
  std::uintmax_t lines() const { return lines_; }

 private:
  static std::uintmax_t CheckRows(const std::string& path, size_t num_joints) {
    CheckInputFile(path, kMaxCalibrationCsvBytes);
    return CheckRowMemory(path, num_joints);
  }
  std::uintmax_t lines_;
  sim::CsvLines csv_;
};

// Group labels are global: rows with one label share one fixed point whatever their set. A
// label used in several sets (e.g. "hole_0" for every placement) is almost always meant per
// set; it is named on stderr with the fix.
void WarnGroupsSpanningSets(const DataSet& data, size_t first_row) {
  std::map<int, std::pair<int, size_t>> first;  // group -> (set, row)
  int warned = 0;
  std::set<int> done;
  for (size_t r = first_row; r < data.rows.size(); ++r) {
    const Observation& o = data.rows[r];
    if (o.type != ObservationType::kGroup) continue;
    const auto it = first.find(o.group);
    if (it == first.end()) {
      first[o.group] = {o.set, r};
      continue;
    }
    if (it->second.first == o.set || done.count(o.group)) continue;
    done.insert(o.group);
    if (++warned > 3) continue;
    const std::string g = CapForMessage(data.groups[o.group], 60);
    std::cerr << "[flexbench] warning: " << o.where << ": group '" << g << "' spans sets '"
              << CapForMessage(data.sets[it->second.first], 60) << "' and '"
              << CapForMessage(data.sets[o.set], 60) << "' (first at "
              << data.rows[it->second.second].where
              << "); group labels are global (one fixed point for all its rows): if each set is "
                 "a placement, label the groups per set, e.g. '"
              << CapForMessage(data.sets[o.set], 60) << "/" << g << "'\n";
  }
  if (warned > 3) {
    std::cerr << "[flexbench] warning: " << warned - 3 << " more groups span several sets\n";
  }
}

// LabelIndex with a hash index: a linear search per row made reading a file whose rows each
// carry their own label quadratic in the rows.
class LabelIndexer {
 public:
  explicit LabelIndexer(std::vector<std::string>* labels) : labels_(labels) {
    for (size_t i = 0; i < labels->size(); ++i) index_.emplace((*labels)[i], static_cast<int>(i));
  }
  int operator()(const std::string& label) {
    const auto [it, added] = index_.emplace(label, static_cast<int>(labels_->size()));
    if (added) labels_->push_back(label);
    return it->second;
  }

 private:
  std::vector<std::string>* labels_;
  std::unordered_map<std::string, int> index_;
};

// The row's `frame` cell: `base`, or a measurement frame of the data set (DataSet::frames), in
// which its point (and orientation) were measured.
void SetRowFrame(const std::string& cell, const std::string& where, const DataSet& data,
                 Observation* o) {
  if (cell == "base") return;
  int f = -1;
  std::string names = "base";
  for (size_t k = 0; k < data.frames.size(); ++k) {
    if (data.frames[k].name == cell) f = static_cast<int>(k);
    names += ", " + data.frames[k].name;
  }
  if (f < 0) {
    throw InputError(
        where + ": column 'frame': '" + CapForMessage(cell) +
        "' is not a declared measurement frame (declared: " + names +
        "; declare it in the scenario's 'frames' key, --frame NAME on the command line)");
  }
  if (o->type != ObservationType::kPoint && o->type != ObservationType::kPose) {
    throw InputError(where + ": column 'frame': only point and pose rows (x, y, z) are measured " +
                     "in a frame; this row's frame must be 'base'");
  }
  o->frame = f;
  o->p_frame = o->p_base;
  o->R_frame = o->R_base;
  o->p_base.setZero();
  o->R_base.setIdentity();
}

// The row's `marker` cell: the frame of the declared model it measures, one of DataSet::points.
int MarkerIndex(const std::string& cell, const std::string& where, const DataSet& data) {
  std::string names;
  for (size_t k = 0; k < data.points.size(); ++k) {
    if (data.points[k] == cell) return static_cast<int>(k);
    names += (k ? ", " : "") + data.points[k];
  }
  throw InputError(where + ": column 'marker': '" + CapForMessage(cell) +
                   "' is not a measured frame of the declared model (" +
                   (names.empty() ? std::string("none declared") : "measured: " + names) +
                   "; the scenario's 'markers' key, --marker NAME on the command line)");
}

}  // namespace

namespace {

// The log's set label (its folder's name).
int LogSet(const sim::RecordedLog& log, DataSet* data) {
  const std::string folder = std::filesystem::path(log.dir).lexically_normal().filename().string();
  return LabelIndex(&data->sets, folder.empty() ? "log" : folder);
}

// Labels the rows from `first` on (their times `times`) with `time_blocks` equal spans of the
// source's time: [t_from, t_to] within the joints' span, the same for every kind of row of a
// log, so that a fold holds what was measured at one time.
void LabelTimeSpans(const sim::RecordedLog& log, double t_from, double t_to,
                    const std::vector<double>& times, size_t first, int time_blocks,
                    DataSet* data) {
  if (times.empty()) return;
  const double t0 = std::max(t_from, log.joint_t.front());
  const double span = std::min(t_to, log.joint_t.back()) - t0;
  for (size_t i = 0; i < times.size(); ++i) {
    const int k = span > 0.0 ? std::clamp(static_cast<int>(time_blocks * (times[i] - t0) / span), 0,
                                          time_blocks - 1)
                             : 0;
    data->rows[first + i].pose = LabelIndex(&data->poses, "span" + std::to_string(k));
  }
}

std::string LogWhere(const std::string& file, double t) {
  char where[64];
  std::snprintf(where, sizeof(where), " t=%.9g", t);
  return file + where;
}

}  // namespace

int AppendLogPoints(const sim::RecordedLog& log, const std::vector<int>& column, double t_from,
                    double t_to, int point, DataSet* data, int frame, int time_blocks) {
  const int set = LogSet(log, data);
  const size_t first = data->rows.size();
  std::vector<double> times;
  for (size_t r = 0; r < log.truth_t.size(); ++r) {
    const double t = log.truth_t[r];
    Observation o;
    if (t < t_from || t > t_to || !sim::JointsAt(log, column, t, &o.q)) continue;
    o.type = ObservationType::kPoint;
    o.set = set;
    o.point = point;
    o.frame = frame;
    (frame >= 0 ? o.p_frame : o.p_base) = log.truth[r].translation();
    o.where = LogWhere(log.truth_stats.file, t);
    data->rows.push_back(std::move(o));
    times.push_back(t);
  }
  LabelTimeSpans(log, t_from, t_to, times, first, time_blocks, data);
  return static_cast<int>(times.size());
}

int AppendLogPixels(const sim::RecordedLog& log, const std::vector<int>& column, double t_from,
                    double t_to, int camera, const std::vector<int>& tag_points, DataSet* data,
                    int time_blocks) {
  const int set = LogSet(log, data);
  const size_t first = data->rows.size();
  std::vector<double> times;
  for (const sim::LogTagRow& row : log.tag_rows) {
    Observation o;
    if (row.camera != camera || tag_points[row.tag] < 0 || row.t < t_from || row.t > t_to ||
        !sim::JointsAt(log, column, row.t, &o.q)) {
      continue;
    }
    if (!row.centre.allFinite()) continue;  // degenerate corners: no centre
    o.type = ObservationType::kPixel;
    o.set = set;
    o.point = tag_points[row.tag];
    o.uv = row.centre;
    o.where = LogWhere(log.tag_stats.file, row.t);
    data->rows.push_back(std::move(o));
    times.push_back(row.t);
  }
  LabelTimeSpans(log, t_from, t_to, times, first, time_blocks, data);
  return static_cast<int>(times.size());
}

int AppendLogGravity(const sim::RecordedLog& log, const std::vector<StaticWindow>& windows,
                     double t_from, double t_to, const std::vector<int>& imu_points, DataSet* data,
                     int time_blocks) {
  const int set = LogSet(log, data);
  const size_t first = data->rows.size();
  std::vector<double> times;
  for (const StaticWindow& w : windows) {
    if (imu_points[w.sensor] < 0) continue;
    Observation o;
    o.type = ObservationType::kGravity;
    o.q = w.q;
    o.set = set;
    o.point = imu_points[w.sensor];
    o.up() = w.up;
    char span[64];
    std::snprintf(span, sizeof(span), " t=%.9g..%.9g", w.t_begin, w.t_end);
    o.where = log.imu_stats.file + span;
    data->rows.push_back(std::move(o));
    times.push_back(0.5 * (w.t_begin + w.t_end));
  }
  LabelTimeSpans(log, t_from, t_to, times, first, time_blocks, data);
  return static_cast<int>(times.size());
}

int LabelIndex(std::vector<std::string>* labels, const std::string& label) {
  for (size_t i = 0; i < labels->size(); ++i) {
    if ((*labels)[i] == label) return static_cast<int>(i);
  }
  labels->push_back(label);
  return static_cast<int>(labels->size()) - 1;
}

namespace {

// Where each column of a calibration CSV is (-1: absent), and what kind of rows it holds.
struct CsvColumns {
  std::vector<int> joint_col, motion_col;
  int frame_col = -1, marker_col = -1;
  int group_col = -1, set_col = -1, pose_col = -1, xyz_col[3] = {-1, -1, -1},
      quat_col[4] = {-1, -1, -1, -1}, uv_col[2] = {-1, -1}, up_col[3] = {-1, -1, -1};
  bool has_xyz = false, has_uv = false, has_up = false;
  int num_quat = 0;
};

// The header: every column known, none twice, no column for a coupled joint.
CsvColumns ParseHeader(const std::vector<std::string>& header, const std::string& hdr,
                       const std::vector<std::string>& joints,
                       const std::function<bool(const std::string&)>& is_coupled) {
  CsvColumns cols;
  cols.joint_col.assign(joints.size(), -1);
  cols.motion_col.assign(joints.size(), -1);
  for (size_t c = 0; c < header.size(); ++c) {
    const std::string& h = header[c];
    for (size_t k = 0; k < c; ++k) {
      if (header[k] == h) throw InputError(hdr + ": column '" + CapForMessage(h) + "' twice");
    }
    bool known = false;
    for (size_t j = 0; j < joints.size(); ++j) {
      if (joints[j] == h) {
        if (is_coupled(h)) {
          throw InputError(hdr + ": column '" + h +
                           "' is a coupled joint (the declared model's coupled:): its angle "
                           "follows from its drivers, give no column for it");
        }
        cols.joint_col[j] = static_cast<int>(c);
        known = true;
      }
    }
    if (h == "group") cols.group_col = static_cast<int>(c), known = true;
    if (h == "set") cols.set_col = static_cast<int>(c), known = true;
    if (h == "pose") cols.pose_col = static_cast<int>(c), known = true;
    if (h == "frame") cols.frame_col = static_cast<int>(c), known = true;
    if (h == "marker") cols.marker_col = static_cast<int>(c), known = true;
    if (h == "x") cols.xyz_col[0] = static_cast<int>(c), known = true;
    if (h == "y") cols.xyz_col[1] = static_cast<int>(c), known = true;
    if (h == "z") cols.xyz_col[2] = static_cast<int>(c), known = true;
    const char* quat[4] = {"qw", "qx", "qy", "qz"};
    for (int k = 0; k < 4; ++k) {
      if (h == quat[k]) cols.quat_col[k] = static_cast<int>(c), known = true;
    }
    if (h == "u") cols.uv_col[0] = static_cast<int>(c), known = true;
    const char* up[3] = {"up_x", "up_y", "up_z"};
    for (int k = 0; k < 3; ++k) {
      if (h == up[k]) cols.up_col[k] = static_cast<int>(c), known = true;
    }
    if (h.rfind("motion_", 0) == 0) {
      for (size_t j = 0; j < joints.size(); ++j) {
        if (joints[j] == h.substr(7)) cols.motion_col[j] = static_cast<int>(c), known = true;
      }
      if (!known)
        throw InputError(hdr + ": column '" + CapForMessage(h) + "' names no actuated joint");
    }
    if (h == "v") cols.uv_col[1] = static_cast<int>(c), known = true;
    if (!known) {
      throw InputError(hdr + ": column '" + CapForMessage(h) +
                       "' is neither an actuated joint of the declared model nor one of group, "
                       "set, pose, frame, marker, x, y, z, qw, qx, qy, qz, u, v, up_x, up_y, up_z, "
                       "motion_<joint>");
    }
  }
  return cols;
}

// The columns together: every joint, x/y/z and the quaternion complete, one kind of row.
void CheckColumns(const std::string& hdr, const std::vector<std::string>& joints,
                  const std::function<bool(const std::string&)>& is_coupled, const DataSet& data,
                  CsvColumns& cols) {
  for (size_t j = 0; j < joints.size(); ++j) {
    if (cols.joint_col[j] < 0 && !is_coupled(joints[j])) {
      throw InputError(hdr + ": no column for joint '" + joints[j] + "'");
    }
  }
  cols.has_xyz = cols.xyz_col[0] >= 0 && cols.xyz_col[1] >= 0 && cols.xyz_col[2] >= 0;
  if ((cols.xyz_col[0] >= 0 || cols.xyz_col[1] >= 0 || cols.xyz_col[2] >= 0) && !cols.has_xyz) {
    throw InputError(hdr + ": x, y and z go together");
  }
  cols.num_quat = (cols.quat_col[0] >= 0) + (cols.quat_col[1] >= 0) + (cols.quat_col[2] >= 0) +
                  (cols.quat_col[3] >= 0);
  if (cols.num_quat != 0 && (cols.num_quat != 4 || !cols.has_xyz)) {
    throw InputError(hdr + ": a pose needs x, y, z and all of qw, qx, qy, qz");
  }
  cols.has_uv = cols.uv_col[0] >= 0 && cols.uv_col[1] >= 0;
  if ((cols.uv_col[0] >= 0) != (cols.uv_col[1] >= 0)) {
    throw InputError(hdr + ": u and v go together");
  }
  const int num_up = (cols.up_col[0] >= 0) + (cols.up_col[1] >= 0) + (cols.up_col[2] >= 0);
  cols.has_up = num_up == 3;
  if (num_up != 0 && !cols.has_up) throw InputError(hdr + ": up_x, up_y and up_z go together");
  if (cols.has_xyz + (cols.group_col >= 0) + cols.has_uv + cols.has_up != 1) {
    throw InputError(hdr +
                     ": need exactly one of a 'group' column, 'x','y','z' columns, "
                     "'u','v' columns or 'up_x','up_y','up_z' columns");
  }
  if (cols.has_up && cols.frame_col >= 0) {
    throw InputError(hdr +
                     ": gravity rows (up_x, up_y, up_z) are measured in their marker's "
                     "frame: no 'frame' column");
  }
  if (cols.has_uv && !data.camera.present) {
    throw InputError(hdr + ": pixel columns need a camera (the scenario's 'camera' key)");
  }
}

// One data row (its cells already counted against the header).
Observation ParseRow(const std::vector<std::string>& cells, const std::string& where,
                     const std::string& path, const std::vector<std::string>& joints,
                     const CsvColumns& cols, const DataSet& data, LabelIndexer& group_index,
                     LabelIndexer& set_index, LabelIndexer& pose_index) {
  Observation o;
  o.where = where;
  o.q.resize(joints.size());
  for (size_t j = 0; j < joints.size(); ++j) {
    // A coupled joint's entry is set from its drivers by the caller (ApplyCouplings).
    o.q[j] = cols.joint_col[j] < 0
                 ? 0.0
                 : sim::ParseCsvNumber(cells[cols.joint_col[j]], where, joints[j], kMaxJoint);
  }
  if (std::any_of(cols.motion_col.begin(), cols.motion_col.end(), [](int c) { return c >= 0; })) {
    o.motion_sign = Eigen::VectorXd::Zero(joints.size());
    for (size_t j = 0; j < joints.size(); ++j) {
      if (cols.motion_col[j] < 0) continue;
      const double v = sim::ParseCsvNumber(cells[cols.motion_col[j]], where, "motion_" + joints[j]);
      if (v != -1.0 && v != 0.0 && v != 1.0) {
        throw InputError(where + ": column 'motion_" + joints[j] + "' must be -1, 0 or 1");
      }
      o.motion_sign[j] = v;
    }
  }
  if (cols.has_xyz) {
    o.type = ObservationType::kPoint;
    const char* names[3] = {"x", "y", "z"};
    for (int k = 0; k < 3; ++k) {
      o.p_base[k] = sim::ParseCsvNumber(cells[cols.xyz_col[k]], where, names[k], kMaxCoordinate);
    }
    if (cols.num_quat == 4) {
      o.type = ObservationType::kPose;
      const Eigen::Quaterniond qt(sim::ParseCsvNumber(cells[cols.quat_col[0]], where, "qw"),
                                  sim::ParseCsvNumber(cells[cols.quat_col[1]], where, "qx"),
                                  sim::ParseCsvNumber(cells[cols.quat_col[2]], where, "qy"),
                                  sim::ParseCsvNumber(cells[cols.quat_col[3]], where, "qz"));
      if (std::abs(qt.norm() - 1.0) > 1e-3) {
        throw InputError(where + ": quaternion (qw, qx, qy, qz) is not of unit length");
      }
      o.R_base = qt.normalized().toRotationMatrix();
    }
  } else if (cols.has_up) {
    o.type = ObservationType::kGravity;
    const char* names[3] = {"up_x", "up_y", "up_z"};
    for (int k = 0; k < 3; ++k) {
      o.up()[k] = sim::ParseCsvNumber(cells[cols.up_col[k]], where, names[k], kMaxCoordinate);
    }
    if (std::abs(o.up().norm() - 1.0) > 1e-3) {
      throw InputError(where + ": (up_x, up_y, up_z) is not of unit length");
    }
  } else if (cols.has_uv) {
    o.type = ObservationType::kPixel;
    o.uv = Eigen::Vector2d(sim::ParseCsvNumber(cells[cols.uv_col[0]], where, "u", kMaxPixel),
                           sim::ParseCsvNumber(cells[cols.uv_col[1]], where, "v", kMaxPixel));
  } else {
    if (cells[cols.group_col].empty()) throw InputError(where + ": column 'group' is empty");
    o.type = ObservationType::kGroup;
    o.group = group_index(cells[cols.group_col]);
  }
  if (cols.frame_col >= 0) SetRowFrame(cells[cols.frame_col], where, data, &o);
  if (cols.marker_col >= 0) o.point = MarkerIndex(cells[cols.marker_col], where, data);
  if (cols.set_col >= 0 && cells[cols.set_col].empty()) {
    throw InputError(where + ": column 'set' is empty");
  }
  o.set = set_index(cols.set_col >= 0 ? cells[cols.set_col] : path);
  if (cols.pose_col >= 0) {
    if (cells[cols.pose_col].empty()) throw InputError(where + ": column 'pose' is empty");
    o.pose = pose_index(cells[cols.pose_col]);
  }
  return o;
}

}  // namespace

void ReadCalibrationCsv(const std::string& path, const std::vector<std::string>& joints,
                        DataSet* data, const std::vector<std::string>& coupled) {
  const std::function<bool(const std::string&)> is_coupled = [&](const std::string& j) {
    return std::find(coupled.begin(), coupled.end(), j) != coupled.end();
  };
  CsvLines csv(path, joints.size());
  const size_t first_row = data->rows.size();
  LabelIndexer group_index(&data->groups), set_index(&data->sets), pose_index(&data->poses);
  std::vector<std::string> header;
  if (!csv.Next(&header)) throw InputError(path + ": no header row");
  const std::string hdr = csv.Where();
  CsvColumns cols = ParseHeader(header, hdr, joints, is_coupled);
  CheckColumns(hdr, joints, is_coupled, *data, cols);
  // Room for every line at once: a vector grown by doubling holds up to twice its rows, and
  // both the old and the new block while it moves.
  data->rows.reserve(data->rows.size() + static_cast<size_t>(csv.lines()));
  int rows = 0;
  std::vector<std::string> cells;
  while (csv.Next(&cells)) {
    const std::string where = csv.Where();
    if (cells.size() != header.size()) {
      throw InputError(where + ": " + std::to_string(cells.size()) + " columns, the header has " +
                       std::to_string(header.size()));
    }
    data->rows.push_back(
        ParseRow(cells, where, path, joints, cols, *data, group_index, set_index, pose_index));
    ++rows;
  }
  if (rows == 0) throw InputError(CapForMessage(path) + ": no data rows");
  WarnGroupsSpanningSets(*data, first_row);
}

std::string FormatCalibrationCsv(const DataSet& data, const std::vector<std::string>& joints,
                                 const std::vector<std::string>& coupled) {
  if (data.rows.empty()) return "";
  const ObservationType type = data.rows[0].type;
  bool pose = false, motion = false;
  const bool frame = !data.frames.empty() && type != ObservationType::kGravity;
  for (const Observation& o : data.rows) {
    if (o.type != type) {
      throw InputError(o.where + ": a CSV holds rows of one type (the first row's); this one " +
                       "is another");
    }
    pose = pose || o.pose >= 0;
    motion = motion || o.motion_sign.size() > 0;
  }
  const bool marker = data.points.size() > 1;
  std::vector<int> cols;
  std::string out;
  for (size_t j = 0; j < joints.size(); ++j) {
    if (std::find(coupled.begin(), coupled.end(), joints[j]) != coupled.end()) continue;
    out += (cols.empty() ? "" : ",") + joints[j];
    cols.push_back(static_cast<int>(j));
  }
  out += ",set";
  if (pose) out += ",pose";
  if (frame) out += ",frame";
  if (marker) out += ",marker";
  const bool xyz = type == ObservationType::kPoint || type == ObservationType::kPose;
  if (type == ObservationType::kGroup) out += ",group";
  if (xyz) out += ",x,y,z";
  if (type == ObservationType::kPose) out += ",qw,qx,qy,qz";
  if (type == ObservationType::kPixel) out += ",u,v";
  if (type == ObservationType::kGravity) out += ",up_x,up_y,up_z";
  if (motion) {
    for (int j : cols) out += ",motion_" + joints[j];
  }
  out += "\n";
  char num[32];
  const auto put = [&](double v) {
    std::snprintf(num, sizeof(num), "%.17g", v);
    out += num;
  };
  for (const Observation& o : data.rows) {
    for (size_t k = 0; k < cols.size(); ++k) {
      if (k) out += ",";
      put(o.q[cols[k]]);
    }
    out += "," + data.sets[o.set];
    if (pose) out += "," + (o.pose >= 0 ? data.poses[o.pose] : "none");
    if (frame) out += "," + (o.frame >= 0 ? data.frames[o.frame].name : std::string("base"));
    if (marker) out += "," + data.points[o.point];
    if (type == ObservationType::kGroup) out += "," + data.groups[o.group];
    const Vec3& p = o.frame >= 0 ? o.p_frame : o.p_base;
    if (xyz) {
      for (int k = 0; k < 3; ++k) out += ",", put(p[k]);
    }
    if (type == ObservationType::kPose) {
      const Eigen::Quaterniond qt(o.frame >= 0 ? o.R_frame.get() : o.R_base.get());
      for (double v : {qt.w(), qt.x(), qt.y(), qt.z()}) out += ",", put(v);
    }
    if (type == ObservationType::kPixel) out += ",", put(o.uv[0]), out += ",", put(o.uv[1]);
    if (type == ObservationType::kGravity) {
      for (int k = 0; k < 3; ++k) out += ",", put(o.up()[k]);
    }
    if (motion) {
      for (int j : cols) out += ",", put(o.motion_sign.size() ? o.motion_sign[j] : 0.0);
    }
    out += "\n";
  }
  return out;
}

void ReadMukcaPlacement(const std::string& dir, const std::string& set, int num_joints,
                        double socket_distance_m, DataSet* data) {
  if (!(std::isfinite(socket_distance_m) && socket_distance_m > 0.0 && socket_distance_m <= 10.0)) {
    char v[32];
    std::snprintf(v, sizeof(v), "%g", socket_distance_m);
    throw InputError(CapForMessage(dir) + ": socket_distance_m " + v +
                     " must be > 0 and at most 10 (metres)");
  }
  const int s = LabelIndex(&data->sets, set);
  int groups[2];
  for (int h = 0; h < 2; ++h) {
    const std::string path = dir + "/hole_" + std::to_string(h) + ".csv";
    CsvLines csv(path, static_cast<size_t>(std::max(num_joints, 0)));
    groups[h] = LabelIndex(&data->groups, set + "/hole_" + std::to_string(h));
    int rows = 0;
    std::vector<std::string> cells;
    while (csv.Next(&cells)) {
      const std::string where = csv.Where();
      if (static_cast<int>(cells.size()) != num_joints) {
        throw InputError(where + ": " + std::to_string(cells.size()) + " columns, expected " +
                         std::to_string(num_joints) + " joint angles");
      }
      Observation o;
      o.where = where;
      o.q.resize(num_joints);
      for (int j = 0; j < num_joints; ++j) {
        o.q[j] = sim::ParseCsvNumber(cells[j], where, "joint " + std::to_string(j + 1), kMaxJoint);
      }
      o.type = ObservationType::kGroup;
      o.group = groups[h];
      o.set = s;
      data->rows.push_back(o);
      ++rows;
    }
    if (rows == 0) throw InputError(CapForMessage(path) + ": no data rows");
  }
  data->distances.push_back({groups[0], groups[1], socket_distance_m});
}

std::uintmax_t CalibrationBytesPerRow(size_t num_joints) {
  return kCalibrationBytesPerRow + kCalibrationBytesPerJoint * num_joints;
}

}  // namespace flexbench::identify
