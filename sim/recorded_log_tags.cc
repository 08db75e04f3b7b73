// A recorded log's cameras and tag detections (recorded_log.h): log.yaml's `cameras` and `tags`,
// tags.csv, and their writers.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/csv.h"
#include "sim/recorded_log_streams.h"

namespace flexbench::sim::log_internal {
namespace {

// tags.csv's columns; `centres`: with the detector's centre.
const std::vector<std::string>& TagsHeader(bool centres) {
  static const std::vector<std::string> h = {"t_s",   "camera", "tag_id", "u0_px", "v0_px", "u1_px",
                                             "v1_px", "u2_px",  "v2_px",  "u3_px", "v3_px"};
  static const std::vector<std::string> hc = [] {
    std::vector<std::string> v = h;
    v.push_back("uc_px");
    v.push_back("vc_px");
    return v;
  }();
  return centres ? hc : h;
}

double Positive(const ConfigNode& c, const std::string& key, double max) {
  const double v = c.GetDouble(key);
  if (!(v > 0.0 && v <= max)) c.Child(key).Fail("must be > 0 and at most " + ExactNum(max));
  return v;
}

LogTag ReadTag(const std::string& key, const ConfigNode& t) {
  LogTag tag;
  char* end = nullptr;
  const long id = std::strtol(key.c_str(), &end, 10);
  if (key.empty() || *end != '\0' || id < 0 || id > 1000000) {
    t.Fail("a tag id must be an integer in [0, 1000000], not '" + CapForMessage(key) + "'");
  }
  tag.id = static_cast<int>(id);
  tag.frame = t.GetString("frame");
  if (t.Has("corners_m") == t.Has("size_m")) t.Fail("needs corners_m or size_m (one of them)");
  if (t.Has("size_m")) {
    const double h = 0.5 * Positive(t, "size_m", 10.0);
    // libapriltag's order on the printed tag, x right and y down.
    tag.corners_m = {Vec3(-h, h, 0.0), Vec3(h, h, 0.0), Vec3(h, -h, 0.0), Vec3(-h, -h, 0.0)};
    return tag;
  }
  const ConfigNode c = t.Child("corners_m");
  const std::vector<ConfigNode> corners = c.Items();
  if (corners.size() != 4) c.Fail("expected four corners [[x, y, z], ...] in metres");
  for (int k = 0; k < 4; ++k) {
    const std::vector<double> v = corners[k].AsDoubleList();
    if (v.size() != 3 || !(std::abs(v[0]) <= 10 && std::abs(v[1]) <= 10 && std::abs(v[2]) <= 10)) {
      corners[k].Fail("expected [x, y, z] in metres, each within 10 m");
    }
    tag.corners_m[k] = Vec3(v[0], v[1], v[2]);
  }
  return tag;
}

}  // namespace

void ReadCameras(const ConfigNode& node, RecordedLog* log) {
  for (const std::string& name : node.Keys()) {
    const ConfigNode c = node.Child(name);
    LogCamera cam;
    cam.name = name;
    cam.frame = c.GetString("frame");
    cam.intrinsics.fx = Positive(c, "fx", 1e6);
    cam.intrinsics.fy = Positive(c, "fy", 1e6);
    cam.intrinsics.cx = c.GetDouble("cx");
    cam.intrinsics.cy = c.GetDouble("cy");
    for (const char* k : {"cx", "cy"}) {
      if (!(std::abs(c.GetDouble(k)) <= 1e6)) c.Child(k).Fail("must be finite, within 1e6 px");
    }
    cam.intrinsics.width = c.GetInt("width");
    cam.intrinsics.height = c.GetInt("height");
    for (const char* k : {"width", "height"}) {
      if (!(c.GetInt(k) > 0 && c.GetInt(k) <= 100000)) c.Child(k).Fail("must be in [1, 100000]");
    }
    log->cameras.push_back(cam);
  }
  if (log->cameras.empty()) node.Fail("names no camera");
}

void ReadTags(const ConfigNode& node, RecordedLog* log, double* used) {
  if (log->cameras.empty()) node.Fail("needs `cameras` (those that see the tags)");
  if (node.Has("pixel_std_px")) {
    log->pixel_std_px = Positive(node, "pixel_std_px", 1e3);
    log->pixel_std_stated = true;
  }
  const std::string measurement = node.GetString("measurement", "corners");
  if (measurement != "corners" && measurement != "centre") {
    node.Child("measurement").Fail("expected corners or centre");
  }
  log->tag_centres = measurement == "centre";
  const ConfigNode ids = node.Child("ids");
  for (const std::string& key : ids.Keys()) {
    const LogTag tag = ReadTag(key, ids.Child(key));
    for (const LogTag& other : log->tags) {
      if (other.id == tag.id) ids.Child(key).Fail("tag " + std::to_string(tag.id) + " twice");
    }
    log->tags.push_back(tag);
  }
  if (log->tags.empty()) ids.Fail("names no tag");
  if (!node.Has("file")) return;  // the log's images hold them
  const std::string file = node.ResolvePath(node.GetString("file"));
  const double offset = ClockOffset(node);
  CsvLines csv(file, kMaxLogStreamBytes);
  log->has_centre_columns = ReadHeader(&csv, file, TagsHeader(true), 2) == TagsHeader(true).size();
  const std::vector<std::string>& want = TagsHeader(log->has_centre_columns);
  log->tag_rows.reserve(CheckRows(file, sizeof(LogTagRow) + 16.0, used));
  PairedTimes times;  // a camera's view of one tag is a stream of its own
  std::vector<std::string> cells;
  while (csv.Next(&cells)) {
    const std::string where = csv.Where();
    CheckRowColumns(cells, want.size(), where);
    LogTagRow row;
    row.camera = IndexOf(log->cameras, [&](const LogCamera& c) { return c.name == cells[1]; });
    if (row.camera < 0) {
      throw InputError(where + ": column 'camera': '" + CapForMessage(cells[1]) +
                       "' is not one of the log's cameras");
    }
    const double id = ParseCsvNumber(cells[2], where, "tag_id", 1e6);
    row.tag = IndexOf(log->tags, [&](const LogTag& t) { return t.id == id; });
    if (row.tag < 0) {
      throw InputError(where + ": column 'tag_id': " + cells[2] +
                       " is not one of the log's tags.ids");
    }
    row.t = times.Take({row.camera, row.tag}, cells[0], where, offset);
    for (int k = 0; k < 4; ++k) {
      row.uv[k] = Eigen::Vector2d(ParseCsvNumber(cells[3 + 2 * k], where, want[3 + 2 * k], 1e6),
                                  ParseCsvNumber(cells[4 + 2 * k], where, want[4 + 2 * k], 1e6));
    }
    if (log->has_centre_columns) {
      row.centre = Eigen::Vector2d(ParseCsvNumber(cells[11], where, want[11], 1e6),
                                   ParseCsvNumber(cells[12], where, want[12], 1e6));
    } else if (!DiagonalsCross(row.uv, &row.centre)) {
      if (log->tag_centres) {
        throw InputError(where + ": the corners' diagonals do not cross: no centre");
      }
      row.centre.setConstant(std::nan(""));  // no centre: no pixel row (identify)
    }
    log->tag_rows.push_back(row);
  }
  log->tag_stats = times.Stats(file, offset);
}

void ReadImages(const ConfigNode& node, RecordedLog* log) {
  namespace fs = std::filesystem;
  if (log->tags.empty()) node.Fail("needs `tags` with their ids (the tags to detect)");
  const std::string dir = node.ResolvePath(node.GetString("dir"));
  const double offset = ClockOffset(node);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) node.Child("dir").Fail("no folder " + CapForMessage(dir));
  std::vector<std::vector<double>> times(log->cameras.size());
  try {
    for (const fs::directory_entry& sub : fs::directory_iterator(dir)) {
      const std::string name = sub.path().filename().string();
      const int c =
          IndexOf<LogCamera>(log->cameras, [&](const LogCamera& cam) { return cam.name == name; });
      if (c < 0 || !sub.is_directory()) {
        throw InputError(CapForMessage(sub.path().string()) +
                         ": not a folder named after one of the log's cameras");
      }
      std::vector<LogImage> frames;
      for (const fs::directory_entry& e : fs::directory_iterator(sub.path())) {
        const std::string stem = e.path().stem().string();
        const bool digits =
            !stem.empty() && stem.size() <= 18 &&
            std::all_of(stem.begin(), stem.end(), [](char ch) { return ch >= '0' && ch <= '9'; });
        if (!e.is_regular_file() || e.path().extension() != ".png" || !digits) {
          throw InputError(CapForMessage(e.path().string()) +
                           ": expected <t_ns>.png, the frame's time in nanoseconds");
        }
        frames.push_back(
            {1e-9 * static_cast<double>(std::stoll(stem)) + offset, c, e.path().string()});
      }
      std::sort(frames.begin(), frames.end(), [](const LogImage& a, const LogImage& b) {
        return a.t != b.t ? a.t < b.t : a.path < b.path;
      });
      for (size_t i = 1; i < frames.size(); ++i) {
        if (frames[i].t == frames[i - 1].t) {
          throw InputError(CapForMessage(frames[i].path) + ": the same time as " +
                           CapForMessage(frames[i - 1].path));
        }
      }
      for (const LogImage& f : frames) times[c].push_back(f.t);
      log->images.insert(log->images.end(), frames.begin(), frames.end());
    }
  } catch (const fs::filesystem_error& e) {
    throw InputError(CapForMessage(dir) + ": cannot read the images (" + e.what() + ")");
  }
  if (log->images.empty()) {
    node.Fail("no <camera>/<t_ns>.png under " + CapForMessage(dir) + " for the log's cameras");
  }
  // In time order, cameras in log.yaml's order at equal times: not the folders' listing order.
  std::sort(log->images.begin(), log->images.end(), [](const LogImage& a, const LogImage& b) {
    return a.t != b.t ? a.t < b.t : a.camera < b.camera;
  });
  std::vector<const std::vector<double>*> streams;
  for (const std::vector<double>& ts : times) streams.push_back(&ts);
  log->image_stats = Stats(dir, offset, streams);
}

