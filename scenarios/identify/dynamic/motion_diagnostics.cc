#include "scenarios/identify/dynamic/motion_diagnostics.h"

#include <algorithm>
#include <cmath>

#include "estimators/format.h"

namespace flexbench::identify::dynamic {
namespace {

const char* kAxes[3] = {"x", "y", "z"};

struct Channel {
  std::string name;
  std::vector<double> t, r;  // r: reading - model, over the stream's noise
  int joint = -1;            // encoders: the joint (its velocity and command)
  // Sampled at a steady rate: the tags' are not (a frame may miss a tag), so they have no
  // spectrum and no trend over time, only their level.
  bool regular = true;
};

std::vector<Channel> Channels(const DynamicProblem& p, const Prediction& pred) {
  const MotionData& d = p.data();
  const ResidualLayout& L = p.layout();
  std::vector<Channel> ch;
  const int nj = static_cast<int>(d.joints.size());
  const int ni = static_cast<int>(d.imus.size());
  for (int j = 0; j < nj; ++j) ch.push_back({"encoder " + d.joints[j], {}, {}, j});
  for (int s = 1; s <= 2; ++s) {
    for (int i = 0; i < ni; ++i) {
      for (int a = 0; a < 3; ++a) {
        ch.push_back({std::string(s == 1 ? "gyro " : "accel ") + d.imus[i].name + " " + kAxes[a],
                      {},
                      {},
                      -1});
      }
    }
  }
  // In TagChannel's order, so that a tag entry's channel is its index from here.
  const int tags_from = static_cast<int>(ch.size());
  static const char* kCorner[8] = {"c0 u", "c0 v", "c1 u", "c1 v", "c2 u", "c2 v", "c3 u", "c3 v"};
  for (const MotionCamera& cam : d.cameras) {
    for (const MotionTag& tag : d.tags) {
      for (const char* corner : kCorner) {
        ch.push_back({"tag " + std::to_string(tag.id) + " in " + cam.name + " " + corner,
                      {},
                      {},
                      -1,
                      false});
      }
    }
  }
  for (int k = 0; k < L.size(); ++k) {
    if (pred.diverged[L.segment[k]] || p.declared().diverged[L.segment[k]]) continue;
    const int s = L.stream[k];
    const int c = s == 0   ? L.channel[k]
                  : s == 3 ? tags_from + L.channel[k]
                           : nj + (s - 1) * 3 * ni + L.channel[k];
    ch[c].t.push_back(L.t[k]);
    ch[c].r.push_back(-pred.residual[k]);
  }
  return ch;
}

double MedianStep(const std::vector<double>& t) {
  std::vector<double> dt;
  for (size_t i = 1; i < t.size(); ++i) {
    if (t[i] > t[i - 1]) dt.push_back(t[i] - t[i - 1]);
  }
  if (dt.empty()) return 0.0;
  std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
  return dt[dt.size() / 2];
}

// A series of the log at the times `t`: column j of rows (times rt), linearly interpolated.
std::vector<double> At(const std::vector<double>& rt, const Eigen::MatrixXd& rows, int j,
                       const std::vector<double>& t) {
  std::vector<double> out(t.size());
  for (size_t i = 0; i < t.size(); ++i) {
    const size_t b = std::min<size_t>(
        std::max<size_t>(1, std::lower_bound(rt.begin(), rt.end(), t[i]) - rt.begin()),
        rt.size() - 1);
    const double span = rt[b] - rt[b - 1];
    const double s = span > 0 ? std::clamp((t[i] - rt[b - 1]) / span, 0.0, 1.0) : 1.0;
    out[i] = (1 - s) * rows(static_cast<int>(b - 1), j) + s * rows(static_cast<int>(b), j);
  }
  return out;
}

Eigen::MatrixXd CommandRate(const MotionData& d) {
  const int n = static_cast<int>(d.command_t.size());
  Eigen::MatrixXd rate = Eigen::MatrixXd::Zero(n, d.command.cols());
  for (int r = 0; r < n; ++r) {
    const int a = std::max(0, r - 1), b = std::min(n - 1, r + 1);
    const double span = d.command_t[b] - d.command_t[a];
    if (span > 0) rate.row(r) = (d.command.row(b) - d.command.row(a)) / span;
  }
  return rate;
}

// The residual's mean square while `joint` reverses (speed below `slow`) over its mean square
// elsewhere, and a one-sided p-value for it: the two means compared with their standard errors
// from blocks of `block` samples (a rollout's residual is correlated over its segment).
struct Reversal {
  double ratio = 0.0;
  double p_value = 1.0;
};
Reversal AtReversals(const Channel& c, const std::vector<double>& v, double slow, int block) {
  Reversal out;
  std::vector<double> slow_blocks, fast_blocks;
  double s_sum = 0, f_sum = 0;
  int s_n = 0, f_n = 0;
  const int n = static_cast<int>(c.r.size());
  for (int b = 0; b + block <= n; b += block) {
    double ss = 0, fs = 0;
    int sn = 0, fn = 0;
    for (int i = b; i < b + block; ++i) {
      const double r2 = c.r[i] * c.r[i];
      if (std::abs(v[i]) < slow) {
        ss += r2;
        ++sn;
      } else {
        fs += r2;
        ++fn;
      }
    }
    if (sn > 0) slow_blocks.push_back(ss / sn);
    if (fn > 0) fast_blocks.push_back(fs / fn);
    s_sum += ss;
    s_n += sn;
    f_sum += fs;
    f_n += fn;
  }
  if (slow_blocks.size() < 5 || fast_blocks.size() < 5 || f_sum <= 0) return out;
  const auto var_of_mean = [](const std::vector<double>& x) {
    double m = 0, v = 0;
    for (double a : x) m += a;
    m /= x.size();
    for (double a : x) v += (a - m) * (a - m);
    return v / (x.size() - 1) / x.size();
  };
  const double ms = s_sum / s_n, mf = f_sum / f_n;
  out.ratio = ms / mf;
  const double z = (ms - mf) / std::sqrt(var_of_mean(slow_blocks) + var_of_mean(fast_blocks));
  out.p_value = 0.5 * std::erfc(z / std::sqrt(2.0));
  return out;
}

}  // namespace

MotionDiagnostics Diagnose(const DynamicProblem& p, const Prediction& pred,
                           const DiagnoseOptions& o) {
  MotionDiagnostics out;
  const MotionData& d = p.data();
  const std::vector<Channel> channels = Channels(p, pred);
  const Eigen::MatrixXd rate = CommandRate(d);
  // Bonferroni over the channels the tests run on (steady ones with enough samples) and the
  // three tests.
  std::vector<double> step(channels.size(), 0.0);  // the sampling step; 0: not tested
  int tested = 0;
  for (size_t i = 0; i < channels.size(); ++i) {
    const Channel& c = channels[i];
    if (c.regular && static_cast<int>(c.r.size()) >= 4 * o.window) step[i] = MedianStep(c.t);
    tested += step[i] > 0;
  }
  const double alpha = o.alpha / (3.0 * std::max(1, tested));
  for (size_t i = 0; i < channels.size(); ++i) {
    const Channel& c = channels[i];
    const int n = static_cast<int>(c.r.size());
    double sq = 0.0;
    for (double r : c.r) sq += r * r;
    if (n > 0) out.levels.push_back({c.name, std::sqrt(sq / n)});
    const double dt = step[i];
    if (!(dt > 0)) continue;
    const double hz = 1.0 / dt;
    ChannelSpectrum cs{c.name, Welch(c.r.data(), n, hz, o.window)};
    for (const SpectrumPeak& pk : FindPeaks(cs.spectrum, alpha, 3)) {
      if (pk.power_ratio < o.min_power_ratio) continue;
      out.findings.push_back({"spectrum_peak", c.name, pk.p_value, pk.frequency_hz, pk.amplitude,
                              c.name + ": a peak at " + ShortNum(pk.frequency_hz) +
                                  " Hz, amplitude " + ShortNum(pk.amplitude) + " noise std, " +
                                  ShortNum(pk.power_ratio) +
                                  "x the floor (p = " + ShortNum(pk.p_value) + ")"});
    }
    out.spectra.push_back(std::move(cs));
    // Each joint's reversals, seen in this channel.
    for (int j = 0; j < static_cast<int>(d.joints.size()); ++j) {
      const std::vector<double> vj = At(d.t, d.qd, j, c.t);
      const Reversal rv = AtReversals(c, vj, o.reversal_speed, static_cast<int>(hz / 10));
      if (rv.p_value < alpha / d.joints.size() && rv.ratio >= o.min_reversal_ratio) {
        out.findings.push_back({"reversal", c.name, rv.p_value, 0.0, rv.ratio,
                                c.name + ": the residual is " + ShortNum(rv.ratio) +
                                    " times larger while " + d.joints[j] + " reverses (|speed| < " +
                                    ShortNum(o.reversal_speed) + "; p = " + ShortNum(rv.p_value) +
                                    ")"});
      }
    }
    if (c.joint < 0) continue;
    const std::vector<double> v = At(d.t, d.qd, c.joint, c.t);
    const VelocityTrend vt = ResidualVersusVelocity(c.r.data(), v.data(), n, 16);
    const double p_v = std::min(vt.coulomb_p, vt.viscous_p);
    if (p_v < alpha && vt.explained_fraction >= o.min_velocity_share) {
      out.findings.push_back(
          {"velocity_trend", c.name, p_v, 0.0, vt.explained_fraction,
           c.name + ": the residual follows the velocity (Coulomb " + ShortNum(vt.coulomb) +
               ", viscous " + ShortNum(vt.viscous) + " noise std per unit/s, " +
               ShortNum(100 * vt.explained_fraction) + " % of it; p = " + ShortNum(p_v) + ")"});
    }
    const std::vector<double> cr = At(d.command_t, rate, c.joint, c.t);
    const LagTrend lt = ResidualVersusCommandLag(c.r.data(), cr.data(), n, hz, o.max_lag_s);
    if (lt.p_value < alpha && std::abs(lt.correlation) >= o.min_lag_correlation) {
      out.findings.push_back({"command_lag", c.name, lt.p_value, 0.0, lt.correlation,
                              c.name + ": the residual follows the command's rate (correlation " +
                                  ShortNum(lt.correlation) + " at " + ShortNum(1e3 * lt.lag_s) +
                                  " ms; a delay of " + ShortNum(1e3 * lt.delay_s) +
                                  " ms; p = " + ShortNum(lt.p_value) + ")"});
    }
  }
  std::stable_sort(
      out.findings.begin(), out.findings.end(),
      [](const MotionFinding& a, const MotionFinding& b) { return a.p_value < b.p_value; });
  std::stable_sort(out.levels.begin(), out.levels.end(),
                   [](const ChannelLevel& a, const ChannelLevel& b) { return a.rms > b.rms; });
  return out;
}

}  // namespace flexbench::identify::dynamic
