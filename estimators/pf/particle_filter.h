// The von Mises / Bingham particle filter of the particle-filter paper (sec. III), on a declared
// PpoeModel.
//
// State: the effective joint angles x in [-pi, pi)^m of the rigid model [PF eq. 22], one particle =
// one point of the torus, stored as (cos x_j, sin x_j) in structure-of-arrays form
// (cos[j * stride + i], stride >= N). Propagating x + v is then a rotation of the unit vector, the
// batch forward kinematics (batch_kinematics.h) needs no trigonometry, and the circular mean
// [PF eq. 5] is a sum.
//
// Initial particles: vM(kappa_0, 0)^m [PF eq. 29]. System model: x_t = x_{t-1} + v_t,
// v_t ~ vM(kappa_v, 0)^m [PF eq. 30], one draw per Predict step (the paper's quasi-static model has
// no time scale). Likelihood [PF eq. 23]: the product of
//   - the reference-angle term prod_j vM(kappa_w, 0)(u_j - x_j) [PF eq. 28] per JointReading u,
//   - a Gaussian N(0, R_w)(p - Pos(F; x)) per position-observed frame F in F_P [PF eq. 26],
//   - a Bingham B(M, lambda)(q (.) Rot(F; x)^-1) per orientation-observed frame in F_Q [PF eq. 27],
// each applied when its reading arrives; a frame without a reading in a step contributes
// log-likelihood 0 (the paper's hidden marker). Weights live in the log domain and are
// normalised by their maximum after every term [PF eq. 21], so they cannot all underflow; a
// reading whose log-likelihood is -inf or NaN for every particle is rejected and changes
// nothing. Resampling (stratified by default, systematic as an option) runs at the start of a
// step when the effective sample size is below ess_threshold * N.
//
// Proposal. kBootstrap samples the system model (the paper). kEncoderConjugate uses that the
// reference term [PF eq. 28] is conjugate to the von Mises system noise [PF eq. 30]: for each joint
// vM(kappa_v, x_prev) vM(kappa_w, u) = I0(k) / (2 pi I0(kappa_v) I0(kappa_w)) vM(k, mu) with
// k e^{i mu} = kappa_v e^{i x_prev} + kappa_w e^{i u}, so the particle is drawn from vM(k, mu) and
// weighted by I0(k) (the locally optimal proposal for that term; same model, same posterior,
// lower Monte-Carlo variance). Propagation is then deferred from Predict to the step's
// JointReading; a step without one falls back to the bootstrap move at its first other reading.
// kLaplace folds every reading of the step into the move: the step's readings are kept until
// CompleteStep (called by Predict, and by PfEstimator before an estimate), then each particle is
// drawn from a Gaussian approximation of its own target vM(k, mu) * p(readings | x) [PF eq. 23]
// with the position and Bingham terms linearised once per step at the particles' circular mean
// through the declared chain's frame Jacobians (Doucet, Godsill, Andrieu 2000, sec. II-D). The
// Gaussian lives in the chart l = 2 tan((x - xbar) / 2), whose density on the torus is exact and
// rational, with a small uniform share (bounded weights) and antithetic particle pairs; the
// particle is weighted vM(k, mu)(x) C / q(x) before the readings' likelihoods are applied, so the
// posterior is the paper's whatever the linearisation's quality (docs/particle_filter.md).
//
// Output (Summary): per-joint circular mean [PF eq. 5] (with kLaplace and rao_blackwell, of each
// particle's exact conditional first moment given its other joints, its parent and the step's
// readings: ConditionalMoments), circular standard deviation and 95%
// interval (2.5% and 97.5% weighted quantiles of the deviations from the mean), and the
// end-effector pose at the mean angles (the paper's gripper "from estimated effective joint
// angles") with the second moment of the particles' poses about it, in its local tangent space
// (xi = [rho; theta], conventions.h).
//
// Memory is allocated at construction; Reset, Predict, the Update* calls and Summary do not touch
// the heap (tests/unit/pf_alloc/).
#pragma once

#include <memory>
#include <random>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/ppoe_data.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/se3.h"
#include "estimators/pf/batch_kinematics.h"
#include "estimators/pf/bingham.h"
#include "estimators/pf/circular_quantile.h"
#include "estimators/pf/conditional_moments.h"
#include "estimators/pf/particle_moments.h"
#include "estimators/pf/resampling.h"
#include "estimators/pf/von_mises.h"