std::string TagsYaml(const RecordedLog& log) {
  if (log.tags.empty()) return "";
  std::ostringstream y;
  y << "cameras:\n";
  for (const LogCamera& c : log.cameras) {
    const PinholeCamera& k = c.intrinsics;
    y << "  " << c.name << ": {frame: " << c.frame << ", fx: " << ExactNum(k.fx)
      << ", fy: " << ExactNum(k.fy) << ", cx: " << ExactNum(k.cx) << ", cy: " << ExactNum(k.cy)
      << ", width: " << k.width << ", height: " << k.height << "}\n";
  }
  y << "tags:\n";
  if (log.images.empty()) y << "  file: tags.csv\n";
  if (log.tag_centres) y << "  measurement: centre\n";
  y << "  pixel_std_px: " << ExactNum(log.pixel_std_px) << "\n  ids:\n";
  for (const LogTag& t : log.tags) {
    y << "    " << t.id << ":\n      frame: " << t.frame << "\n      corners_m: [";
    for (int k = 0; k < 4; ++k) {
      const Vec3& p = t.corners_m[k];
      y << (k ? ", " : "") << "[" << ExactNum(p.x()) << ", " << ExactNum(p.y()) << ", "
        << ExactNum(p.z()) << "]";
    }
    y << "]\n";
  }
  if (!log.images.empty()) y << "images: {dir: images}\n";
  return y.str();
}

