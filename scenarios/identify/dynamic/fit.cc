#include "scenarios/identify/dynamic/fit.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>

#include "scenarios/identify/parallel.h"

namespace flexbench::identify::dynamic {

std::vector<Candidate> AllCandidates(const sim::Simulation& nominal,
                                     const std::vector<std::string>& families) {
  std::vector<Candidate> out;
  for (const sim::DynamicRow& row : sim::DynamicTable()) {
    if (!row.fitted) continue;
    if (!families.empty() &&
        std::find(families.begin(), families.end(), row.name) == families.end()) {
      continue;
    }
    for (const std::string& loc : sim::DynamicLocations(nominal.setup(), row.kind)) {
      out.push_back({row.kind, loc});
    }
  }
  return out;
}

namespace {

// Whether segment s of the perturbed rollout `moved` has no derivative against `at`: it diverged,
// or the segment before in its fold did (not at `at`), so s started from a settled state
// instead.
bool NoDerivative(const MotionData& d, const Prediction& moved, const Prediction& at, int s) {
  return moved.diverged[s] || (s > 0 && d.segments[s - 1].fold == d.segments[s].fold &&
                               moved.diverged[s - 1] && !at.diverged[s - 1]);
}

// Levenberg-Marquardt's damping and acceptance: a trial that lowers the cost is kept and the
// damping eased (converged when it gained less than `tol` of the cost); else the damping grows.
struct LmDamping {
  double lambda = 1e-3;
  bool converged = false;
  bool Accept(FitState trial, FitState* best, double tol) {
    if (!trial.ok || !(trial.cost < best->cost)) {
      lambda *= 8.0;
      return false;
    }
    converged = (best->cost - trial.cost) / best->cost < tol;
    *best = std::move(trial);
    lambda = std::max(1e-7, lambda / 5.0);
    return true;
  }
};

}  // namespace

DynamicProblem::DynamicProblem(const RolloutModel& model, const MotionData& data,
                               std::vector<Candidate> cands, int threads)
    : model_(model), data_(data), candidates_(std::move(cands)), threads_(std::max(1, threads)) {
  layout_ = MakeLayout(data_);
  Prediction raw = Roll({});
  SetUnknownNoise(layout_, raw.error, &data_);
  declared_ = Roll({});
}

template <typename TermsOf, typename StartsOf>
void DynamicProblem::RollVariants(int variants, TermsOf terms_of, StartsOf starts_of,
                                  std::vector<Prediction>* out) const {
  const int folds = data_.folds;
  out->assign(variants, NewPrediction(data_, layout_));
  std::vector<std::string> divergence(static_cast<size_t>(variants) * folds);
  // Folds write disjoint entries and segments of their variant's prediction.
  ForEachTask(variants * folds, threads_, [&](int task) {
    const int v = task / folds, f = task % folds;
    divergence[task] =
        RolloutFold(model_, terms_of(v), data_, layout_, f, &(*out)[v], starts_of(v));
  });
  fold_rollouts_ += static_cast<long>(variants) * folds;
  for (int v = 0; v < variants; ++v) {
    FinishPrediction({divergence.begin() + static_cast<long>(v) * folds,
                      divergence.begin() + static_cast<long>(v + 1) * folds},
                     &(*out)[v]);
  }
}

Prediction DynamicProblem::Roll(const std::vector<DynamicTerm>& terms) const {
  std::vector<Prediction> out;
  RollVariants(
      1, [&](int) -> const std::vector<DynamicTerm>& { return terms; },
      [](int) -> const Eigen::MatrixXd* { return nullptr; }, &out);
  return std::move(out[0]);
}

int DynamicProblem::Offset(const std::vector<int>& active, int index) const {
  int o = 0;
  for (int i = 0; i < index; ++i) o += candidates_[active[i]].num_values();
  return o;
}

int DynamicProblem::NumParams(const std::vector<int>& active) const {
  return Offset(active, static_cast<int>(active.size()));
}

// A column of the dynamic table (neutral, lower or upper) stacked over `active`'s values.
Eigen::VectorXd DynamicProblem::Stacked(const std::vector<int>& active,
                                        std::array<double, 2> sim::DynamicRow::*column) const {
  Eigen::VectorXd v(NumParams(active));
  int o = 0;
  for (int c : active) {
    const sim::DynamicRow& row = sim::Row(candidates_[c].kind);
    for (int k = 0; k < row.num_values; ++k) v[o++] = (row.*column)[k];
  }
  return v;
}

std::vector<DynamicTerm> DynamicProblem::Terms(const std::vector<int>& active,
                                               const Eigen::VectorXd& theta) const {
  std::vector<DynamicTerm> terms;
  int o = 0;
  for (int c : active) {
    DynamicTerm t;
    t.kind = candidates_[c].kind;
    t.location = candidates_[c].location;
    const sim::DynamicRow& row = sim::Row(t.kind);
    for (int k = 0; k < 2; ++k) t.values[k] = k < row.num_values ? theta[o + k] : row.neutral[k];
    o += row.num_values;
    terms.push_back(t);
  }
  return terms;
}

std::vector<char> DynamicProblem::Mask(int held_out_fold) const {
  std::vector<char> mask(layout_.size(), 0);
  for (int k = 0; k < layout_.size(); ++k) {
    const int s = layout_.segment[k];
    mask[k] = !declared_.diverged[s] && data_.segments[s].fold != held_out_fold;
  }
  return mask;
}

double DynamicProblem::Cost(const Eigen::VectorXd& r, const std::vector<char>& mask) const {
  double c = 0.0;
  for (int k = 0; k < r.size(); ++k) {
    if (mask[k]) c += r[k] * r[k];
  }
  return c;
}

FitState DynamicProblem::Judged(const std::vector<int>& active, const Eigen::VectorXd& theta,
                                Prediction prediction, const std::vector<char>& mask) const {
  FitState f;
  f.active = active;
  f.theta = theta;
  f.prediction = std::move(prediction);
  f.ok = true;
  for (size_t s = 0; s < f.prediction.diverged.size(); ++s) {
    if (f.prediction.diverged[s] && !declared_.diverged[s]) f.ok = false;
  }
  f.cost = f.ok ? Cost(f.prediction.residual, mask) : std::numeric_limits<double>::infinity();
  return f;
}

FitState DynamicProblem::Evaluate(const std::vector<int>& active, const Eigen::VectorXd& theta,
                                  const std::vector<char>& mask) const {
  return Judged(active, theta, Roll(Terms(active, theta)), mask);
}

FitState DynamicProblem::EvaluateFold(const std::vector<int>& active, const Eigen::VectorXd& theta,
                                      int fold) const {
  Prediction p = NewPrediction(data_, layout_);
  FinishPrediction({RolloutFold(model_, Terms(active, theta), data_, layout_, fold, &p)}, &p);
  ++fold_rollouts_;
  std::vector<char> mask = Mask(-1);
  for (int k = 0; k < layout_.size(); ++k) {
    mask[k] = mask[k] && data_.segments[layout_.segment[k]].fold == fold;
  }
  return Judged(active, theta, std::move(p), mask);
}

Eigen::MatrixXd DynamicProblem::Jacobian(const std::vector<int>& active,
                                         const Eigen::VectorXd& theta, const Prediction& at,
                                         int from) const {
  const int n = static_cast<int>(theta.size());
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(layout_.size(), n - from);
  const Eigen::VectorXd lo = Lower(active), hi = Upper(active);
  std::vector<double> step(n);
  int o = 0;
  for (int c : active) {
    const sim::DynamicRow& row = sim::Row(candidates_[c].kind);
    for (int k = 0; k < row.num_values; ++k) step[o++] = row.fd_step[k];
  }
  // Forward, or backward at the upper bound.
  std::vector<Eigen::VectorXd> moved(n - from, theta);
  std::vector<double> h(n - from);
  for (int col = 0; col < n - from; ++col) {
    const int i = from + col;
    h[col] = theta[i] + step[i] <= hi[i] ? step[i] : -step[i];
    moved[col][i] = std::max(theta[i] + h[col], lo[i]);
  }
  std::vector<Prediction> p;
  RollVariants(
      n - from, [&](int col) { return Terms(active, moved[col]); },
      [](int) -> const Eigen::MatrixXd* { return nullptr; }, &p);
  for (int col = 0; col < n - from; ++col) {
    J.col(col) = (p[col].residual - at.residual) / h[col];
    for (int k = 0; k < layout_.size(); ++k) {
      if (NoDerivative(data_, p[col], at, layout_.segment[k])) J(k, col) = 0.0;
    }
  }
  return J;
}

FitState DynamicProblem::Fit(const std::vector<int>& active, Eigen::VectorXd theta,
                             const std::vector<char>& mask, int iterations) const {
  const Eigen::VectorXd lo = Lower(active), hi = Upper(active);
  theta = theta.cwiseMax(lo).cwiseMin(hi);
  FitState best = Evaluate(active, theta, mask);
  if (!best.ok || theta.size() == 0) return best;
  LmDamping lm;
  for (int it = 0; it < iterations; ++it) {
    Eigen::MatrixXd J = Jacobian(active, best.theta, best.prediction);
    Eigen::VectorXd r = best.prediction.residual;
    for (int k = 0; k < J.rows(); ++k) {
      if (!mask[k]) {
        J.row(k).setZero();
        r[k] = 0.0;
      }
    }
    const Eigen::MatrixXd A = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    Eigen::VectorXd D = A.diagonal().cwiseMax(1e-12 * std::max(1.0, A.diagonal().maxCoeff()));
    bool improved = false;
    for (int tries = 0; tries < 6 && !improved; ++tries) {
      Eigen::MatrixXd H = A;
      H.diagonal() += lm.lambda * D;
      const Eigen::VectorXd step = -H.ldlt().solve(g);
      const Eigen::VectorXd t = (best.theta + step).cwiseMax(lo).cwiseMin(hi);
      improved = lm.Accept(Evaluate(active, t, mask), &best, 1e-4);
      if (improved && lm.converged) return best;
    }
    if (!improved) break;
  }
  return best;
}

}  // namespace flexbench::identify::dynamic

