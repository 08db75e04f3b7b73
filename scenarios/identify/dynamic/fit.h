// Fitting dynamic terms to a log by rollouts: candidate families at the model's locations,
// finite-difference Jacobians over the segments' rollouts (one rollout per parameter, on
// `threads`), and a bounded Levenberg-Marquardt fit on the entries a mask keeps (the folds
// not held out).
#pragma once

#include <Eigen/Core>
#include <array>
#include <atomic>
#include <string>
#include <vector>

#include "scenarios/identify/dynamic/rollout.h"

namespace flexbench::identify::dynamic {

// A family at one location: its parameters are the row's values there.
struct Candidate {
  sim::DynamicKind kind = sim::DynamicKind::kJointDamping;
  std::string location;
  int num_values() const { return sim::Row(kind).num_values; }
  std::string Name() const { return std::string(sim::Row(kind).name) + "@" + location; }
};

// Every fitted row at every location of the model (sim::DynamicLocations), in table order;
// `families` (row names) limits them when not empty.
std::vector<Candidate> AllCandidates(const sim::Simulation& nominal,
                                     const std::vector<std::string>& families);

// A set of chosen candidates and their stacked values.
struct FitState {
  std::vector<int> active;  // candidate indices
  Eigen::VectorXd theta;    // their values, in order
  Prediction prediction;
  double cost = 0.0;  // sum of squared residuals the mask keeps
  bool ok = false;    // no segment diverged that diverged not under the declared model
};

class DynamicProblem {
 public:
  DynamicProblem(const RolloutModel& model, const MotionData& data, std::vector<Candidate> cands,
                 int threads);
  const std::vector<Candidate>& candidates() const { return candidates_; }
  const ResidualLayout& layout() const { return layout_; }
  const MotionData& data() const { return data_; }
  // The declared model's rollout; its diverged segments are left out of every cost after.
  const Prediction& declared() const { return declared_; }
  int Offset(const std::vector<int>& active, int index) const;
  int NumParams(const std::vector<int>& active) const;
  Eigen::VectorXd Neutral(const std::vector<int>& active) const {
    return Stacked(active, &sim::DynamicRow::neutral);
  }

  std::vector<DynamicTerm> Terms(const std::vector<int>& active, const Eigen::VectorXd& t) const;
  FitState Evaluate(const std::vector<int>& active, const Eigen::VectorXd& theta,
                    const std::vector<char>& mask) const;
  // Evaluate on fold `fold` alone (its rollout only; the other folds' entries are zero and out
  // of the cost): a held-out fold's error.
  FitState EvaluateFold(const std::vector<int>& active, const Eigen::VectorXd& theta,
                        int fold) const;
  // d residual / d theta at theta (whose rollout is `at`), the columns from `from` on, each a
  // forward-difference rollout (backward at the upper bound).
  Eigen::MatrixXd Jacobian(const std::vector<int>& active, const Eigen::VectorXd& theta,
                           const Prediction& at, int from = 0) const;
  // Bounded Levenberg-Marquardt from theta0 on the masked entries.
  FitState Fit(const std::vector<int>& active, Eigen::VectorXd theta0,
               const std::vector<char>& mask, int iterations) const;
  // Entries in the folds other than `fold` (-1: every fold), minus diverged segments.
  std::vector<char> Mask(int held_out_fold) const;
  // Multiple shooting's nuisance, the segments' starting speeds, fitted jointly with `fit`'s
  // effects: bounded Levenberg-Marquardt on both, the starts eliminated segment by segment
  // (Schur complement: a segment's speeds move only its own rollout). `fit` must be the current
  // starts' evaluation; the problem keeps the starts of the returned state.
  FitState JointFit(const FitState& fit, const std::vector<char>& mask, int iterations);
  // d residual / d start speeds: per joint a rollout with every segment's start speed of that
  // joint moved (to first order a segment's speeds move only its own rollout, so one
  // perturbation serves all); zero on segments whose perturbed rollout diverged.
  Eigen::MatrixXd StartJacobian(const FitState& fit) const;
  // J with the start speeds projected out, segment by segment (J - Js (Js'Js)^-1 Js'J, Js
  // StartJacobian's): the effects' Jacobian with the starts free, for their covariance.
  Eigen::MatrixXd WithoutStarts(const Eigen::MatrixXd& J, const Eigen::MatrixXd& Js) const;
  double Cost(const Eigen::VectorXd& residual, const std::vector<char>& mask) const;
  Eigen::VectorXd Lower(const std::vector<int>& active) const {
    return Stacked(active, &sim::DynamicRow::lower);
  }
  Eigen::VectorXd Upper(const std::vector<int>& active) const {
    return Stacked(active, &sim::DynamicRow::upper);
  }
  int threads() const { return threads_; }
  // Rollouts of the log so far, in passes over every segment (fold rollouts / folds).
  long rollouts() const { return fold_rollouts_ / data_.folds; }

 private:
  const RolloutModel& model_;
  MotionData data_;
  std::vector<Candidate> candidates_;
  ResidualLayout layout_;
  Prediction declared_;
  int threads_ = 1;
  mutable std::atomic<long> fold_rollouts_{0};
  Eigen::VectorXd Stacked(const std::vector<int>& active,
                          std::array<double, 2> sim::DynamicRow::*column) const;
  // The state of `prediction`: ok unless a segment diverged that the declared model's did not,
  // its cost on `mask`'s entries.
  FitState Judged(const std::vector<int>& active, const Eigen::VectorXd& theta,
                  Prediction prediction, const std::vector<char>& mask) const;
  // Every fold of the log rolled with `terms`, the folds as tasks on the threads.
  Prediction Roll(const std::vector<DynamicTerm>& terms) const;
  // Rolls the log with variant v's terms and segment start speeds (nullptr: the log's) for
  // every v < `variants`, into out[v]; each (variant, fold) pair is a task on the threads.
  template <typename TermsOf, typename StartsOf>
  void RollVariants(int variants, TermsOf terms_of, StartsOf starts_of,
                    std::vector<Prediction>* out) const;
};

}  // namespace flexbench::identify::dynamic
