// The particle filter (particle_filter.h) as a flexbench Estimator. The registry names choose
// which readings enter the likelihood [PF eq. 23]; the scenario's parameters set the numbers.
//
//   pf_encoders          reference angles only [PF eq. 28]
//   pf_encoders_ee       + the end-effector position [PF eq. 26]
//   pf_encoders_imu      + the orientation of every IMU frame [PF eq. 27], lambda (-800,-800,0,0)
//   pf_all               + both
//   pf_bingham_unimodal  encoders + IMU orientations with lambda (-800,-800,-800,0)
//   pf_bingham_axisym    encoders + IMU orientations with lambda (-800,-800,0,0)
//
// Measurements:
//   JointReading        -> reference angles u (its `std` is not used: kappa_w is the model of
//                          "the actual joint is close to the reference", [PF eq. 28])
//   ImuReading          -> its IMU's orientation filter (imu/imu_orientations.h: one Madgwick
//                          filter per IMU of the set-up), if the filter uses IMUs (else
//                          kIgnored); the orientation enters at the step's JointReading
//   OrientationReading  -> Bingham term of its frame, if that frame is an orientation frame
//   PositionReading     -> Gaussian term with R_w = diag(ee_variance), if its frame is in F_P (the
//                          reading's own cov is not used: R_w is the paper's hyperparameter)
//   anything else       -> kIgnored.
//
// A step, as the paper's Fig. 5: Predict(t) opens it; the IMU readings up to t, in any number,
// only run their filters; the JointReading weighs the particles by the reference angles, then by
// one Bingham term per IMU used that had readings since the last term, in the set-up's order.
// A step without JointReading gets its IMU terms when the next step opens. (One term per raw
// reading would multiply the terms' weight by the IMU rate over the step rate.)
//
// Parameters (all optional; Params holds numbers, flags are 0 or 1):
//   particles (2048), kappa_w (15), kappa_v (5), kappa_0 (0.1)          Table I, [PF eq. 29]
//   bingham_lambda [4] (per name above; sorted ascending, largest 0)     [PF eqs. 9, 27]
//   ee_variance [1 or 3] (0.01 m^2)                                      [PF eq. 26], R_w
//   imus [indices into setup.imus] (all IMUs for the names that use them, else none)
//   ee_position (0/1) (per name above)
//   ess_threshold (0.5): resample when ESS < ess_threshold * N
//   systematic_resampling (0): 1 = systematic instead of stratified
//   conjugate_proposal (0): 1 = the encoder-conjugate proposal (particle_filter.h)
//   laplace_proposal (0): 1 = the proposal that folds in every reading of the step
//     (particle_filter.h); excludes conjugate_proposal
//   rao_blackwell (1): with laplace_proposal, the joint means from each particle's exact
//     conditional moments (conditional_moments.h); 0 = from the particles' own angles
//   initial_at_first_reading (0): 1 = initial particles vM(kappa_0, first reading), not about 0
//
// Predict(t) makes one system-model step [PF eq. 30] when t is later than the last step.
//
// On an augmented model whose identified effects carry standard deviations, the estimate's
// covariance is the particles' plus those parameters' through the kinematics at the last reading
// (as the PPOE estimators carry them in their sources): the particles describe the joint angles
// only, and the fitted parameters' error moves the end effector where no joint can (a tilted
// plate near a singular posture). The declared PPOE sources are not added: the PF paper's filter
// has none.
#pragma once

#include <memory>

#include "estimators/estimator.h"
#include "estimators/imu/imu_orientations.h"
#include "estimators/pf/particle_filter.h"

namespace flexbench::estimators {

class PfEstimator : public Estimator {
 public:
  struct Variant {
    const char* name;
    bool ee_position;
    bool imus;
    Vec4 lambda;
  };
  PfEstimator(const EstimatorSetup& setup, const Variant& variant);

  void Reset() override;
  void Predict(double t) override;
  UpdateStatus Update(const Measurement& z) override;
  Belief Estimate() const override;

  const pf::ParticleFilter& filter() const { return *filter_; }
  const pf::ParticleFilterConfig& config() const { return filter_->config(); }
  // IMU orientation terms the filter refused (non-finite or not unit) since it was made.
  int deferred_rejections() const override { return imu_terms_rejected_; }
  const pf::ParticleSummary* Particles() const override { return &filter_->Summary(); }

 private:
  void ParameterCovariance(const Eigen::VectorXd& q);
  UpdateStatus UpdateJoints(const JointReading& j);
  // The Bingham term of each IMU used with readings since its last term (set-up order).
  void ApplyImuTerms();

  std::string name_;
  // The declared model with its identified effects at the last joint reading; the particles
  // live in its joint angles (the readings are mapped before they weigh them).
  std::unique_ptr<kinematics::EffectiveChain> kin_;
  std::unique_ptr<pf::ParticleFilter> filter_;
  bool has_t_ = false;
  double t_ = 0.0;
  // The IMUs' orientation filters (none when the filter uses no IMU) and which IMUs enter.
  std::unique_ptr<imu::ImuOrientations> imu_;
  std::vector<char> imu_used_;
  bool joints_in_step_ = false;
  int imu_terms_rejected_ = 0;
  // The identified effects' uncertainty (their stds), which the particles, living in joint
  // angles, cannot carry: the declared model without its PPOE sources, with the effects, at the
  // last reading; its end-effector covariance is added to the particles' (ParameterCovariance).
  std::unique_ptr<kinematics::PpoeModel> bare_;
  std::unique_ptr<kinematics::EffectiveChain> param_kin_;
  std::unique_ptr<kinematics::PpoeData> param_data_;
  Mat6 param_cov_ = Mat6::Zero();
};

// Builds the filter configuration of `variant` from the setup and its Params (InputError with
// the estimator's name for bad values); exposed for tests.
pf::ParticleFilterConfig MakePfConfig(const EstimatorSetup& setup,
                                      const PfEstimator::Variant& variant);

std::unique_ptr<Estimator> MakePfEncoders(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakePfEncodersEe(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakePfEncodersImu(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakePfAll(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakePfBinghamUnimodal(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakePfBinghamAxisym(const EstimatorSetup& setup);

}  // namespace flexbench::estimators
