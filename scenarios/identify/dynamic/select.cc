#include "scenarios/identify/dynamic/select.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "estimators/format.h"
#include "scenarios/identify/parallel.h"

namespace flexbench::identify::dynamic {
namespace {

// A candidate whose neutral values change the model (a mode's joints released at the MJCF's
// stiffness): its screening starts from a rollout with it in.
bool NeutralChangesModel(sim::DynamicKind k) {
  return k == sim::DynamicKind::kLinkMode || k == sim::DynamicKind::kBaseMode;
}

void ZeroUnmasked(const std::vector<char>& mask, Eigen::MatrixXd* J, Eigen::VectorXd* r) {
  for (int k = 0; k < J->rows(); ++k) {
    if (!mask[k]) {
      J->row(k).setZero();
      (*r)[k] = 0.0;
    }
  }
}

// min |r + J d| over d with lo <= theta + d <= hi (clamped once, the free part re-solved).
double LinearRss(const Eigen::MatrixXd& J, const Eigen::VectorXd& r, const Eigen::VectorXd& theta,
                 const Eigen::VectorXd& lo, const Eigen::VectorXd& hi, Eigen::VectorXd* d_out) {
  const Eigen::MatrixXd A = J.transpose() * J;
  const Eigen::VectorXd g = J.transpose() * r;
  Eigen::MatrixXd H = A;
  H.diagonal() += 1e-9 * A.diagonal().cwiseMax(1e-12);
  Eigen::VectorXd d = -H.ldlt().solve(g);
  const Eigen::VectorXd clamped = (theta + d).cwiseMax(lo).cwiseMin(hi) - theta;
  if ((clamped - d).norm() > 0.0) d = clamped;
  if (d_out) *d_out = d;
  return (r + J * d).squaredNorm();
}

struct Screened {
  int candidate = -1;
  double bic = 0.0;
  double rss = 0.0;
  Eigen::VectorXd start;  // the stacked values to fit from
};

class Selection {
 public:
  Selection(const DynamicProblem& p, const DynamicIdentifyOptions& o, DynamicReport* rep)
      : p_(p), o_(o), rep_(rep), all_(p.Mask(-1)) {
    for (char m : all_) n_ += m;
  }

  double Bic(double rss, int k) const { return n_ * std::log(rss / n_) + k * std::log(n_); }

  // Screens every candidate beside `state`'s; also keeps each one's columns for equivalence.
  std::vector<Screened> Screen(const FitState& state) {
    const std::vector<int>& active = state.active;
    Eigen::MatrixXd Ja = p_.Jacobian(active, state.theta, state.prediction);
    rep_->rollouts += static_cast<int>(state.theta.size());
    Eigen::VectorXd ra = state.prediction.residual;
    ZeroUnmasked(all_, &Ja, &ra);
    const int nc = static_cast<int>(p_.candidates().size());
    std::vector<Screened> out(nc);
    columns_.assign(nc, {});
    ForEachTask(nc, p_.threads(), [&](int c) {
      out[c].candidate = c;
      out[c].bic = std::numeric_limits<double>::infinity();
      if (std::find(active.begin(), active.end(), c) != active.end()) return;
      std::vector<int> ext = active;
      ext.push_back(c);
      Eigen::VectorXd theta(state.theta.size() + p_.candidates()[c].num_values());
      theta << state.theta, p_.Neutral({c});
      Prediction base = state.prediction;
      if (NeutralChangesModel(p_.candidates()[c].kind)) {
        FitState s = p_.Evaluate(ext, theta, all_);
        if (!s.ok) return;
        base = std::move(s.prediction);
      }
      // Only c's own columns are new: the chosen ones' are the state's.
      Eigen::MatrixXd Jc = SingleColumns(ext, theta, base, static_cast<int>(state.theta.size()));
      Eigen::VectorXd r = base.residual;
      ZeroUnmasked(all_, &Jc, &r);
      Eigen::MatrixXd J(Ja.rows(), Ja.cols() + Jc.cols());
      J << Ja, Jc;
      Eigen::VectorXd d;
      const double rss = LinearRss(J, r, theta, p_.Lower(ext), p_.Upper(ext), &d);
      out[c].rss = rss;
      out[c].bic = Bic(std::max(rss, 1e-300), static_cast<int>(theta.size()));
      out[c].start = theta + d;
      columns_[c] = {std::move(Jc), std::move(r)};
    });
    return out;
  }

  // The Jacobian columns from `from` on (a candidate's own), each a rollout.
  Eigen::MatrixXd SingleColumns(const std::vector<int>& ext, const Eigen::VectorXd& theta,
                                const Prediction& at, int from) const {
    return p_.Jacobian(ext, theta, at, from);
  }

