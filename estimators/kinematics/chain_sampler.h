// Monte-Carlo oracle of the PPOE model: the exact chain of [PPOE eq. 16] with every source drawn,
// xi_i ~ N(0, Sigma_i), no compounding approximation. The covariances of
// ForwardKinematicsWithCovariance are checked against it, and scenarios draw samples from it.
#pragma once

#include <Eigen/Core>
#include <random>
#include <vector>

#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/sampling.h"
#include "estimators/lie/se3.h"

namespace flexbench::kinematics {

class ChainSampler {
 public:
  explicit ChainSampler(const PpoeModel& model);

  // One draw of all frame poses (size num_frames) at joint angles q. `poses` must have
  // model.num_frames() entries; no allocation.
  void Sample(const Eigen::Ref<const Eigen::VectorXd>& q, std::mt19937_64& rng,
              std::vector<lie::SE3>* poses);

  // Second moment about the nominal pose, E[Log(Tbar^-1 T) Log(Tbar^-1 T)^T], of `frame` from
  // n draws (the definition of [PPOE eq. 9]), with a control variate: xi_lin = sum_i
  // Ad_{Tbar_frame^-1 Tbar_ip} xi_i, the first-order image of the drawn sources, has the exactly
  // known covariance Sigma_lin = sum_i Ad Sigma_i Ad^T, so Sigma_lin + mean(xi xi^T - xi_lin
  // xi_lin^T) estimates E[xi xi^T] with the sampling error of a 4th-order difference only. This is
  // what resolves 2nd- against 4th-order compounding at 10 deg, where their difference is smaller
  // than the raw Monte-Carlo error of a million draws. Returns Sigma_lin in *linear when given.
  Mat6 SampleCovarianceControlVariate(const Eigen::Ref<const Eigen::VectorXd>& q, FrameId frame,
                                      int n, std::mt19937_64& rng, Mat6* linear = nullptr);

 private:
  const PpoeModel& model_;
  std::vector<lie::GaussianSampler<6>> samplers_;
  std::vector<lie::SE3> scratch_;
  std::vector<Vec6> drawn_;  // the source draws of the last Sample
};

}  // namespace flexbench::kinematics