namespace flexbench::pf {

enum class Proposal { kBootstrap, kEncoderConjugate, kLaplace };

// The most joints a filter supports (the same capacity as estimators::JointVector).
inline constexpr int kMaxPfJoints = 32;

struct ParticleFilterConfig {
  int num_particles = 2048;
  double kappa_w = 15.0;  // reference angles, [PF eq. 28]
  double kappa_v = 5.0;   // system noise, [PF eq. 30]
  double kappa_0 = 0.1;   // initial particles, [PF eq. 29]
  // The initial particles about the first joint reading, vM(kappa_0, u_0), instead of about 0:
  // [PF eq. 29] assumes the arm starts at its zero pose; a tracker started on a moving arm
  // would otherwise begin kappa_0-sure of a pose it is not in.
  bool initial_at_first_reading = false;
  // F_P and its covariance R_w [PF eq. 26].
  std::vector<FrameId> position_frames;
  Mat3 position_cov = 0.01 * Mat3::Identity();
  // F_Q and its Bingham parameters [PF eq. 27]; lambda as in [PF eq. 9].
  std::vector<FrameId> orientation_frames;
  Vec4 bingham_lambda = Vec4(-800.0, -800.0, 0.0, 0.0);
  Mat4 bingham_M = Mat4::Identity();
  ResamplingScheme resampling = ResamplingScheme::kStratified;
  double ess_threshold = 0.5;  // resample when ESS < ess_threshold * N; in (0, 1]
  Proposal proposal = Proposal::kBootstrap;
  // kLaplace: the joint means from each particle's exact conditional moments
  // (conditional_moments.h) instead of its own angles; same posterior, less Monte-Carlo noise.
  bool rao_blackwell = true;
  FrameId end_effector = -1;  // pose reported by Summary (-1: none)
};

// Throws InputError with a clear message for any invalid field (kappas <= 0 or not finite,
// N outside [2, 1 << 22], more than kMaxPfJoints joints, lambda not sorted or not shifted, R_w not
// symmetric positive definite, unknown frames, ess_threshold outside (0, 1]). `what` prefixes the
// messages.
void ValidateConfig(const ParticleFilterConfig& config, const kinematics::PpoeModel& model,
                    const std::string& what);

struct ParticleSummary {
  int nq = 0;
  // Per joint (first nq entries used).
  double mean[kMaxPfJoints] = {};
  double circular_std[kMaxPfJoints] = {};
  double lower95[kMaxPfJoints] = {};  // mean + 2.5% quantile of the deviation (not wrapped)
  double upper95[kMaxPfJoints] = {};  // mean + 97.5% quantile of the deviation (not wrapped)
  bool has_end_effector = false;
  lie::SE3 T_base_ee;
  Mat6 cov_ee = Mat6::Zero();
  double ess = 0.0;  // effective sample size of the current weights
};

enum class PfStatus { kAccepted, kIgnored, kRejectedNonFinite, kRejectedOutside, kRejectedAllZero };

class ParticleFilter {
 public:
  // Validates the config (InputError). Allocates everything the filter will ever need.
  ParticleFilter(const kinematics::PpoeModel& model, const ParticleFilterConfig& config,
                 std::uint64_t seed);

  const ParticleFilterConfig& config() const { return config_; }
  int num_particles() const { return n_; }
  int nq() const { return nq_; }

  // Back to the initial particles of [PF eq. 29]; reseeds the random stream (same seed, same run).
  void Reset();
  // One system-model step [PF eq. 30]. With kEncoderConjugate the move waits for the step's
  // JointReading; with kLaplace for CompleteStep (which Predict calls first).
  void Predict();
  // kLaplace: moves the particles with every reading since Predict and applies them; Summary,
  // the weights and the angles show the step only after it. A no-op for the other proposals
  // and when nothing is pending.
  void CompleteStep();

  // Replaces the kinematic model by `model` (the same frames and joints, other fixed parts: the
  // declared model corrected at this reading, kinematics::EffectiveChain). Kept by reference;
  // does not allocate.
  void SetModel(const kinematics::PpoeModel& model);

  // Reference angles u (nq values; [PF eq. 28]). Non-finite values are rejected.
  PfStatus UpdateReference(const double* u, int n);
  // Position p_base of the point p_frame on frame [PF eq. 26]. Ignored for frames not in F_P.
  PfStatus UpdatePosition(FrameId frame, const Vec3& p_frame, const Vec3& p_base);
  // Orientation of frame in the base frame [PF eq. 27]. Ignored for frames not in F_Q; a quaternion
  // whose norm differs from 1 by more than kUnitQuaternionTol is rejected (kRejectedOutside).
  PfStatus UpdateOrientation(FrameId frame, const Quat& q_base_frame);

  // The weighted-particle summary (computed on demand, cached until the particles change).
  const ParticleSummary& Summary() const;

  // log p(readings of this step | earlier readings), estimated from the weights (the
  // normalisers of every term, including the Bingham C(lambda), are included).
  double StepLogLikelihood() const;
  // Effective sample size of the current weights, and of the weights that triggered (or not)
  // the last resampling decision.
  double EffectiveSampleSize() const;
  double last_ess_before_resampling() const { return last_ess_; }
  bool last_step_resampled() const { return last_resampled_; }
  long resample_count() const { return resample_count_; }

  // Raw particle access (tests, plots): angle of joint j of particle i, and its normalised weight.
  double Angle(int j, int i) const;
  double Weight(int i) const;

