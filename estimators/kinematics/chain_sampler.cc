#include "estimators/kinematics/chain_sampler.h"

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/ppoe_data.h"

namespace flexbench::kinematics {

ChainSampler::ChainSampler(const PpoeModel& model)
    : model_(model), scratch_(model.num_frames()), drawn_(model.num_frames(), Vec6::Zero()) {
  samplers_.reserve(model.num_frames());
  for (const PpoeFrame& f : model.frames()) samplers_.emplace_back(f.source_cov);
}

void ChainSampler::Sample(const Eigen::Ref<const Eigen::VectorXd>& q, std::mt19937_64& rng,
                          std::vector<lie::SE3>* poses) {
  (*poses)[kBaseFrame] = lie::SE3::Identity();
  for (FrameId i = 1; i < model_.num_frames(); ++i) {
    const PpoeFrame& f = model_.frame(i);
    lie::SE3 T = f.T_parent_ip;
    if (f.has_source) {
      drawn_[i] = samplers_[i].Sample(rng);
      T = T * lie::SE3::Exp(drawn_[i]);
    }
    if (f.q_index >= 0) T = T * lie::SE3::Exp(f.zeta * q[f.q_index]);
    (*poses)[i] = (*poses)[f.parent] * T;
  }
}

Mat6 ChainSampler::SampleCovarianceControlVariate(const Eigen::Ref<const Eigen::VectorXd>& q,
                                                  FrameId frame, int n, std::mt19937_64& rng,
                                                  Mat6* linear) {
  PpoeData data(model_);
  ForwardKinematics(model_, data, q);
  const lie::SE3& mean = data.T_base_frame[frame];
  // Sources upstream of `frame`, with the adjoint taking each to the frame's tangent space.
  std::vector<FrameId> sources;
  std::vector<Mat6> Ad;
  for (FrameId f = frame; f > kBaseFrame; f = model_.frame(f).parent) {
    const PpoeFrame& pf = model_.frame(f);
    if (!pf.has_source) continue;
    const lie::SE3 T_base_ip = data.T_base_frame[pf.parent] * pf.T_parent_ip;
    sources.push_back(f);
    Ad.push_back(mean.Between(T_base_ip).Adjoint());
  }
  Mat6 sigma_lin = Mat6::Zero();
  for (size_t k = 0; k < sources.size(); ++k) {
    sigma_lin += Ad[k] * model_.frame(sources[k]).source_cov * Ad[k].transpose();
  }
  Mat6 diff = Mat6::Zero();
  for (int s = 0; s < n; ++s) {
    Sample(q, rng, &scratch_);
    const Vec6 xi = mean.Between(scratch_[frame]).Log();
    Vec6 xi_lin = Vec6::Zero();
    for (size_t k = 0; k < sources.size(); ++k) xi_lin += Ad[k] * drawn_[sources[k]];
    diff += xi * xi.transpose() - xi_lin * xi_lin.transpose();
  }
  if (linear) *linear = sigma_lin;
  return sigma_lin + diff / n;
}

}  // namespace flexbench::kinematics
