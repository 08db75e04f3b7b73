#include "scenarios/identify/diagnostics.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include "estimators/conventions.h"
#include "estimators/stats/chi_square.h"
#include "scenarios/identify/problem.h"

namespace flexbench::identify {
namespace {

struct Regression {
  Eigen::VectorXd beta;
  double stat = 0.0;
  double p_value = 1.0;
};

// Weighted least squares of z on [1, X] against [1] alone; the test of the X columns.
Regression Regress(const Eigen::MatrixXd& X, const Eigen::VectorXd& z, const Eigen::VectorXd& w) {
  Regression out;
  const int n = static_cast<int>(z.size());
  const int p = static_cast<int>(X.cols());
  if (n < p + 3) return out;
  Eigen::MatrixXd A(n, p + 1);
  A.col(0).setOnes();
  A.rightCols(p) = X;
  const Eigen::VectorXd sw = w.cwiseSqrt();
  const Eigen::MatrixXd Aw = sw.asDiagonal() * A;
  const Eigen::VectorXd zw = sw.cwiseProduct(z);
  out.beta = Aw.colPivHouseholderQr().solve(zw);
  const double ss1 = (zw - Aw * out.beta).squaredNorm();
  const double mean = w.sum() > 0 ? w.dot(z) / w.sum() : 0.0;
  const double ss0 = (zw - sw * mean).squaredNorm();
  if (!(ss1 > 0)) return out;
  out.stat = (ss0 - ss1) / (ss1 / (n - p - 1));
  out.p_value = std::max(1e-16, 1.0 - stats::ChiSquareCdf(std::max(0.0, out.stat), p));
  return out;
}

// The most significant structure; one above the stated noise before any below it.
void Keep(ResidualFinding candidate, ResidualFinding* best) {
  const bool below = candidate.size < candidate.noise;
  const bool best_below = best->kind.empty() || best->size < best->noise;
  if (below != best_below) {
    if (!below) *best = std::move(candidate);
    return;
  }
  if (candidate.p_value < best->p_value ||
      (candidate.p_value == best->p_value && candidate.statistic > best->statistic)) {
    *best = std::move(candidate);
  }
}

// One joint's residual along its own direction, row by row: z (the residual's projection on the
// direction a small turn of the joint moves the marker, in radians), its weight, the joint's
// angle and its gravity torque. Only the rows whose marker the joint moves: a marker on another
// branch of a tree says nothing about this joint, and counted with zero weight it
// shrank the residual variance and inflated the statistic.
struct JointSamples {
  std::vector<double> z, w, q, tau;
};

// What the tests share: the position rows' residuals under the fit.
struct ResidualContext {
  const EffectModel& em;
  const DataSet& data;
  const RowLoads& loads;
  const Fit& fit;
  const IdentifyOptions& opt;
  const Problem& pr;
  const Eigen::VectorXd& res;
  const std::vector<int>& rows;  // rows with a position residual
};

JointSamples SampleJoint(const ResidualContext& c, int k, EffectModel::Workspace& ws) {
  JointSamples out;
  const double h = 1e-6;
  for (const int r : c.rows) {
    Eigen::VectorXd qp = c.data.rows[r].q, qm = qp;
    qp[k] += h;
    qm[k] -= h;
    const int pt = c.data.rows[r].point;
    const ConfigLoads& L = c.loads.At(r, c.data.rows[r], ws);
    const Vec3 s = (c.em.Predict(qp, L, c.fit.active, c.fit.theta.data(), ws, pt) -
                    c.em.Predict(qm, L, c.fit.active, c.fit.theta.data(), ws, pt)) /
                   (2 * h * c.opt.point_std_m);
    const Vec3 e = c.res.segment<3>(c.pr.row_offset(r));
    const double s2 = s.squaredNorm();
    if (!(s2 > 1e-12)) continue;
    out.z.push_back(s.dot(e) / s2);
    out.w.push_back(s2);
    out.q.push_back(c.data.rows[r].q[k]);
    out.tau.push_back(L.tau.size() > k ? L.tau[k] : 0.0);
  }
  return out;
}

// The stated noise of a joint's projected residual (rad): one over the square root of the
// typical weight, the rows' point noise seen as an angle at that joint.
double NoiseOfJoint(const Eigen::VectorXd& w) {
  std::vector<double> v(w.data(), w.data() + w.size());
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2] > 0 ? 1.0 / std::sqrt(v[v.size() / 2]) : 0.0;
}

// Half the peak-to-peak of `curve` (the fitted structure without its constant) over
// [lo, hi], never more than half the peak-to-peak of the residual `z` it explains: the size of
// what the data show, not of a curve extrapolated beyond them.
double HalfPeakToPeak(const std::function<double(double)>& curve, double lo, double hi,
                      const Eigen::VectorXd& z) {
  double mn = HUGE_VAL, mx = -HUGE_VAL;
  for (int i = 0; i <= 200; ++i) {
    const double y = curve(lo + (hi - lo) * i / 200.0);
    mn = std::min(mn, y);
    mx = std::max(mx, y);
  }
  return std::min(0.5 * (mx - mn), 0.5 * (z.maxCoeff() - z.minCoeff()));
}

// Harmonics of 1 to 3 cycles a turn that the observed range of a joint can tell apart: over a
// full turn all three, fitted together; over less, neighbouring harmonics are nearly the same
// curve and each is fitted alone, and only where at least half of its cycle is seen (a shorter
// stretch is a constant and a slope, which extrapolate to any amplitude).
std::vector<std::vector<int>> HarmonicSets(double range) {
  if (range >= 2.0 * M_PI) return {{1, 2, 3}};
  std::vector<std::vector<int>> sets;
  for (int c = 1; c <= 3; ++c) {
    if (c * range >= M_PI) sets.push_back({c});
  }
  return sets;
}

// The residual of joint k against its angle: a periodic error of 1 to 3 cycles a turn.
void TestPeriodic(int k, const JointSamples& js, ResidualFinding* best) {
  const int m = static_cast<int>(js.z.size());
  const Eigen::Map<const Eigen::VectorXd> z(js.z.data(), m), w(js.w.data(), m), q(js.q.data(), m);
  const double lo = q.minCoeff(), hi = q.maxCoeff();
  for (const std::vector<int>& harmonics : HarmonicSets(hi - lo)) {
    const int h = static_cast<int>(harmonics.size());
    Eigen::MatrixXd X(m, 2 * h);
    for (int i = 0; i < h; ++i) {
      X.col(2 * i) = (harmonics[i] * q.array()).cos();
      X.col(2 * i + 1) = (harmonics[i] * q.array()).sin();
    }
    const Regression g = Regress(X, z, w);
    if (g.beta.size() == 0) continue;
    ResidualFinding f;
    f.kind = "periodic";
    f.q_index = k;
    // [const, cos 1q, sin 1q, cos 2q, sin 2q, cos 3q, sin 3q], zero where not fitted.
    f.coefficients.assign(7, 0.0);
    f.coefficients[0] = g.beta[0];
    double amp = 0.0;
    for (int i = 0; i < h; ++i) {
      const int c = harmonics[i];
      f.coefficients[2 * c - 1] = g.beta[2 * i + 1];
      f.coefficients[2 * c] = g.beta[2 * i + 2];
      const double a = std::hypot(g.beta[2 * i + 1], g.beta[2 * i + 2]);
      if (a > amp) amp = a, f.cycles = c;
    }
    const std::vector<double> beta = f.coefficients;
    f.size = HalfPeakToPeak(
                 [&beta](double v) {
                   double y = 0.0;
                   for (int c = 1; c <= 3; ++c) {
                     y += beta[2 * c - 1] * std::cos(c * v) + beta[2 * c] * std::sin(c * v);
                   }
                   return y;
                 },
                 lo, hi, z) /
             kDeg;
    f.unit = "deg";
    f.noise = NoiseOfJoint(w) / kDeg;
    f.p_value = g.p_value;
    f.statistic = g.stat;
    f.x.assign(q.data(), q.data() + m);
    f.z.assign(z.data(), z.data() + m);
    Keep(std::move(f), best);
  }
}

// The residual of joint k against its gravity torque (linear and cubic: a spring, stiffening).
void TestLoad(int k, const JointSamples& js, ResidualFinding* best) {
  const int m = static_cast<int>(js.z.size());
  const Eigen::Map<const Eigen::VectorXd> z(js.z.data(), m), w(js.w.data(), m),
      tau(js.tau.data(), m);
  if (!(tau.cwiseAbs().maxCoeff() > 1e-6)) return;
  const double scale = tau.cwiseAbs().maxCoeff();
  Eigen::MatrixXd X(m, 2);
  X.col(0) = tau;
  X.col(1) = (tau / scale).array().cube() * scale;
  const Regression g = Regress(X, z, w);
  if (g.beta.size() == 0) return;
  ResidualFinding f;
  f.kind = "load";
  f.q_index = k;
  // Half the peak-to-peak of the fitted angle error over the loads the data hold.
  const double b1 = g.beta[1], b2 = g.beta[2];
  f.size = HalfPeakToPeak([&](double t) { return b1 * t + b2 * std::pow(t / scale, 3) * scale; },
                          tau.minCoeff(), tau.maxCoeff(), z) /
           kDeg;
  f.unit = "deg over the gravity torques";
  f.noise = NoiseOfJoint(w) / kDeg;
  f.p_value = g.p_value;
  f.statistic = g.stat;
  f.coefficients.assign(g.beta.data(), g.beta.data() + g.beta.size());
  f.x.assign(tau.data(), tau.data() + m);
  f.z.assign(z.data(), z.data() + m);
  Keep(std::move(f), best);
}

// One coordinate of the position rows' residuals, in metres.
Eigen::VectorXd AxisResiduals(const ResidualContext& c, int axis) {
  Eigen::VectorXd z(c.rows.size());
  for (size_t i = 0; i < c.rows.size(); ++i) {
    z[i] = c.res[c.pr.row_offset(c.rows[i]) + axis] * c.opt.point_std_m;
  }
  return z;
}

// Drift: each coordinate of the residual against the row order.
void TestDrift(const ResidualContext& c, ResidualFinding* best) {
  const int n = static_cast<int>(c.rows.size());
  Eigen::VectorXd t(n);
  for (int i = 0; i < n; ++i) t[i] = static_cast<double>(i) / std::max(1, n - 1);
  for (int axis = 0; axis < 3; ++axis) {
    const Eigen::VectorXd z = AxisResiduals(c, axis);
    const Regression g = Regress(t, z, Eigen::VectorXd::Ones(n));
    if (g.beta.size() == 0) continue;
    ResidualFinding f;
    f.kind = "drift";
    f.variable = std::string("row order, ") + "xyz"[axis];
    f.size = std::min(0.5 * std::abs(g.beta[1]), 0.5 * (z.maxCoeff() - z.minCoeff())) * 1e3;
    f.unit = "mm over the data";
    f.noise = c.opt.point_std_m * 1e3;
    f.p_value = g.p_value;
    f.statistic = g.stat;
    f.coefficients.assign(g.beta.data(), g.beta.data() + g.beta.size());
    f.x.assign(t.data(), t.data() + n);
    f.z.assign(z.data(), z.data() + n);
    Keep(std::move(f), best);
  }
}

// Per set: each coordinate of the residual against the set it belongs to (a placement or a
// session that errs as a whole; with socket groups the fitted points absorb most of it).
void TestSets(const ResidualContext& c, ResidualFinding* best) {
  if (c.data.sets.size() < 2) return;
  const int n = static_cast<int>(c.rows.size());
  const int S = static_cast<int>(c.data.sets.size());
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(n, S - 1);
  for (int i = 0; i < n; ++i) {
    const int set = c.data.rows[c.rows[i]].set;
    if (set > 0) X(i, set - 1) = 1.0;
  }
  for (int axis = 0; axis < 3; ++axis) {
    const Eigen::VectorXd z = AxisResiduals(c, axis);
    const Regression g = Regress(X, z, Eigen::VectorXd::Ones(n));
    if (g.beta.size() == 0) continue;
    ResidualFinding f;
    f.kind = "set";
    f.variable = std::string("set, ") + "xyz"[axis];
    f.size = g.beta.tail(S - 1).cwiseAbs().maxCoeff() * 1e3;
    f.unit = "mm between sets";
    f.noise = c.opt.point_std_m * 1e3;
    f.p_value = g.p_value;
    f.statistic = g.stat;
    Keep(std::move(f), best);
  }
}

// The finding in one line.
std::string FindingMessage(const ResidualFinding& best) {
  char line[256];
  const char* rel = best.p_value <= 1e-16 ? "<" : "=";
  if (best.kind == "periodic") {
    std::snprintf(line, sizeof(line), "residual periodic in %s, %d cycles/rev, %.3g deg, p %s %.2g",
                  best.variable.c_str(), best.cycles, best.size, rel, best.p_value);
  } else if (best.kind == "load") {
    std::snprintf(line, sizeof(line),
                  "residual follows the gravity torque of %s, %.3g %s, p %s %.2g",
                  best.variable.c_str(), best.size, best.unit.c_str(), rel, best.p_value);
  } else if (best.kind == "set") {
    std::snprintf(line, sizeof(line), "residual differs between sets (%s), %.3g %s, p %s %.2g",
                  best.variable.c_str(), best.size, best.unit.c_str(), rel, best.p_value);
  } else if (best.kind == "drift") {
    std::snprintf(line, sizeof(line), "residual drifts with the %s, %.3g %s, p %s %.2g",
                  best.variable.c_str(), best.size, best.unit.c_str(), rel, best.p_value);
  } else {
    std::snprintf(line, sizeof(line), "no residual structure tested");
    return line;
  }
  if (best.below_noise) {
    char noise[96];
    std::snprintf(noise, sizeof(noise), ", below the stated noise (%.3g %s)", best.noise,
                  best.kind == "periodic" || best.kind == "load" ? "deg" : "mm");
    return line + std::string(noise);
  }
  return line;
}

}  // namespace

