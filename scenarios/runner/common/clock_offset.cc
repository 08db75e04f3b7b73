#include "scenarios/runner/common/clock_offset.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"

namespace flexbench::scenarios {
namespace {

// The angular speed of a frame between consecutive joint rows, at the rows' mid-times.
struct Speeds {
  std::vector<double> t, speed;
};

// One IMU's angular speed readings, in time order.
struct Gyro {
  std::vector<double> t, speed;
  // Linear interpolation at t; false outside the readings.
  bool At(double tq, double* v) const {
    if (t.size() < 2 || tq < t.front() || tq > t.back()) return false;
    const size_t i = std::upper_bound(t.begin(), t.end(), tq) - t.begin();
    if (i == t.size()) {
      *v = speed.back();
      return true;
    }
    const double span = t[i] - t[i - 1];
    const double s = span > 0.0 ? (tq - t[i - 1]) / span : 0.0;
    *v = (1.0 - s) * speed[i - 1] + s * speed[i];
    return true;
  }
};

// Pearson correlation of the predicted speeds in [t0, t1) against the gyros' at lag `lag`.
double Correlation(const std::vector<Speeds>& pred, const std::vector<Gyro>& gyro, double lag,
                   double t0, double t1) {
  double n = 0, sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  for (size_t k = 0; k < pred.size(); ++k) {
    const std::vector<double>& ts = pred[k].t;
    const size_t end = std::lower_bound(ts.begin(), ts.end(), t1) - ts.begin();
    for (size_t i = std::lower_bound(ts.begin(), ts.end(), t0) - ts.begin(); i < end; ++i) {
      const double tm = ts[i];
      double y = 0.0;
      if (!gyro[k].At(tm + lag, &y)) continue;
      const double x = pred[k].speed[i];
      n += 1;
      sx += x, sy += y, sxx += x * x, syy += y * y, sxy += x * y;
    }
  }
  if (n < 10) return std::nan("");
  const double vx = sxx - sx * sx / n, vy = syy - sy * sy / n;
  if (!(vx > 0.0) || !(vy > 0.0)) return std::nan("");
  return (sxy - sx * sy / n) / std::sqrt(vx * vy);
}

// The lag of the largest correlation on `lags`, refined by a parabola; NaN without one.
// `*at_edge` (optional): whether the largest is at the first or the last lag.
double PeakLag(const std::vector<Speeds>& pred, const std::vector<Gyro>& gyro,
               const std::vector<double>& lags, double t0, double t1, double* peak,
               bool* at_edge = nullptr) {
  std::vector<double> c(lags.size());
  size_t best = lags.size();
  for (size_t i = 0; i < lags.size(); ++i) {
    c[i] = Correlation(pred, gyro, lags[i], t0, t1);
    if (std::isfinite(c[i]) && (best == lags.size() || c[i] > c[best])) best = i;
  }
  if (best == lags.size()) return std::nan("");
  *peak = c[best];
  if (at_edge) *at_edge = best == 0 || best + 1 == lags.size();
  if (best == 0 || best + 1 == lags.size() || !std::isfinite(c[best - 1]) ||
      !std::isfinite(c[best + 1])) {
    return lags[best];
  }
  const double denom = c[best - 1] - 2.0 * c[best] + c[best + 1];
  const double shift = denom < 0.0 ? 0.5 * (c[best - 1] - c[best + 1]) / denom : 0.0;
  return lags[best] + shift * (lags[1] - lags[0]);
}

}  // namespace

ClockOffset EstimateImuClockOffset(const sim::RecordedLog& log, const kinematics::PpoeModel& model,
                                   const std::vector<int>& column,
                                   const std::vector<kinematics::FrameId>& frames,
                                   double max_offset_s) {
  if (log.imu.empty()) throw InputError(log.dir + ": no IMU readings to estimate a clock offset");
  // The encoders' angular speed of each IMU frame.
  kinematics::PpoeData data(model);
  Eigen::VectorXd q(model.nq());
  std::vector<Speeds> pred(frames.size());
  std::vector<Mat3> R_prev(frames.size());
  for (size_t r = 0; r < log.joint_t.size(); ++r) {
    for (int k = 0; k < model.nq(); ++k) q[k] = log.q(r)[column[k]];
    kinematics::ForwardKinematics(model, data, q);
    for (size_t i = 0; i < frames.size(); ++i) {
      const Mat3 R = data.T_base_frame[frames[i]].rotation();
      const double dt = r > 0 ? log.joint_t[r] - log.joint_t[r - 1] : 0.0;
      if (r > 0 && dt > 0.0) {
        pred[i].t.push_back(0.5 * (log.joint_t[r] + log.joint_t[r - 1]));
        pred[i].speed.push_back(lie::SO3Log(R_prev[i].transpose() * R).norm() / dt);
      }
      R_prev[i] = R;
    }
  }
  // The gyros' (on their own clock).
  std::vector<Gyro> gyro(frames.size());
  for (const estimators::ImuReading& z : log.imu) {
    gyro[z.imu].t.push_back(z.t);
    gyro[z.imu].speed.push_back(z.gyro.norm());
  }
  const double step = std::max(1e-4, 0.25 * log.joint_stats.median_dt_s);
  std::vector<double> lags;
  for (double lag = -max_offset_s; lag <= max_offset_s + 1e-12; lag += step) lags.push_back(lag);
  ClockOffset out;
  const double t0 = log.joint_t.front(), t1 = log.joint_t.back() + 1.0;
  bool at_edge = false;
  const double lag = PeakLag(pred, gyro, lags, t0, t1, &out.correlation, &at_edge);
  if (!std::isfinite(lag) || !(out.correlation > 0.5)) {
    throw InputError(log.dir +
                     ": the joints and the IMUs move too little together to estimate "
                     "a clock offset (give clock_offset_s in log.yaml)");
  }
  if (at_edge) {
    char range[32];
    std::snprintf(range, sizeof(range), "%g", max_offset_s);
    throw InputError(log.dir + ": the IMU clock offset lies at the edge of the searched +-" +
                     range + " s or beyond (widen clock_offset_range_s, or give clock_offset_s)");
  }
  // The spread of the estimate over eight stretches of the log, each searched within 20 grid
  // steps of the whole log's peak.
  std::vector<double> near;
  for (double l : lags) {
    if (std::abs(l - lag) <= 20.0 * step) near.push_back(l);
  }
  std::vector<double> parts;
  const int kSegments = 8;
  for (int s = 0; s < kSegments; ++s) {
    const double a = t0 + (t1 - 1.0 - t0) * s / kSegments;
    const double b = t0 + (t1 - 1.0 - t0) * (s + 1) / kSegments;
    double peak = 0.0;
    const double l = PeakLag(pred, gyro, near, a, b, &peak);
    if (std::isfinite(l) && peak > 0.5) parts.push_back(l);
  }
  out.segments = static_cast<int>(parts.size());
  if (parts.size() >= 2) {
    double mean = 0.0, var = 0.0;
    for (double p : parts) mean += p / parts.size();
    for (double p : parts) var += (p - mean) * (p - mean) / (parts.size() - 1);
    out.std_s = std::sqrt(var / parts.size());
  } else {
    out.std_s = std::nan("");
  }
  // The gyro at time m + lag matches the encoders at m: the IMU clock runs `lag` ahead.
  out.offset_s = -lag;
  return out;
}

}  // namespace flexbench::scenarios
