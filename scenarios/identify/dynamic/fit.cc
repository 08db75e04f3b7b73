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

DynamicProblem::DynamicProblem(const RolloutModel& model, const MotionData& data,
                               std::vector<Candidate> cands, int threads)
    : model_(model), data_(data), candidates_(std::move(cands)), threads_(std::max(1, threads)) {
  layout_ = MakeLayout(data_);
  Prediction raw = Roll({}, data_);
  SetUnknownNoise(layout_, raw.error, &data_);
  declared_ = Roll({}, data_);
}

Prediction DynamicProblem::Roll(const std::vector<DynamicTerm>& terms,
                                const MotionData& data) const {
  ++rollouts_;
  return Rollout(model_, terms, data, layout_);
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

FitState DynamicProblem::Evaluate(const std::vector<int>& active, const Eigen::VectorXd& theta,
                                  const std::vector<char>& mask) const {
  FitState f;
  f.active = active;
  f.theta = theta;
  f.prediction = Roll(Terms(active, theta), data_);
  f.ok = true;
  for (size_t s = 0; s < f.prediction.diverged.size(); ++s) {
    if (f.prediction.diverged[s] && !declared_.diverged[s]) f.ok = false;
  }
  f.cost = f.ok ? Cost(f.prediction.residual, mask) : std::numeric_limits<double>::infinity();
  return f;
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
  ForEachTask(n - from, threads_, [&](int col) {
    const int i = from + col;
    Eigen::VectorXd t = theta;
    // Forward, or backward at the upper bound.
    const double h = t[i] + step[i] <= hi[i] ? step[i] : -step[i];
    t[i] += h;
    if (t[i] < lo[i]) t[i] = lo[i];
    const Prediction p = Roll(Terms(active, t), data_);
    J.col(col) = (p.residual - at.residual) / h;
    // A diverged segment has no derivative, nor the next one, which starts from a settled state.
    for (int k = 0; k < layout_.size(); ++k) {
      const int s = layout_.segment[k];
      if (p.diverged[s] || (s > 0 && p.diverged[s - 1] && !at.diverged[s - 1])) J(k, col) = 0.0;
    }
  });
  return J;
}

FitState DynamicProblem::Fit(const std::vector<int>& active, Eigen::VectorXd theta,
                             const std::vector<char>& mask, int iterations) const {
  const Eigen::VectorXd lo = Lower(active), hi = Upper(active);
  theta = theta.cwiseMax(lo).cwiseMin(hi);
  FitState best = Evaluate(active, theta, mask);
  if (!best.ok || theta.size() == 0) return best;
  double lambda = 1e-3;
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
      H.diagonal() += lambda * D;
      const Eigen::VectorXd step = -H.ldlt().solve(g);
      const Eigen::VectorXd t = (best.theta + step).cwiseMax(lo).cwiseMin(hi);
      FitState trial = Evaluate(active, t, mask);
      if (trial.ok && trial.cost < best.cost) {
        const double gain = (best.cost - trial.cost) / best.cost;
        best = std::move(trial);
        lambda = std::max(1e-7, lambda / 5.0);
        improved = true;
        if (gain < 1e-4) return best;
      } else {
        lambda *= 8.0;
      }
    }
    if (!improved) break;
  }
  return best;
}

}  // namespace flexbench::identify::dynamic

namespace flexbench::identify::dynamic {

FitState DynamicProblem::RefineStarts(const FitState& fit, int iterations) {
  const int nj = static_cast<int>(data_.joints.size());
  const int ns = static_cast<int>(data_.segments.size());
  constexpr double kStep = 1e-3;  // rad/s
  std::vector<Prediction> moved(nj);
  const Eigen::MatrixXd start = data_.start_qd;
  ForEachTask(nj, threads_, [&](int k) {
    MotionData d = data_;
    d.start_qd.col(k).array() += kStep;
    moved[k] = Roll(Terms(fit.active, fit.theta), d);
  });
  const Eigen::VectorXd& r = fit.prediction.residual;
  int k = 0;
  for (int s = 0; s < ns; ++s) {
    const int first = k;
    while (k < layout_.size() && layout_.segment[k] == s) ++k;
    bool lost = declared_.diverged[s] || fit.prediction.diverged[s];
    for (int j = 0; j < nj; ++j) {
      lost |= moved[j].diverged[s] || (s > 0 && moved[j].diverged[s - 1]);
    }
    if (lost) continue;
    Eigen::MatrixXd J(k - first, nj);
    for (int j = 0; j < nj; ++j) {
      J.col(j) =
          (moved[j].residual.segment(first, k - first) - r.segment(first, k - first)) / kStep;
    }
    Eigen::MatrixXd A = J.transpose() * J;
    A.diagonal() += 1e-9 * A.diagonal().cwiseMax(1e-12);
    data_.start_qd.row(s) +=
        (-A.ldlt().solve(J.transpose() * r.segment(first, k - first))).transpose();
  }
  FitState refit = Fit(fit.active, fit.theta, Mask(-1), iterations);
  if (!refit.ok || refit.cost >= fit.cost) {
    data_.start_qd = start;
    return fit;
  }
  return refit;
}

}  // namespace flexbench::identify::dynamic
