// The mean NEES of estimates that share part of their error (a fitted model parameter's error
// through the model, the same at every step): its distribution and bounds. Used wherever a
// consistency claim is checked: the runner's error statistics and the identification's source
// sizing.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "estimators/stats/chi_square.h"

namespace flexbench::stats {

// One estimate's part in a mean NEES whose estimates share part of their error: e = G z + w,
// z ~ N(0, I) the same at every step (a fitted model parameter's error through the model), w
// independent, e ~ N(0, P). With W = P - G G^T and P^+ the pseudo-inverse on P's range:
struct SharedNeesStep {
  int dof = 0;                // rank of P
  double t1 = 0.0, t2 = 0.0;  // tr(P^+ W), tr((P^+ W)^2)
  Eigen::MatrixXd X, Y;       // G^T P^+ W P^+ G and G^T P^+ G (m x m; empty: none shared)
  bool shared() const { return Y.size() > 0; }
};

// The step of an estimate with covariance `cov` and shared part G (N x m, may have no columns).
// G is first scaled down, where needed, so that G G^T <= P: the shared part of an error is at
// most all of it (an estimate whose covariance leaves the shared error out is not credited
// with it).
template <int N>
SharedNeesStep MakeSharedNeesStep(const Eigen::Matrix<double, N, Eigen::Dynamic>& G,
                                  const Eigen::Matrix<double, N, N>& cov);

// The distribution of the mean of the steps' NEES values. Given the shared z, the mean is a sum
// of independent quadratic forms with mean (sum t1 + z^T Y z) / n and variance (2 sum t2 +
// 4 z^T X z) / n^2 (Y, X summed over the steps), taken as the gamma with those two moments; the
// distribution is the average of those over `draws` draws of z from a fixed seed (the same bits
// every run). Without a shared term it is exactly that of n independent chi-square values; a
// shared term widens it, mostly upwards, since the run's NEES values then rise and fall
// together. (Moment matching alone, one gamma or Pearson's three-moment curve, held 97% and 93%
// of consistent runs inside 95% bounds in error_stats_test; this holds 95%.)
class SharedNeesDistribution {
 public:
  explicit SharedNeesDistribution(const std::vector<SharedNeesStep>& steps, int draws = 1024);
  double Cdf(double x) const;
  double Quantile(double p) const;

 private:
  struct Gamma {
    double shape, scale;
  };
  std::vector<Gamma> given_z_;
  double hi_ = 0.0;                   // above every quantile asked for
  double shape_ = 1.0, scale_ = 1.0;  // the gamma with the mixture's mean and variance
};

// Two-sided 1 - alpha bounds on the mean NEES (SharedNeesDistribution's quantiles).
ChiSquareBounds SharedNeesBounds(const std::vector<SharedNeesStep>& steps, double alpha);

}  // namespace flexbench::stats
