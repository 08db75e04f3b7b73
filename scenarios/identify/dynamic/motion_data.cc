#include "scenarios/identify/dynamic/motion_data.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>

#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/mujoco_model.h"

namespace flexbench::identify::dynamic {
namespace {

// Column of each actuated joint in `names` (a log file's joint columns), InputError naming the
// file when one is missing or extra.
std::vector<int> ColumnsOf(const std::vector<std::string>& actuated,
                           const std::vector<std::string>& names, const std::string& file,
                           const std::string& model, const char* unit = "_rad") {
  std::vector<int> col;
  for (const std::string& j : actuated) {
    const auto it = std::find(names.begin(), names.end(), j);
    if (it == names.end()) {
      throw InputError(file + ":1: no column for actuated joint '" + j + "' of " + model + " (" +
                       j + unit + ")");
    }
    col.push_back(static_cast<int>(it - names.begin()));
  }
  for (const std::string& n : names) {
    if (std::find(actuated.begin(), actuated.end(), n) == actuated.end()) {
      throw InputError(file + ":1: column '" + n + "': " + model +
                       " has no actuated joint of that name");
    }
  }
  return col;
}

// A command outside what the actuator can be sent (its ctrlrange, else its joint's range).
void CheckCommandRange(const MotionData& d, const sim::Simulation& sim, const std::string& file) {
  const mjModel* m = sim.model();
  for (size_t k = 0; k < d.joints.size(); ++k) {
    const int j = sim.catalog().actuated[k];
    const int a = sim.catalog().Joint(j).actuator;
    double lo = -mjMAXVAL, hi = mjMAXVAL;
    if (m->actuator_ctrllimited[a]) {
      lo = m->actuator_ctrlrange[2 * a];
      hi = m->actuator_ctrlrange[2 * a + 1];
    } else if (m->jnt_limited[j]) {
      lo = m->jnt_range[2 * j];
      hi = m->jnt_range[2 * j + 1];
    }
    for (int r = 0; r < d.command.rows(); ++r) {
      const double c = d.command(r, static_cast<int>(k));
      if (c < lo || c > hi) {
        throw InputError(file + ": row at t = " + ShortNum(d.command_t[r]) + " s: command " +
                         ShortNum(c) + " for '" + d.joints[k] + "' is outside its actuator's " +
                         "range [" + ShortNum(lo) + ", " + ShortNum(hi) + "]");
      }
    }
  }
}

// Each row's speed: the slope at the row of a least-squares polynomial through the rows within
// `half_s` each side (fewer at the ends), which averages the encoders' noise and quantisation.
// A centred cubic is unbiased up to the motion's fourth derivative, so its window can be wider
// than a line's for the same bias, and its noise lower.
Eigen::MatrixXd LocalSlopes(const std::vector<double>& t, const Eigen::MatrixXd& q, double half_s,
                            int degree) {
  const int n = static_cast<int>(t.size());
  Eigen::MatrixXd qd = Eigen::MatrixXd::Zero(n, q.cols());
  int a = 0, b = 0;
  for (int r = 0; r < n; ++r) {
    while (t[a] < t[r] - half_s - 1e-9) ++a;
    while (b + 1 < n && t[b + 1] <= t[r] + half_s + 1e-9) ++b;
    const int m = b - a + 1;
    const int deg = std::min(degree, m - 1);
    if (deg < 1) continue;
    Eigen::MatrixXd V(m, deg + 1);
    for (int i = 0; i < m; ++i) {
      const double x = (t[a + i] - t[r]) / half_s;
      double p = 1.0;
      for (int k = 0; k <= deg; ++k, p *= x) V(i, k) = p;
    }
    const Eigen::MatrixXd coef = V.colPivHouseholderQr().solve(q.middleRows(a, m));
    qd.row(r) = coef.row(1) / half_s;
  }
  return qd;
}

void CutSegments(const MotionOptions& o, double timestep, MotionData* d) {
  const std::string where = d->log_dir + "/joints.csv";
  if (!(o.segment_s >= timestep)) {
    throw InputError("segment_s = " + ShortNum(o.segment_s) +
                     " s is shorter than the model's time step (" + ShortNum(timestep) + " s)");
  }
  const int n = static_cast<int>(d->t.size());
  int begin = 0;
  for (int r = 1; r < n; ++r) {
    if (d->t[r] - d->t[begin] >= o.segment_s - 1e-9 || r == n - 1) {
      d->segments.push_back({begin, r + (r == n - 1 ? 1 : 0), 0});
      begin = r;
    }
  }
  const int s = static_cast<int>(d->segments.size());
  if (s < 2) {
    throw InputError(where + ": " + ShortNum(d->t.back() - d->t.front()) +
                     " s of rows make fewer than two segments of " + ShortNum(o.segment_s) + " s");
  }
  d->folds = std::max(1, std::min(o.folds, s));
  for (int k = 0; k < s; ++k) d->segments[k].fold = k * d->folds / s;
}

// The log's cameras, tags and detections (tags.csv) for the model: frames by their model names.
void ReadTags(const sim::RecordedLog& log, const sim::Simulation& sim, MotionData* d) {
  if (log.tag_rows.empty()) {
    if (!log.images.empty()) {
      throw InputError(log.dir +
                       "/log.yaml: the tags are given as images only: dynamic "
                       "identification reads their detections (closed_loop_dynamic detects "
                       "the images first)");
    }
    return;
  }
  const auto frame = [&](const std::string& name, const std::string& what) {
    try {
      return sim.Frame(name);
    } catch (const InputError& e) {
      throw InputError(log.dir + "/log.yaml: " + what + ": frame '" + name + "': " + e.what());
    }
  };
  for (const sim::LogCamera& c : log.cameras) {
    d->cameras.push_back({c.name, frame(c.frame, "camera '" + c.name + "'"), c.intrinsics});
  }
  for (const sim::LogTag& t : log.tags) {
    d->tags.push_back({t.id, frame(t.frame, "tag " + std::to_string(t.id)), t.corners_m});
  }
  for (const sim::LogTagRow& r : log.tag_rows) d->tag_rows.push_back({r.t, r.camera, r.tag, r.uv});
  std::stable_sort(d->tag_rows.begin(), d->tag_rows.end(),
                   [](const MotionTagRow& a, const MotionTagRow& b) { return a.t < b.t; });
}

}  // namespace

MotionData ReadMotionData(const sim::RecordedLog& log, const sim::Simulation& sim,
                          const MotionOptions& o) {
  MotionData d;
  d.log_dir = log.dir;
  d.joints = sim.actuated_joints();
  const std::string model = sim.model_name();
  if (log.command_t.empty()) {
    throw InputError(log.dir +
                     "/log.yaml: no `commands` (commands.csv): dynamic identification "
                     "drives its rollouts with the commands the servos were sent (or the "
                     "motors' torques)");
  }
  const std::vector<int> qc = ColumnsOf(d.joints, log.joints, log.joint_stats.file, model);
  const std::vector<int> cc = ColumnsOf(d.joints, log.command_joints, log.command_stats.file, model,
                                        log.command_torque ? "_Nm" : "_rad");
  const int nj = static_cast<int>(d.joints.size());
  d.t = log.joint_t;
  d.q.resize(static_cast<int>(d.t.size()), nj);
  for (size_t r = 0; r < d.t.size(); ++r) {
    for (int k = 0; k < nj; ++k) d.q(static_cast<int>(r), k) = log.q(r)[qc[k]];
  }
  d.command_t = log.command_t;
  d.command.resize(static_cast<int>(d.command_t.size()), nj);
  for (size_t r = 0; r < d.command_t.size(); ++r) {
    for (int k = 0; k < nj; ++k) d.command(static_cast<int>(r), k) = log.command(r)[cc[k]];
  }
  d.torque = log.command_torque;
  if (!d.torque) CheckCommandRange(d, sim, log.command_stats.file);
  d.qd = LocalSlopes(d.t, d.q, o.velocity_window_s, o.velocity_degree);
  if (o.use_imus) {
    for (size_t i = 0; i < log.imus.size(); ++i) {
      MotionImu imu;
      imu.name = log.imus[i].name;
      imu.site = log.imus[i].frame;
      imu.site_id = mj_name2id(sim.model(), mjOBJ_SITE, imu.site.c_str());
      if (imu.site_id < 0) {
        throw InputError(log.dir + "/log.yaml: imu sensor '" + imu.name + "': frame '" + imu.site +
                         "' is no site of " + model);
      }
      std::vector<int> rows;
      for (size_t r = 0; r < log.imu.size(); ++r) {
        if (log.imu[r].imu == static_cast<int>(i)) rows.push_back(static_cast<int>(r));
      }
      imu.gyro.resize(static_cast<int>(rows.size()), 3);
      imu.accel.resize(static_cast<int>(rows.size()), 3);
      for (size_t k = 0; k < rows.size(); ++k) {
        const estimators::ImuReading& z = log.imu[rows[k]];
        imu.t.push_back(z.t);
        imu.gyro.row(static_cast<int>(k)) = z.gyro.transpose();
        imu.accel.row(static_cast<int>(k)) = z.accel.transpose();
      }
      d.imus.push_back(std::move(imu));
    }
  }
  if (o.use_tags) ReadTags(log, sim, &d);
  d.std_q = log.joint_std;
  d.std_gyro = log.gyro_std;
  d.std_accel = log.accel_std;
  d.std_px = d.tag_rows.empty() || !log.pixel_std_stated ? 0.0 : log.pixel_std_px;
  for (int s = 0; s < 4; ++s) d.noise_from_log[s] = d.Noise(s) > 0.0;
  CutSegments(o, sim.timestep(), &d);
  d.start_qd.resize(static_cast<int>(d.segments.size()), nj);
  for (size_t s = 0; s < d.segments.size(); ++s) {
    d.start_qd.row(static_cast<int>(s)) = d.qd.row(d.segments[s].row_begin);
  }
  return d;
}

}  // namespace flexbench::identify::dynamic