  // Held-out normalised RMS: per fold a Gauss-Newton step from the fit on the other folds'
  // entries, then the held-out fold's rollout at it.
  double HeldOut(const FitState& fit) {
    const auto& L = p_.layout();
    if (fit.theta.size() == 0) return std::sqrt(p_.Cost(fit.prediction.residual, all_) / n_);
    const Eigen::MatrixXd J = p_.Jacobian(fit.active, fit.theta, fit.prediction);
    rep_->rollouts += static_cast<int>(fit.theta.size());
    const int folds = p_.data().folds;
    std::vector<double> cost(folds, 0.0);
    ForEachTask(folds, p_.threads(), [&](int f) {
      const std::vector<char> train = p_.Mask(f);
      Eigen::MatrixXd Jt = J;
      Eigen::VectorXd r = fit.prediction.residual;
      ZeroUnmasked(train, &Jt, &r);
      Eigen::VectorXd d;
      LinearRss(Jt, r, fit.theta, p_.Lower(fit.active), p_.Upper(fit.active), &d);
      const FitState at = p_.Evaluate(fit.active, fit.theta + d, train);
      const Eigen::VectorXd& res = at.ok ? at.prediction.residual : fit.prediction.residual;
      for (int k = 0; k < L.size(); ++k) {
        if (all_[k] && p_.data().segments[L.segment[k]].fold == f) cost[f] += res[k] * res[k];
      }
    });
    rep_->rollouts += folds;
    double sum = 0.0;
    for (double c : cost) sum += c;
    return std::sqrt(sum / n_);
  }

  const std::vector<char>& all() const { return all_; }
  double n() const { return n_; }
  const std::vector<std::pair<Eigen::MatrixXd, Eigen::VectorXd>>& columns() const {
    return columns_;
  }