namespace flexbench::identify::dynamic {

Eigen::MatrixXd DynamicProblem::StartJacobian(const FitState& fit) const {
  const int nj = static_cast<int>(data_.joints.size());
  constexpr double kStep = 1e-3;  // rad/s
  Eigen::MatrixXd Js = Eigen::MatrixXd::Zero(layout_.size(), nj);
  // One joint's speeds moved at a time (the starts, segments x joints, not the log).
  std::vector<Eigen::MatrixXd> moved(nj, data_.start_qd);
  for (int j = 0; j < nj; ++j) moved[j].col(j).array() += kStep;
  const std::vector<DynamicTerm> terms = Terms(fit.active, fit.theta);
  std::vector<Prediction> p;
  RollVariants(
      nj, [&](int) -> const std::vector<DynamicTerm>& { return terms; },
      [&](int j) { return &moved[j]; }, &p);
  for (int j = 0; j < nj; ++j) {
    for (int k = 0; k < layout_.size(); ++k) {
      const int s = layout_.segment[k];
      const bool lost = NoDerivative(data_, p[j], fit.prediction, s) ||
                        fit.prediction.diverged[s] || declared_.diverged[s];
      Js(k, j) = lost ? 0.0 : (p[j].residual[k] - fit.prediction.residual[k]) / kStep;
    }
  }
  return Js;
}

namespace {

// The row span of each segment in the layout (entries are in segment order).
std::vector<std::pair<int, int>> SegmentRows(const ResidualLayout& L, int segments) {
  std::vector<std::pair<int, int>> rows(segments, {0, 0});
  for (int k = 0; k < L.size();) {
    const int s = L.segment[k];
    const int first = k;
    while (k < L.size() && L.segment[k] == s) ++k;
    rows[s] = {first, k - first};
  }
  return rows;
}

// A segment's start-speed block made invertible: a joint the segment does not move (a zero
// column) is held.
Eigen::MatrixXd Regularised(Eigen::MatrixXd A, double lambda) {
  const double scale = std::max(1.0, A.diagonal().maxCoeff());
  for (int i = 0; i < A.rows(); ++i) A(i, i) += lambda * A(i, i) + 1e-12 * scale;
  return A;
}

}  // namespace

Eigen::MatrixXd DynamicProblem::WithoutStarts(const Eigen::MatrixXd& J,
                                              const Eigen::MatrixXd& Js) const {
  Eigen::MatrixXd out = J;
  for (const auto& [first, n] : SegmentRows(layout_, static_cast<int>(data_.segments.size()))) {
    if (n == 0) continue;
    const auto Jss = Js.middleRows(first, n);
    const Eigen::MatrixXd A = Regularised(Jss.transpose() * Jss, 0.0);
    out.middleRows(first, n) -= Jss * A.ldlt().solve(Jss.transpose() * J.middleRows(first, n));
  }
  return out;
}

FitState DynamicProblem::JointFit(const FitState& fit, const std::vector<char>& mask,
                                  int iterations) {
  const Eigen::VectorXd lo = Lower(fit.active), hi = Upper(fit.active);
  const int np = static_cast<int>(fit.theta.size());
  const auto rows = SegmentRows(layout_, static_cast<int>(data_.segments.size()));
  FitState best = fit;
  if (!best.ok) return best;
  LmDamping lm;
  for (int it = 0; it < iterations; ++it) {
    Eigen::MatrixXd J = np > 0 ? Jacobian(best.active, best.theta, best.prediction)
                               : Eigen::MatrixXd(layout_.size(), 0);
    Eigen::MatrixXd Js = StartJacobian(best);
    Eigen::VectorXd r = best.prediction.residual;
    for (int k = 0; k < layout_.size(); ++k) {
      if (mask[k]) continue;
      J.row(k).setZero();
      Js.row(k).setZero();
      r[k] = 0.0;
    }
    const Eigen::MatrixXd A = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    bool improved = false;
    for (int tries = 0; tries < 6 && !improved; ++tries) {
      // The starts eliminated: H dtheta = -g' with H = A - sum B_s' A_s^-1 B_s.
      Eigen::MatrixXd H = A;
      Eigen::VectorXd gr = g;
      std::vector<Eigen::LDLT<Eigen::MatrixXd>> solve(rows.size());
      std::vector<Eigen::MatrixXd> B(rows.size());
      std::vector<Eigen::VectorXd> gs(rows.size());
      for (size_t s = 0; s < rows.size(); ++s) {
        const auto [first, n] = rows[s];
        if (n == 0) continue;
        const auto Jss = Js.middleRows(first, n);
        solve[s].compute(Regularised(Jss.transpose() * Jss, lm.lambda));
        B[s] = Jss.transpose() * J.middleRows(first, n);
        gs[s] = Jss.transpose() * r.segment(first, n);
        H -= B[s].transpose() * solve[s].solve(B[s]);
        gr -= B[s].transpose() * solve[s].solve(gs[s]);
      }
      Eigen::VectorXd t = best.theta;
      if (np > 0) {
        const Eigen::VectorXd D =
            H.diagonal().cwiseMax(1e-12 * std::max(1.0, H.diagonal().maxCoeff()));
        H.diagonal() += lm.lambda * D;
        t = (best.theta - H.ldlt().solve(gr)).cwiseMax(lo).cwiseMin(hi);
      }
      const Eigen::VectorXd dtheta = t - best.theta;
      const Eigen::MatrixXd starts = data_.start_qd;
      for (size_t s = 0; s < rows.size(); ++s) {
        if (rows[s].second == 0) continue;
        const Eigen::VectorXd rhs = np > 0 ? Eigen::VectorXd(gs[s] + B[s] * dtheta) : gs[s];
        data_.start_qd.row(static_cast<int>(s)) -= solve[s].solve(rhs).transpose();
      }
      improved = lm.Accept(Evaluate(best.active, t, mask), &best, 1e-5);
      if (!improved) data_.start_qd = starts;
      if (improved && lm.converged) return best;
    }
    if (!improved) break;
  }
  return best;
}

}  // namespace flexbench::identify::dynamic
