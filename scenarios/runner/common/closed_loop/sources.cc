#include "scenarios/runner/common/closed_loop/sources.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/cross_validation.h"
#include "scenarios/runner/common/closed_loop/truth.h"
#include "scenarios/runner/common/log_images.h"
#include "scenarios/runner/common/log_replay.h"
#include "scenarios/runner/output.h"

namespace flexbench::scenarios {
namespace {

using identify::DataSet;

// Pixel rows of a log's tags seen by the identification's camera (CameraFromLogs).
void AppendLogPixels(const ClosedLoopSetup& cl, const sim::RecordedLog& log,
                     const std::vector<int>& column, const Source& s, const std::string& what,
                     RunContext& ctx, DataSet* d) {
  int camera = -1;
  for (size_t c = 0; c < log.cameras.size(); ++c) {
    if (log.cameras[c].frame == cl.camera.name) camera = static_cast<int>(c);
  }
  std::vector<int> tag_points;
  for (const sim::LogTag& tag : log.tags) {
    const auto it = std::find(cl.points.begin(), cl.points.end(), tag.frame);
    tag_points.push_back(cl.centred_tag_frames.count(tag.frame) && it != cl.points.end()
                             ? static_cast<int>(it - cl.points.begin())
                             : -1);
  }
  const int n = identify::AppendLogPixels(log, column, s.from_s, s.to_s, camera, tag_points, d);
  ctx.log(what + ": " + std::to_string(n) + " tag detections of " + log.tag_stats.file +
          " by camera '" + cl.camera.name + "' in " + Span(s) +
          " (pixel rows of the tags' centres)");
}

// A log IMU's frame as a measured point (checked on the chain, listed once); returns the
// variance its readings' rounding gives an up direction there: count^2 / 12 of each joint on
// its way from the base (a joint about the vertical counts too: on the safe side).
double ImuPoint(ClosedLoopSetup& cl, const sim::RecordedLog& log, int sensor,
                const std::vector<double>& steps) {
  const sim::LogImu& imu = log.imus[sensor];
  const std::string where = log.dir + "/log.yaml: imu.sensors." + imu.name + ".frame";
  kinematics::FrameId f = -1;
  try {
    f = cl.chain->ObservedFrame(imu.frame);
  } catch (const InputError& e) {
    throw InputError(where + ": " + e.what());
  }
  const bool listed = imu.frame == cl.declared.end_effector ||
                      std::any_of(cl.marker_nodes.begin(), cl.marker_nodes.end(),
                                  [&](const auto& m) { return m.first == imu.frame; });
  if (!listed) cl.marker_nodes.push_back({imu.frame, where});
  double var = 0.0;
  for (; f > 0; f = cl.chain->model.frame(f).parent) {
    const int q = cl.chain->model.frame(f).q_index;
    if (q >= 0) var += steps[q] * steps[q] / 12.0;
  }
  return var;
}

// Gravity rows of a log's static IMU windows (ImuFromLogs).
void AppendGravity(const ClosedLoopSetup& cl, const sim::RecordedLog& log, const Source& s,
                   const std::string& what, RunContext& ctx, DataSet* d) {
  const auto it = cl.still_windows.find(&s);
  if (it == cl.still_windows.end() || it->second.empty()) return;
  std::vector<int> imu_points;
  for (const sim::LogImu& imu : log.imus) {
    const auto p = std::find(cl.points.begin(), cl.points.end(), imu.frame);
    imu_points.push_back(p == cl.points.end() ? -1 : static_cast<int>(p - cl.points.begin()));
  }
  const int n = identify::AppendLogGravity(log, it->second, s.from_s, s.to_s, imu_points, d);
  const double g = cl.em->g_base().norm();
  double worst = 0.0, ss = 0.0;
  for (const identify::StaticWindow& w : it->second) {
    worst = std::max(worst, std::abs(w.accel_norm - g) / g);
    ss += w.std_rad * w.std_rad;
  }
  char line[192];
  std::snprintf(line, sizeof(line),
                ": %d windows at rest of %s in %s (gravity rows; up measured to %.3g mrad "
                "there, stated %.3g mrad)",
                n, log.imu_stats.file.c_str(), Span(s).c_str(),
                1e3 * std::sqrt(ss / it->second.size()), 1e3 * cl.opt.gravity_std_rad);
  ctx.log(what + line);
  if (worst > 0.1) {
    ctx.log(what + ": warning: an accelerometer at rest reads " + ShortNum(100.0 * worst) +
            "% off |g| = " + ShortNum(g) +
            " m/s^2 (imu.csv's units are m/s^2): the up directions are used, their length not");
  }
}

// What each of a log source's streams gave: none, or no row in its span.
std::string WhyNoLogRows(ClosedLoopSetup& cl, const Source& s) {
  const sim::RecordedLog& log = Log(cl, s);
  std::string out;
  const auto say = [&](const std::string& text) { out += (out.empty() ? "" : "; ") + text; };
  if (s.streams.count("truth")) say(log.truth_t.empty() ? "no truth.tum" : "truth.tum: none");
  if (s.streams.count("tags")) {
    say(log.tag_rows.empty() ? "no tag detections"
                             : "tags: none of a fixed camera's on a measured frame");
  }
  if (s.streams.count("imu")) {
    say(log.imu.empty() ? "no imu.csv" : "imu.csv: no window at rest (static:)");
  }
  return out;
}

// Simulated rows as the measured data a user brings (`flexbench identify --calibration`).
// A CSV holds rows of one type: a log's pixel and gravity rows go beside its points,
// <what>_pixels.csv and <what>_gravity.csv.
void WriteDataCsv(const ClosedLoopSetup& cl, RunContext& ctx, const DataSet& d,
                  const std::string& what) {
  std::vector<std::string> coupled;
  for (const auto& c : cl.chain->couplings) coupled.push_back(cl.chain->q_joints[c.q_index]);
  std::array<std::vector<int>, 3> rows;  // by RowUnit
  for (size_t r = 0; r < d.rows.size(); ++r) {
    rows[static_cast<int>(identify::UnitOf(d.rows[r].type))].push_back(static_cast<int>(r));
  }
  if (std::count_if(rows.begin(), rows.end(), [](const auto& v) { return !v.empty(); }) <= 1) {
    WriteFileAtomic(ctx.out->File(what + "_data.csv"),
                    identify::FormatCalibrationCsv(d, cl.chain->q_joints, coupled));
    return;
  }
  const char* names[3] = {"_data.csv", "_pixels.csv", "_gravity.csv"};
  for (int u = 0; u < 3; ++u) {
    if (rows[u].empty()) continue;
    DataSet part = identify::Subset(d, rows[u]);
    part.poses = d.poses;  // a subset keeps the rows' pose indices, not the labels
    WriteFileAtomic(ctx.out->File(what + names[u]),
                    identify::FormatCalibrationCsv(part, cl.chain->q_joints, coupled));
  }
}

}  // namespace

DataSet LoadRows(ClosedLoopSetup& cl, const Source& s, RunContext& ctx, const std::string& what) {
  DataSet d;
  d.camera = cl.camera;
  d.frames = cl.frames;
  d.points = cl.points;
  d.offset_unknown = cl.offset_unknown;
  if (!cl.chain->couplings.empty() && s.type != Source::Type::kCsv &&
      !(s.type == Source::Type::kSimulate && cl.truth.tracker)) {
    throw InputError(s.where +
                     ": coupled joints (the declared model's coupled:) need csv data or a "
                     "simulated tracker");
  }
  switch (s.type) {
    case Source::Type::kMukca:
      for (const std::string& p : s.placements) {
        identify::ReadMukcaPlacement(s.path + "/" + p, p, cl.chain->model.nq(), s.socket_distance_m,
                                     &d);
      }
      break;
    case Source::Type::kCsv: {
      std::vector<std::string> coupled;
      for (const auto& c : cl.chain->couplings) coupled.push_back(cl.chain->q_joints[c.q_index]);
      identify::ReadCalibrationCsv(s.path, cl.chain->q_joints, &d, coupled);
      // Coupled joints are never read: their angles follow from the readings of their drivers.
      for (identify::Observation& o : d.rows) cl.chain->ApplyCouplings(&o.q);
      for (const auto& [a, b, dist] : s.distances) {
        const auto ia = std::find(d.groups.begin(), d.groups.end(), a);
        const auto ib = std::find(d.groups.begin(), d.groups.end(), b);
        if (ia == d.groups.end() || ib == d.groups.end()) {
          throw InputError(s.where + ": distance between unknown groups '" + a + "', '" + b + "'");
        }
        d.distances.push_back({static_cast<int>(ia - d.groups.begin()),
                               static_cast<int>(ib - d.groups.begin()), dist});
      }
      break;
    }
    case Source::Type::kLog: {
      const sim::RecordedLog& log = Log(cl, s);
      const std::vector<int> column = IndexLog(log, *cl.chain, cl.declared.file).column;
      if (s.streams.count("imu")) AppendGravity(cl, log, s, what, ctx, &d);
      if (cl.camera.present && !log.tag_rows.empty() && s.streams.count("tags")) {
        AppendLogPixels(cl, log, column, s, what, ctx, &d);
      }
      if (log.truth_t.empty() || !s.streams.count("truth")) break;
      const auto it = std::find(cl.points.begin(), cl.points.end(), log.truth_frame);
      if (it == cl.points.end()) {
        throw InputError(log.dir + "/log.yaml: truth.frame '" + log.truth_frame +
                         "' is neither the end effector nor one of 'markers'");
      }
      const int n =
          identify::AppendLogPoints(log, column, s.from_s, s.to_s,
                                    static_cast<int>(it - cl.points.begin()), &d, LogFrame(cl, s));
      ctx.log(what + ": " + std::to_string(n) + " rows of " + log.truth_stats.file + " in " +
              Span(s));
      break;
    }
    case Source::Type::kSimulate: {
      if (cl.truth.tracker) {
        SimulateTracker(cl, s, ctx, what, &d);
        break;
      }
      SimulateSockets(cl, s, ctx, what, &d);
      // A socket reached once fixes only its own point: left out, and counted.
      std::vector<int> count(d.groups.size(), 0), keep;
      for (const auto& o : d.rows) ++count[o.group];
      for (size_t r = 0; r < d.rows.size(); ++r) {
        if (count[d.rows[r].group] >= 2) keep.push_back(static_cast<int>(r));
      }
      if (keep.size() < d.rows.size()) {
        ctx.log(what + ": " + std::to_string(d.rows.size() - keep.size()) +
                " row(s) of sockets reached only once left out");
        (*ctx.summary)["metrics"][what + "_skipped_configurations"] =
            (*ctx.summary)["metrics"][what + "_skipped_configurations"].get<int>() +
            static_cast<int>(d.rows.size() - keep.size());
        d = identify::Subset(d, keep);
      }
      break;
    }
  }
  if (d.rows.empty()) {
    throw InputError(s.where + ": no " + what + " rows" +
                     (s.type == Source::Type::kLog
                          ? " in " + Span(s) + " of " + s.path + " (" + WhyNoLogRows(cl, s) + ")"
                          : ""));
  }
  if (s.type == Source::Type::kSimulate || s.type == Source::Type::kLog) {
    WriteDataCsv(cl, ctx, d, what);
  }
  return d;
}

// The declared model for identification: a frame that only a log's tag detections measure,
// whose tag's centre is off its origin (libapriltag's centre is the tag's, the frame is the
// model's), is moved to the centre (a marker offset known exactly), so that the pixel rows
// measure the frame. A frame other rows measure (the end effector, the truth's, a marker), one
// already moved, one carrying two tags, or a tag whose corners are no parallelogram (the
// diagonals' crossing is then not their mean) keeps its place, is said, and gives no rows.
sim::DeclaredModel WithTagCentres(ClosedLoopSetup& cl) {
  sim::DeclaredModel d = cl.declared;
  std::set<std::string> measured = {cl.declared.end_effector};
  for (const auto& m : cl.marker_nodes) measured.insert(m.first);
  std::map<std::string, Vec3> centre_of;
  for (const Source* s : {&cl.calibration, &cl.validation}) {
    if (s->type != Source::Type::kLog) continue;
    const sim::RecordedLog& log = Log(cl, *s);
    if (!log.truth_t.empty()) measured.insert(log.truth_frame);
    if (log.tag_rows.empty() || !s->streams.count("tags")) continue;
    for (const sim::LogTag& tag : log.tags) {
      const std::array<Vec3, 4>& c = tag.corners_m;
      const Vec3 centre = sim::TagCentre(c);
      const bool parallelogram = (c[0] + c[2] - c[1] - c[3]).norm() <= 1e-9;
      const auto [it, added] = centre_of.emplace(tag.frame, centre);
      if ((!added && it->second != centre) || !parallelogram) {
        it->second = Vec3::Constant(std::nan(""));
      }
    }
  }
  for (const auto& [frame, centre] : centre_of) {
    const bool move = !centre.isZero(0.0);
    if (!centre.allFinite() ||
        (move && (!d.MarkerOffset(frame).isZero(0.0) || measured.count(frame)))) {
      cl.log_notes.push_back("log tags on '" + frame + "': no pixel rows (two tags on the " +
                             "frame, corners that are no parallelogram, or a tag centre off a " +
                             "frame other rows measure or a declared marker offset moves)");
      continue;
    }
    if (move) d.marker_offsets.push_back({frame, centre, Mat3::Zero(), ""});
    cl.centred_tag_frames.insert(frame);
  }
  return d;
}

// The first log source's camera that sees tags, when fixed on the declared model, becomes the
// identification's camera (pixel rows of the tags' centres; the camera_offset candidate), and
// its tags' frames measured points. Called when the scenario names no camera.
void CameraFromLogs(ClosedLoopSetup& cl, const ConfigNode& root) {
  for (const Source* s : {&cl.calibration, &cl.validation}) {
    if (s->type != Source::Type::kLog || cl.camera.present || !s->streams.count("tags")) continue;
    const sim::RecordedLog& log = Log(cl, *s);
    if (log.tag_rows.empty()) continue;
    const sim::LogCamera& cam =
        log.cameras[std::min_element(log.tag_rows.begin(), log.tag_rows.end(),
                                     [](const auto& a, const auto& b) { return a.t < b.t; })
                        ->camera];
    const std::string where = log.dir + "/log.yaml";
    kinematics::FrameId f = -1;
    try {
      f = cl.chain->ObservedFrame(cam.frame);
    } catch (const InputError& e) {
      throw InputError(where + ": cameras." + cam.name + ".frame: " + e.what());
    }
    kinematics::PpoeData data(cl.chain->model);
    kinematics::ForwardKinematics(cl.chain->model, data,
                                  Eigen::VectorXd::Zero(cl.chain->model.nq()));
    const lie::SE3 T_base_cam = data.T_base_frame[f];
    kinematics::ForwardKinematics(cl.chain->model, data,
                                  Eigen::VectorXd::Constant(cl.chain->model.nq(), 0.5));
    if ((T_base_cam.Inverse() * data.T_base_frame[f]).Log().norm() > 1e-12) {
      cl.log_notes.push_back(
          "log camera '" + cam.name + "' moves with the joints: its tag " +
          "detections are no identification rows (pixel rows need a fixed camera)");
      continue;
    }
    cl.camera.present = true;
    cl.camera.name = cam.frame;  // the declared model's name: camera_offset@<frame> applies there
    cl.camera.intrinsics = cam.intrinsics;
    cl.camera.T_base_cam = T_base_cam;
    if (!root.Has("pixel_std_px")) cl.opt.pixel_std_px = log.pixel_std_px;
    for (const sim::LogTag& tag : log.tags) {
      const bool listed = tag.frame == cl.declared.end_effector ||
                          std::any_of(cl.marker_nodes.begin(), cl.marker_nodes.end(),
                                      [&](const auto& m) { return m.first == tag.frame; });
      if (cl.centred_tag_frames.count(tag.frame) && !listed) {
        cl.marker_nodes.push_back({tag.frame, where + ": tags.ids." + std::to_string(tag.id)});
      }
    }
  }
}

// A log's IMUs at rest (identify::FindStaticWindows) measure the up direction in their frames:
// each IMU frame with a window becomes a measured point of gravity rows, and gravity_tilt a
// candidate (unless the key says otherwise). gravity_std_rad, when not given, is the
// calibration windows' RMS of what the log shows of a row's error: the mean reading's
// standard error from the readings' scatter, and the rounding of the encoders on the way to
// the IMU (identify::ReadingSteps; the mean of a resting encoder keeps it). An accelerometer's
// bias is the user's to state.
void ImuFromLogs(ClosedLoopSetup& cl, const ConfigNode& root) {
  double ss = 0.0;
  int n = 0;
  for (const Source* s : {&cl.calibration, &cl.validation}) {
    if (s->type != Source::Type::kLog || !s->streams.count("imu")) continue;
    const sim::RecordedLog& log = Log(cl, *s);
    if (log.imus.empty()) continue;
    const std::vector<int> column = IndexLog(log, *cl.chain, cl.declared.file).column;
    std::vector<identify::StaticWindow>& w = cl.still_windows[s];
    w = identify::FindStaticWindows(log, column, s->from_s, s->to_s, s->still);
    const std::vector<double> steps = identify::ReadingSteps(log, column);
    std::map<int, double> rounding;  // per sensor, rad^2
    for (const identify::StaticWindow& win : w) {
      if (!rounding.count(win.sensor)) {
        rounding[win.sensor] = ImuPoint(cl, log, win.sensor, steps);
      }
      if (s == &cl.calibration) ss += win.std_rad * win.std_rad + rounding[win.sensor], ++n;
    }
    if (w.empty()) {
      cl.log_notes.push_back("log IMUs of " + log.dir + ": no window at rest in " + Span(*s) +
                             " (static: min_s, gyro_max_rad_s, joint_span_rad): no gravity rows");
    }
  }
  if (n > 0 && !root.Has("gravity_std_rad")) {
    cl.opt.gravity_std_rad = std::max(std::sqrt(ss / n), 1e-6);
  }
  if (n > 0 && !root.Has("gravity_tilt")) cl.gravity_tilt = true;
}

int LogFrame(const ClosedLoopSetup& cl, const Source& s) {
  if (s.frame.empty()) return -1;
  for (size_t f = 0; f < cl.frames.size(); ++f) {
    if (cl.frames[f].name == s.frame) return static_cast<int>(f);
  }
  throw InputError(s.where + ": frame '" + s.frame +
                   "' is not declared in the scenario's 'frames'");
}

const sim::RecordedLog& Log(ClosedLoopSetup& cl, const Source& s) {
  auto it = cl.logs.find(s.path);
  if (it == cl.logs.end()) {
    it = cl.logs.emplace(s.path, sim::ReadRecordedLog(s.path)).first;
    DetectLogImages(cl.detector, &it->second);
  }
  const sim::RecordedLog& log = it->second;
  if (!log.estimate_in.empty()) {
    throw InputError(s.path_where + ": " + log.dir + " is estimated in '" + log.estimate_in +
                     "' (estimate_in): its truth and planes are not in the base frame the "
                     "identification measures in");
  }
  const std::pair<const char*, bool> has[] = {
      {"truth", !log.truth_t.empty()}, {"tags", !log.tag_rows.empty()}, {"imu", !log.imu.empty()}};
  bool any = false;
  for (const auto& [stream, present] : has) {
    if (s.streams_named && s.streams.count(stream) && !present) {
      throw InputError(s.path_where + ": streams names '" + stream + "', which " + log.dir +
                       " does not have");
    }
    any = any || (present && s.streams.count(stream));
  }
  if (!any) {
    throw InputError(s.path_where + ": " + log.dir +
                     " has none of truth.tum, tag detections (tags.csv or images/) and imu.csv" +
                     " among its streams: identification fits their rows");
  }
  return log;
}

}  // namespace flexbench::scenarios
