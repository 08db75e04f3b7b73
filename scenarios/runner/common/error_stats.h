// Scoring estimates against the truth: errors, NEES with its chi-square bounds (also when the
// estimates share an error, e.g. a fitted parameter's), and a running model-mismatch test.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"
#include "estimators/stats/chi_square.h"
#include "estimators/stats/shared_nees.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

using Mat6x = Eigen::Matrix<double, 6, Eigen::Dynamic>;
using stats::MakeSharedNeesStep;
using stats::SharedNeesBounds;
using stats::SharedNeesDistribution;
using stats::SharedNeesStep;

// A running model-mismatch test: the mean NEES over the last `window` estimates above the
// one-sided 99.5% bound of a mean of that many chi-square variables (their dof) flags a
// mismatch, once. One-sided, since an overconfident estimate is the dangerous one; 99.5% per
// window so that a consistent run of 30 estimates (21 overlapping windows) raises a false alarm
// about 1 time in 20. Where the estimates share a term, the window's mean is tested against
// its SharedNeesDistribution.
class MismatchTest {
 public:
  explicit MismatchTest(int window = 10) : window_(window) {}
  void Add(double nees, const SharedNeesStep& step);
  bool flagged() const { return first_ >= 0; }
  int window() const { return window_; }
  // Index of the estimate at which it fired (-1: never).
  int first_step() const { return first_; }

 private:
  int window_;
  std::vector<double> nees_;
  std::vector<SharedNeesStep> steps_;
  int first_ = -1;
};

// Accumulates per-configuration errors of one estimator and writes its metrics, with a running
// model-mismatch test over its NEES (every kind that scores estimators reports it).
class ErrorStats {
 public:
  explicit ErrorStats(int mismatch_window = 10) : mismatch_(mismatch_window) {}
  // e = Log(T_est^-1 T_true) in the estimate's tangent space (covariance `cov`), position
  // error split along/across the end effector's axis (the true z axis). G_shared (6 x m, may
  // be empty): the part of e that every estimate of the run shares, e = G_shared z + ..., z ~
  // N(0, I) (the fitted parameters' error through the model); the NEES bounds and the mismatch
  // test then account for it (SharedNeesBounds).
  void Add(const lie::SE3& T_est, const Mat6& cov, const lie::SE3& T_true,
           const Mat6x& G_shared = Mat6x());
  int count() const { return static_cast<int>(pos_.size()); }
  // Writes pos/lateral/rot error means, std, max, NEES with its chi-square bounds (6-DoF and
  // position alone) and the mismatch test (mismatch_flagged, mismatch_first_step: the index of
  // the estimate at which it fired, -1 never; it needs mismatch_window estimates to run).
  void WriteMetrics(Json* metrics) const;

  double last_pos() const { return pos_.back(); }
  double last_lateral() const { return lateral_.back(); }
  double last_rot_deg() const { return rot_deg_.back(); }
  double last_nees() const { return nees_.back(); }
  const MismatchTest& mismatch() const { return mismatch_; }

 private:
  MismatchTest mismatch_;
  std::vector<double> pos_, lateral_, rot_deg_, nees_, pos_nees_;
  std::vector<int> dof_, pos_dof_;
  std::vector<SharedNeesStep> steps_, pos_steps_;  // for the NEES bounds (SharedNeesBounds)
};

// NEES of error e against a possibly singular covariance: Mahalanobis distance on the
// covariance's range (eigenvalues above 1e-12 of the largest), with that rank as dof.
double Nees(const Vec6& e, const Mat6& cov, int* dof);
// The same for the translation part of e alone (its 3x3 block of cov).
double PositionNees(const Vec6& e, const Mat6& cov, int* dof);

}  // namespace flexbench::scenarios