 private:
  const DynamicProblem& p_;
  const DynamicIdentifyOptions& o_;
  DynamicReport* rep_;
  std::vector<char> all_;
  double n_ = 0.0;
  std::vector<std::pair<Eigen::MatrixXd, Eigen::VectorXd>> columns_;
};

// Sandwich covariance with segments as clusters.
Eigen::MatrixXd ClusterCovariance(const DynamicProblem& p, const FitState& fit,
                                  const std::vector<char>& mask) {
  Eigen::MatrixXd J = p.Jacobian(fit.active, fit.theta, fit.prediction);
  Eigen::VectorXd r = fit.prediction.residual;
  ZeroUnmasked(mask, &J, &r);
  const int n = static_cast<int>(fit.theta.size());
  const Eigen::MatrixXd A = J.transpose() * J;
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(n, n);
  const auto& L = p.layout();
  Eigen::VectorXd s = Eigen::VectorXd::Zero(n);
  int seg = -1;
  for (int k = 0; k <= L.size(); ++k) {
    if (k == L.size() || L.segment[k] != seg) {
      B += s * s.transpose();
      s.setZero();
      if (k == L.size()) break;
      seg = L.segment[k];
    }
    s += J.row(k).transpose() * r[k];
  }
  const Eigen::MatrixXd Ainv = A.fullPivLu().inverse();
  return Ainv * B * Ainv;
}

StreamError StreamStats(const DynamicProblem& p, const FitState& before, const FitState& after,
                        const std::vector<char>& mask, int stream) {
  static const char* kNames[3] = {"encoders", "gyro", "accel"};
  static const char* kUnits[3] = {"rad", "rad/s", "m/s^2"};
  const MotionData& d = p.data();
  StreamError e;
  e.stream = kNames[stream];
  e.unit = kUnits[stream];
  e.noise = stream == 0 ? d.std_q : stream == 1 ? d.std_gyro : d.std_accel;
  e.noise_from_log = d.noise_from_log[stream];
  double b = 0.0, a = 0.0;
  const auto& L = p.layout();
  for (int k = 0; k < L.size(); ++k) {
    if (!mask[k] || L.stream[k] != stream) continue;
    ++e.entries;
    b += before.prediction.error[k] * before.prediction.error[k];
    a += after.prediction.error[k] * after.prediction.error[k];
  }
  if (e.entries > 0) {
    e.rms_before = std::sqrt(b / e.entries);
    e.rms_after = std::sqrt(a / e.entries);
  }
  return e;
}

}  // namespace

DynamicReport IdentifyDynamics(const DynamicProblem& p, const DynamicIdentifyOptions& o) {
  DynamicReport rep;
  const MotionData& d = p.data();
  rep.segments = static_cast<int>(d.segments.size());
  rep.folds = d.folds;
  rep.diverged_declared = p.declared().num_diverged;
  rep.first_divergence = p.declared().first_divergence;
  Selection sel(p, o, &rep);
  FitState state = p.Evaluate({}, Eigen::VectorXd(), sel.all());
  const FitState declared = state;
  rep.heldout_before = sel.HeldOut(state);
  double heldout = rep.heldout_before;
  const auto& cands = p.candidates();
  std::vector<Screened> last;
  for (int round = 0;; ++round) {
    last = sel.Screen(state);
    if (round >= o.max_effects) break;
    const double bic_now = sel.Bic(state.cost, static_cast<int>(state.theta.size()));
    std::vector<Screened> kept;
    for (const Screened& s : last) {
      if (s.bic < bic_now - o.bic_threshold) kept.push_back(s);
    }
    std::sort(kept.begin(), kept.end(),
              [](const Screened& a, const Screened& b) { return a.bic < b.bic; });
    if (kept.size() > static_cast<size_t>(o.screen_keep)) kept.resize(o.screen_keep);
    FitState best;
    double best_cv = std::numeric_limits<double>::infinity();
    for (const Screened& s : kept) {
      std::vector<int> ext = state.active;
      ext.push_back(s.candidate);
      FitState fit = p.Fit(ext, s.start, sel.all(), o.iterations);
      const double cv = fit.ok ? sel.HeldOut(fit) : std::numeric_limits<double>::infinity();
      rep.log.push_back("round " + std::to_string(round + 1) + ": " + cands[s.candidate].Name() +
                        " screened BIC " + ShortNum(s.bic - bic_now) + ", held-out " +
                        ShortNum(cv) + " (now " + ShortNum(heldout) + ")");
      if (cv < best_cv) {
        best_cv = cv;
        best = std::move(fit);
      }
    }
    if (kept.empty() || !(best_cv < (1.0 - o.cv_min_gain) * heldout)) {
      rep.log.push_back("round " + std::to_string(round + 1) + ": " +
                        (kept.empty() ? "no candidate lowers BIC by " + ShortNum(o.bic_threshold)
                                      : "no candidate lowers the held-out error by " +
                                            ShortNum(100 * o.cv_min_gain) + " %") +
                        "; selection ends");
      break;
    }
    rep.log.push_back("round " + std::to_string(round + 1) + ": chose " +
                      cands[best.active.back()].Name());
    state = std::move(best);
    heldout = best_cv;
  }
  rep.heldout_after = heldout;
  // Equivalence: a swap of a chosen effect for another candidate that leaves the fit's RSS
  // within `equivalence` of what the chosen effects explained.
  const Eigen::MatrixXd Ja = state.theta.size() > 0
                                 ? p.Jacobian(state.active, state.theta, state.prediction)
                                 : Eigen::MatrixXd();
  const Eigen::MatrixXd cov = state.theta.size() > 0 ? ClusterCovariance(p, state, sel.all())
                                                     : Eigen::MatrixXd();
  const double explained = declared.cost - state.cost;
  for (size_t i = 0; i < state.active.size(); ++i) {
    ChosenEffect ce;
    const Candidate& c = cands[state.active[i]];
    const sim::DynamicRow& row = sim::Row(c.kind);
    ce.name = c.Name();
    const int off = p.Offset(state.active, static_cast<int>(i));
    for (int k = 0; k < row.num_values; ++k) {
      ce.value_names.push_back(row.value_names[k]);
      ce.values.push_back(state.theta[off + k]);
      ce.std_errors.push_back(std::sqrt(std::max(0.0, cov(off + k, off + k))));
    }
    for (size_t c2 = 0; c2 < cands.size(); ++c2) {
      const auto& [Jc, rc] = sel.columns()[c2];
      if (Jc.size() == 0 || NeutralChangesModel(cands[c2].kind)) continue;
      // The chosen set without i, plus c2, linearised at the final fit.
      std::vector<int> cols;
      for (int k = 0; k < static_cast<int>(state.theta.size()); ++k) {
        if (k < off || k >= off + row.num_values) cols.push_back(k);
      }
      Eigen::MatrixXd J(Ja.rows(), static_cast<int>(cols.size()) + Jc.cols());
      for (size_t k = 0; k < cols.size(); ++k) J.col(static_cast<int>(k)) = Ja.col(cols[k]);
      J.rightCols(Jc.cols()) = Jc;
      Eigen::VectorXd r = state.prediction.residual;
      Eigen::MatrixXd Jm = J;
      ZeroUnmasked(sel.all(), &Jm, &r);
      // Undo chosen i's part of the fit: r at the fit with i's values back at neutral.
      r += Ja.middleCols(off, row.num_values) *
           (p.Neutral({state.active[i]}) - state.theta.segment(off, row.num_values));
      ZeroUnmasked(sel.all(), &Jm, &r);
      const double rss = (r - Jm * Jm.colPivHouseholderQr().solve(r)).squaredNorm();
      if (rss - state.cost <= o.equivalence * explained) ce.equivalent.push_back(cands[c2].Name());
    }
    rep.chosen.push_back(std::move(ce));
  }
  for (int s = 0; s < 3; ++s) {
    StreamError e = StreamStats(p, declared, state, sel.all(), s);
    if (e.entries > 0) rep.streams.push_back(e);
  }
  bool all_explained = true;
  for (const StreamError& e : rep.streams) {
    all_explained &= e.rms_after <= o.explained_rms * e.noise;
  }
  rep.verdict = rep.chosen.empty()                ? "unexplained"
                : all_explained                   ? "explained"
                                                  : "partly_explained";
  rep.final_state = std::move(state);
  return rep;
}

}  // namespace flexbench::identify::dynamic
