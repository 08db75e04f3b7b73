// A recorded log's contact readings (recorded_log.h): log.yaml's `contacts`, contacts.csv, and
// their writers.
#include <Eigen/Geometry>
#include <cmath>
#include <sstream>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/csv.h"
#include "sim/recorded_log_streams.h"

namespace flexbench::sim::log_internal {
namespace {

const std::vector<std::string>& ContactsHeader() {
  static const std::vector<std::string> h = {"t_s", "point", "plane", "distance_m", "std_m"};
  return h;
}

LogPlane ReadPlane(const std::string& name, const ConfigNode& p) {
  LogPlane plane;
  plane.name = name;
  const ConfigNode pose = p.Child("T_base_plane");
  const std::vector<double> v = pose.AsDoubleList();
  bool ok = v.size() == 7;
  for (size_t i = 0; ok && i < 7; ++i) ok = std::abs(v[i]) <= 1e3;
  const Eigen::Quaterniond q(ok ? v[3] : 0.0, ok ? v[4] : 0.0, ok ? v[5] : 0.0, ok ? v[6] : 0.0);
  if (!ok || std::abs(q.norm() - 1.0) > 1e-6) {
    pose.Fail("expected [x, y, z, qw, qx, qy, qz] (m, a unit quaternion)");
  }
  plane.q_base_plane = q;
  plane.T_base_plane = PlanePose(q, Vec3(v[0], v[1], v[2]));
  if (const auto sd = p.Optional("std")) {
    if (p.Has("std_m") || p.Has("std_deg")) sd->Fail("std, or std_m and std_deg: not both");
    const std::vector<double> v = sd->AsDoubleList();
    bool ok = v.size() == 6;
    for (size_t i = 0; ok && i < 6; ++i) ok = v[i] >= 0.0 && v[i] <= (i < 3 ? 10.0 : M_PI);
    if (!ok) sd->Fail("expected 6 standard deviations [m m m rad rad rad], each >= 0");
    for (int i = 0; i < 6; ++i) plane.std[i] = v[i];
  } else {
    const double std_m = p.GetDouble("std_m", 0.0), std_deg = p.GetDouble("std_deg", 0.0);
    if (!(std_m >= 0.0 && std_m <= 10.0)) p.Child("std_m").Fail("must be in [0, 10] m");
    if (!(std_deg >= 0.0 && std_deg <= 180.0)) p.Child("std_deg").Fail("must be in [0, 180] deg");
    plane.std << Vec3::Constant(std_m), Vec3::Constant(std_deg * kDeg);
  }
  plane.cov.diagonal() = plane.std.cwiseProduct(plane.std);
  return plane;
}

}  // namespace

void ReadContacts(const ConfigNode& node, RecordedLog* log, double* used) {
  const std::string file = node.ResolvePath(node.GetString("file"));
  const double offset = ClockOffset(node);
  const ConfigNode planes = node.Child("planes");
  for (const std::string& name : planes.Keys()) {
    log->planes.push_back(ReadPlane(name, planes.Child(name)));
  }
  if (log->planes.empty()) planes.Fail("names no plane");
  const ConfigNode points = node.Child("points");
  for (const std::string& name : points.Keys()) {
    const ConfigNode p = points.Child(name);
    LogContactPoint point;
    point.name = name;
    point.frame = p.GetString("frame");
    if (const auto at = p.Optional("p_frame_m")) {
      const std::vector<double> v = at->AsDoubleList();
      if (v.size() != 3 ||
          !(std::abs(v[0]) <= 10 && std::abs(v[1]) <= 10 && std::abs(v[2]) <= 10)) {
        at->Fail("expected [x, y, z] in metres, each within 10 m");
      }
      point.p_frame = Vec3(v[0], v[1], v[2]);
    }
    log->contact_points.push_back(point);
  }
  if (log->contact_points.empty()) points.Fail("names no point");
  CsvLines csv(file, kMaxLogStreamBytes);
  const std::vector<std::string>& want = ContactsHeader();
  ReadHeader(&csv, file, want);
  log->contacts.reserve(CheckRows(file, sizeof(LogContactRow) + 16.0, used));
  PairedTimes times;  // a point's readings against one plane are a stream of their own
  std::vector<std::string> cells;
  while (csv.Next(&cells)) {
    const std::string where = csv.Where();
    CheckRowColumns(cells, want.size(), where);
    LogContactRow row;
    row.point =
        IndexOf(log->contact_points, [&](const LogContactPoint& p) { return p.name == cells[1]; });
    if (row.point < 0) {
      throw InputError(where + ": column 'point': '" + CapForMessage(cells[1]) +
                       "' is not one of the log's contacts.points");
    }
    row.plane = IndexOf(log->planes, [&](const LogPlane& p) { return p.name == cells[2]; });
    if (row.plane < 0) {
      throw InputError(where + ": column 'plane': '" + CapForMessage(cells[2]) +
                       "' is not one of the log's contacts.planes");
    }
    row.t = times.Take({row.point, row.plane}, cells[0], where, offset);
    row.distance_m = ParseCsvNumber(cells[3], where, "distance_m", 1e3);
    row.std_m = ParseCsvNumber(cells[4], where, "std_m", 1e3);
    if (!(row.std_m > 0.0)) throw InputError(where + ": column 'std_m' must be > 0");
    log->contacts.push_back(row);
  }
  log->contact_stats = times.Stats(file, offset);
}

std::string ContactsYaml(const RecordedLog& log) {
  if (log.planes.empty()) return "";
  std::ostringstream y;
  y << "contacts:\n  file: contacts.csv\n  planes:\n";
  for (const LogPlane& p : log.planes) {
    const Vec3& t = p.T_base_plane.translation();
    const Quat& q = p.q_base_plane;
    y << "    " << p.name << ": {T_base_plane: [" << ExactNum(t.x()) << ", " << ExactNum(t.y())
      << ", " << ExactNum(t.z()) << ", " << ExactNum(q.w()) << ", " << ExactNum(q.x()) << ", "
      << ExactNum(q.y()) << ", " << ExactNum(q.z()) << "], std: [";
    for (int i = 0; i < 6; ++i) y << (i ? ", " : "") << ExactNum(p.std[i]);
    y << "]}\n";
  }
  y << "  points:\n";
  for (const LogContactPoint& p : log.contact_points) {
    y << "    " << p.name << ": {frame: " << p.frame << ", p_frame_m: [" << ExactNum(p.p_frame.x())
      << ", " << ExactNum(p.p_frame.y()) << ", " << ExactNum(p.p_frame.z()) << "]}\n";
  }
  return y.str();
}

std::string ContactsCsv(const RecordedLog& log) {
  std::ostringstream c;
  const std::vector<std::string>& h = ContactsHeader();
  c << HeaderLine(h);
  for (const LogContactRow& r : log.contacts) {
    c << ExactNum(r.t) << "," << log.contact_points[r.point].name << "," << log.planes[r.plane].name
      << "," << ExactNum(r.distance_m) << "," << ExactNum(r.std_m) << "\n";
  }
  return c.str();
}

}  // namespace flexbench::sim::log_internal