 private:
  void ComputeKinematics();
  void CentreOnReading(const double* u);
  void ResampleIfNeeded();
  void PropagateBootstrap();
  void PropagateConjugate(const double* u);
  void EnsurePropagated();
  // kLaplace: keeps a reading of the pending step; false when it has no room (apply it now).
  bool KeepReading(const double* u, FrameId frame, const Vec3* p_frame, const Vec3* p_base,
                   const Quat* q);
  void LaplaceMove();
  // The readings' log-likelihood at lin_q_ to second order in the joint angles: H_ (precision)
  // and g_ (gradient), summed over the kept readings.
  void LinearisedReadings();
  // Adds ll_ (+ constant) to the log weights; false when every particle got -inf/NaN.
  bool ApplyLogLikelihood(double constant);
  double LogSumExpWeights() const;

  const kinematics::PpoeModel* model_;
  ParticleFilterConfig config_;
  std::uint64_t seed_;
  int n_;
  int nq_;
  std::mt19937_64 rng_;
  VonMisesTableSampler system_noise_;  // [PF eq. 30], the hot loop
  VonMisesTableSampler initial_;       // [PF eq. 29]
  Bingham bingham_;
  // The encoder-conjugate proposal: vM(k, mu) draws and log I0(k) weights for
  // k in [|kappa_v - kappa_w|, kappa_v + kappa_w].
  VonMisesFamilySampler conjugate_sampler_;
  LogBesselI0Interpolant log_i0_;
  Mat3 position_info_;               // R_w^-1
  double log_norm_position_ = 0.0;   // -1/2 log det(2 pi R_w)
  double log_norm_reference_ = 0.0;  // -log(2 pi I0(kappa_w)) per joint
  double log_norm_conjugate_ = 0.0;  // -log(2 pi I0(kappa_v) I0(kappa_w)) per joint

  size_t stride_ = 0;                // distance between two joints' arrays (>= N)
  std::vector<double> cos_, sin_;    // [nq][stride_]
  std::vector<double> cos2_, sin2_;  // resampling targets
  std::vector<double> log_w_;        // max-normalised log weights
  std::vector<double> ll_;           // scratch: this term's log-likelihood per particle
  std::vector<double> w_;            // scratch: exp(log_w_)
  std::vector<int> ancestors_;
  std::vector<std::uint64_t> bits_;  // scratch of the system-noise sampler
  BatchKinematics fk_;
  std::vector<int> position_outputs_;     // fk_ output index per position frame
  std::vector<int> orientation_outputs_;  // fk_ output index per orientation frame
  int ee_output_ = -1;

  // kLaplace: the pending step's readings and the linearisation scratch.
  struct KeptPosition {
    FrameId frame;
    Vec3 p_frame, p_base;
    bool applied;  // its likelihood was applied (CompleteStep)
  };
  struct KeptOrientation {
    FrameId frame;
    Quat q_base_frame;
    bool applied;
  };
  bool kept_u_valid_ = false;
  double kept_u_[kMaxPfJoints] = {};
  std::vector<KeptPosition> kept_positions_;        // capacity: one per F_P frame
  std::vector<KeptOrientation> kept_orientations_;  // capacity: one per F_Q frame
  size_t num_kept_positions_ = 0, num_kept_orientations_ = 0;
  // kLaplace with rao_blackwell: the parents of the step's move and the conditional moments,
  // valid from CompleteStep until the particles or weights change.
  std::unique_ptr<ConditionalMoments> rb_;
  std::vector<double> prev_c_, prev_s_;  // [nq][stride_]
  bool rb_valid_ = false;
  void RaoBlackwellise(const double* u, size_t np, size_t no);
  kinematics::PpoeData lin_data_;
  Eigen::VectorXd lin_q_;
  kinematics::Matrix6Xd J_frame_q_;
  double H_[kMaxPfJoints * kMaxPfJoints] = {};
  double g_[kMaxPfJoints] = {};
  std::vector<double> k_;  // [nq][stride_]: each particle's conjugate concentrations
  // The proposal's Gaussian draws, and the share of its draws that are uniform on the torus.
  std::normal_distribution<double> normal_;
  static constexpr double kDefensiveShare = 1.0 / 128.0;

  bool pending_move_ = false;
  bool awaiting_first_reading_ = false;  // initial_at_first_reading: centre on the next reading
  long moves_ = 0;  // bootstrap moves since Reset (for the periodic renormalisation)
  double log_norm_at_step_start_ = 0.0;  // logsumexp(log_w_) when the step's move happened
  double shift_ = 0.0;                   // maxima removed from log_w_ since then, + constants
  double last_ess_ = 0.0;
  bool last_resampled_ = false;
  long resample_count_ = 0;

  mutable bool summary_valid_ = false;
  mutable ParticleSummary summary_;
  mutable CircularQuantileScratch quantiles_;
  mutable std::vector<double> scratch_w_;
  mutable KeptParticles kept_;                   // the summary's non-negligible particles
  mutable std::vector<double> kept_c_, kept_s_;  // one joint's cos and sin at kept_'s positions
  mutable kinematics::PpoeData fk_data_;         // the end effector at the mean angles
  mutable Eigen::VectorXd q_mean_;
};

}  // namespace flexbench::pf