// Per joint: the residual against its angle (periodic) and its load; then against the row
// order (drift) and the set; the most significant structure is the finding.
ResidualFinding FindResidualStructure(const EffectModel& em, const DataSet& data,
                                      const RowLoads& loads, const Fit& fit,
                                      const IdentifyOptions& opt) {
  ResidualFinding best;
  const Problem pr(em, data, loads, fit.active, fit.basis, opt);
  const Eigen::VectorXd res = pr.Residuals(StateOf(pr, fit));
  std::vector<int> rows;  // rows with a position residual
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (UnitOf(data.rows[r].type) == RowUnit::kMetres) rows.push_back(static_cast<int>(r));
  }
  if (rows.size() < 10) return best;
  const ResidualContext c{em, data, loads, fit, opt, pr, res, rows};
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (int k = 0; k < em.chain().nq(); ++k) {
    const JointSamples js = SampleJoint(c, k, ws);
    if (js.z.size() < 10) continue;
    TestPeriodic(k, js, &best);
    if (em.has_masses()) TestLoad(k, js, &best);
  }
  TestDrift(c, &best);
  TestSets(c, &best);
  if (best.q_index >= 0) {
    best.variable = em.chain().frame(em.chain().joint_frame(best.q_index)).name;
    const size_t slash = best.variable.find('/');
    if (slash != std::string::npos) best.variable = best.variable.substr(slash + 1);
  }
  // A structure smaller than the stated noise is not evidence of a missing effect, however many
  // rows make its p-value small.
  best.below_noise = best.size < best.noise;
  best.significant = best.p_value < opt.diagnostic_p && !best.below_noise;
  best.notable = best.p_value < opt.explained_p && !best.below_noise;
  best.message = FindingMessage(best);
  return best;
}

std::vector<int> CandidatesFor(const EffectModel& em, const ResidualFinding& finding,
                               const std::vector<int>& candidates) {
  std::vector<int> out;
  if (!finding.significant || finding.q_index < 0) return out;
  for (int c : candidates) {
    const Candidate& cand = em.candidates()[c];
    if (!cand.needs_evidence || cand.q_index != finding.q_index) continue;
    const EffectType type = cand.type;
    const bool match =
        finding.kind == "periodic"
            ? (type == EffectType::kTransmissionError || type == EffectType::kJointErrorCurve)
            : finding.kind == "load" && type == EffectType::kStiffeningSpring;
    if (match) out.push_back(c);
  }
  return out;
}

}  // namespace flexbench::identify
