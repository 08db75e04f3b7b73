#include "scenarios/identify/log_gravity.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>

namespace flexbench::identify {
namespace {

// One sensor's readings in a span, in time order (indices into log.imu).
std::vector<size_t> SensorReadings(const sim::RecordedLog& log, int sensor, double t_from,
                                   double t_to) {
  std::vector<size_t> out;
  if (log.joint_t.empty()) return out;
  const double lo = std::max(t_from, log.joint_t.front());
  const double hi = std::min(t_to, log.joint_t.back());
  for (size_t i = 0; i < log.imu.size(); ++i) {
    const estimators::ImuReading& r = log.imu[i];
    if (r.imu == sensor && r.t >= lo && r.t <= hi) out.push_back(i);
  }
  return out;
}

// The window over readings[begin..end] (inclusive) of `sensor`, when long enough.
bool MakeWindow(const sim::RecordedLog& log, const std::vector<int>& column,
                const std::vector<size_t>& readings, size_t begin, size_t end, int sensor,
                const StaticWindowOptions& opt, StaticWindow* w) {
  const int n = static_cast<int>(end - begin + 1);
  const double t0 = log.imu[readings[begin]].t, t1 = log.imu[readings[end]].t;
  if (n < 10 || !(t1 - t0 >= opt.min_s)) return false;
  Vec3 mean = Vec3::Zero();
  Eigen::VectorXd q_sum = Eigen::VectorXd::Zero(static_cast<int>(column.size())), q;
  for (size_t k = begin; k <= end; ++k) {
    const estimators::ImuReading& r = log.imu[readings[k]];
    mean += r.accel;
    sim::JointsAt(log, column, r.t, &q);
    q_sum += q;
  }
  mean /= n;
  if (!(mean.norm() > 0.0)) return false;
  // The scatter normal to the mean direction, per axis, over the mean's length: the direction's
  // standard error.
  const Vec3 u = mean.normalized();
  double normal_ss = 0.0;
  for (size_t k = begin; k <= end; ++k) {
    const Vec3 d = log.imu[readings[k]].accel - mean;
    normal_ss += (d - d.dot(u) * u).squaredNorm();
  }
  w->sensor = sensor;
  w->t_begin = t0;
  w->t_end = t1;
  w->readings = n;
  w->q = q_sum / n;
  w->up = u;
  w->accel_norm = mean.norm();
  w->std_rad = std::sqrt(normal_ss / (2.0 * (n - 1)) / n) / mean.norm();
  return true;
}

// Per joint row, the spread (max - min) of one joints.csv column over the rows within h of it:
// monotonic queues of the window's candidates for its minimum and maximum, so that a long log
// at a high rate costs a pass, not a pass per row.
std::vector<double> JointSpread(const sim::RecordedLog& log, int col, double h) {
  const std::vector<double>& t = log.joint_t;
  const auto v = [&](size_t r) { return log.q(r)[col]; };
  std::vector<double> out(t.size());
  std::deque<size_t> lo, hi;  // row indices, values increasing (lo) or decreasing (hi)
  size_t next = 0;            // the first row not yet in the window
  for (size_t r = 0; r < t.size(); ++r) {
    for (; next < t.size() && t[next] <= t[r] + h; ++next) {
      while (!lo.empty() && v(lo.back()) >= v(next)) lo.pop_back();
      while (!hi.empty() && v(hi.back()) <= v(next)) hi.pop_back();
      lo.push_back(next);
      hi.push_back(next);
    }
    while (t[lo.front()] < t[r] - h) lo.pop_front();
    while (t[hi.front()] < t[r] - h) hi.pop_front();
    out[r] = v(hi.front()) - v(lo.front());
  }
  return out;
}

}  // namespace

std::vector<StaticWindow> FindStaticWindows(const sim::RecordedLog& log,
                                            const std::vector<int>& column, double t_from,
                                            double t_to, const StaticWindowOptions& opt) {
  std::vector<StaticWindow> out;
  // A joint row is at rest when every joint's readings within min_s / 2 of it stay within the
  // span: a window then starts where the arm has stopped, not in the slow end of a motion.
  const std::vector<double>& jt = log.joint_t;
  std::vector<char> row_still(jt.size(), 1);
  for (size_t j = 0; j < column.size(); ++j) {
    const std::vector<double> spread = JointSpread(log, column[j], 0.5 * opt.min_s);
    for (size_t r = 0; r < jt.size(); ++r) row_still[r] &= spread[r] <= opt.joint_span_rad;
  }
  for (size_t s = 0; s < log.imus.size(); ++s) {
    const int sensor = static_cast<int>(s);
    const std::vector<size_t> readings = SensorReadings(log, sensor, t_from, t_to);
    size_t begin = 0;
    bool open = false;
    for (size_t k = 0; k <= readings.size(); ++k) {
      bool still = false;
      if (k < readings.size()) {
        const estimators::ImuReading& r = log.imu[readings[k]];
        // The joint rows on either side of the reading (SensorReadings keeps it inside them).
        const size_t b = std::lower_bound(jt.begin(), jt.end(), r.t) - jt.begin();
        const size_t a = jt[b] == r.t ? b : b - 1;
        still = r.gyro.norm() <= opt.gyro_max_rad_s && row_still[a] && row_still[b];
      }
      if (still && !open) begin = k, open = true;
      if (!still && open) {
        StaticWindow w;
        if (MakeWindow(log, column, readings, begin, k - 1, sensor, opt, &w)) {
          out.push_back(std::move(w));
        }
        open = false;
      }
    }
  }
  return out;
}

std::vector<double> ReadingSteps(const sim::RecordedLog& log, const std::vector<int>& column) {
  std::vector<double> step(column.size(), 0.0);
  for (size_t j = 0; j < column.size(); ++j) {
    double smallest = std::numeric_limits<double>::infinity();
    for (size_t r = 1; r < log.joint_t.size(); ++r) {
      const double d = std::abs(log.q(r)[column[j]] - log.q(r - 1)[column[j]]);
      if (d > 0.0) smallest = std::min(smallest, d);
    }
    if (std::isfinite(smallest)) step[j] = smallest;
  }
  return step;
}

}  // namespace flexbench::identify