std::string TagsCsv(const RecordedLog& log) {
  std::ostringstream c;
  const std::vector<std::string>& h = TagsHeader(log.has_centre_columns);
  c << HeaderLine(h);
  for (const LogTagRow& r : log.tag_rows) {
    c << ExactNum(r.t) << "," << log.cameras[r.camera].name << "," << log.tags[r.tag].id;
    for (int k = 0; k < 4; ++k) c << "," << ExactNum(r.uv[k].x()) << "," << ExactNum(r.uv[k].y());
    if (log.has_centre_columns) c << "," << ExactNum(r.centre.x()) << "," << ExactNum(r.centre.y());
    c << "\n";
  }
  return c.str();
}

}  // namespace flexbench::sim::log_internal

namespace flexbench::sim {

int TagIndex(const RecordedLog& log, int id) {
  return log_internal::IndexOf(log.tags, [&](const LogTag& t) { return t.id == id; });
}

bool DiagonalsCross(const std::array<Eigen::Vector2d, 4>& uv, Eigen::Vector2d* centre) {
  const auto h = [&](int k) { return Eigen::Vector3d(uv[k].x(), uv[k].y(), 1.0); };
  const Eigen::Vector3d c = h(0).cross(h(2)).cross(h(1).cross(h(3)));
  if (!(std::abs(c.z()) > 1e-12)) return false;
  *centre = c.head<2>() / c.z();
  return true;
}

}  // namespace flexbench::sim
