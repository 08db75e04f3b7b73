#include "estimators/pf/particle_filter.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"
#include "estimators/pf/bessel.h"
#include "estimators/pf/particle_loop.h"
#include "estimators/pf/particle_moments.h"
#include "estimators/pf/pose_spread.h"

namespace flexbench::pf {
namespace {

constexpr double kNegInf = -std::numeric_limits<double>::infinity();
// The bands (in circular standard deviations) where Summary looks for the 95% interval's ends.
constexpr double kTailInner = 1.6;
constexpr double kTailOuter = 2.5;

void CheckPositiveFinite(double v, const std::string& what, const std::string& name) {
  if (!(v > 0.0) || !std::isfinite(v)) {
    std::ostringstream msg;
    msg << what << ": " << name << " must be finite and > 0, got " << v;
    throw InputError(msg.str());
  }
}

void CheckFrames(const std::vector<FrameId>& frames, const kinematics::PpoeModel& model,
                 const std::string& what, const char* set) {
  for (FrameId f : frames) {
    if (f < 0 || f >= model.num_frames()) {
      throw InputError(what + ": " + set + " frame id " + std::to_string(f) +
                       " does not exist in PPOE model '" + model.name() + "'");
    }
  }
}

}  // namespace

void ValidateConfig(const ParticleFilterConfig& config, const kinematics::PpoeModel& model,
                    const std::string& what) {
  if (config.num_particles < 2 || config.num_particles > (1 << 22)) {
    throw InputError(what + ": the number of particles must be in [2, 4194304], got " +
                     std::to_string(config.num_particles));
  }
  if (model.nq() < 1 || model.nq() > kMaxPfJoints) {
    throw InputError(what + ": PPOE model '" + model.name() + "' has " +
                     std::to_string(model.nq()) + " joints; the particle filter supports 1 to " +
                     std::to_string(kMaxPfJoints));
  }
  CheckPositiveFinite(config.kappa_w, what, "kappa_w");
  CheckPositiveFinite(config.kappa_v, what, "kappa_v");
  CheckPositiveFinite(config.kappa_0, what, "kappa_0");
  if (!(config.ess_threshold > 0.0 && config.ess_threshold <= 1.0)) {
    std::ostringstream msg;
    msg << what << ": ess_threshold must be in (0, 1], got " << config.ess_threshold;
    throw InputError(msg.str());
  }
  ValidateBinghamLambda(config.bingham_lambda, what);
  const Mat3& S = config.position_cov;
  if (!S.allFinite() ||
      (S - S.transpose()).cwiseAbs().maxCoeff() > 1e-12 * S.cwiseAbs().maxCoeff() ||
      Eigen::SelfAdjointEigenSolver<Mat3>(S).eigenvalues().minCoeff() <= 0.0) {
    throw InputError(what +
                     ": the position covariance R_w must be finite, symmetric and "
                     "positive definite");
  }
  CheckFrames(config.position_frames, model, what, "position");
  CheckFrames(config.orientation_frames, model, what, "orientation");
  if (config.end_effector >= model.num_frames()) {
    throw InputError(what + ": end-effector frame id " + std::to_string(config.end_effector) +
                     " does not exist in PPOE model '" + model.name() + "'");
  }
}

namespace {
bool RaoBlackwellised(const ParticleFilterConfig& c) {
  return c.proposal == Proposal::kLaplace && c.rao_blackwell;
}

// The readings' frames, the end effector, and (Rao-Blackwellised) the joint frames above them.
std::vector<FrameId> KinematicOutputs(const ParticleFilterConfig& c,
                                      const kinematics::PpoeModel& model) {
  std::vector<FrameId> out;
  const auto add = [&](FrameId f) {
    if (f >= 0 && std::find(out.begin(), out.end(), f) == out.end()) out.push_back(f);
  };
  for (FrameId f : c.position_frames) add(f);
  for (FrameId f : c.orientation_frames) add(f);
  add(c.end_effector);
  if (RaoBlackwellised(c)) {
    for (FrameId f :
         ConditionalMoments::JointFrames(model, c.position_frames, c.orientation_frames)) {
      add(f);
    }
  }
  return out;
}

// Orientation-only frames need no translation (a joint frame's locates its axis).
std::vector<bool> TranslationNeeded(const ParticleFilterConfig& c,
                                    const kinematics::PpoeModel& model) {
  std::vector<bool> out;
  std::vector<FrameId> joint_frames;
  if (RaoBlackwellised(c)) {
    joint_frames = ConditionalMoments::JointFrames(model, c.position_frames, c.orientation_frames);
  }
  for (FrameId f : KinematicOutputs(c, model)) {
    const bool orientation_only =
        f != c.end_effector &&
        std::find(joint_frames.begin(), joint_frames.end(), f) == joint_frames.end() &&
        std::find(c.position_frames.begin(), c.position_frames.end(), f) ==
            c.position_frames.end() &&
        std::find(c.orientation_frames.begin(), c.orientation_frames.end(), f) !=
            c.orientation_frames.end();
    out.push_back(!orientation_only);
  }
  return out;
}

const ParticleFilterConfig& Validated(const ParticleFilterConfig& c,
                                      const kinematics::PpoeModel& model) {
  ValidateConfig(c, model, "particle filter");
  return c;
}
}  // namespace

ParticleFilter::ParticleFilter(const kinematics::PpoeModel& model,
                               const ParticleFilterConfig& config, std::uint64_t seed)
    : model_(&model),
      config_(Validated(config, model)),
      seed_(seed),
      n_(config.num_particles),
      nq_(model.nq()),
      rng_(seed),
      system_noise_(config.kappa_v),
      initial_(config.kappa_0),
      bingham_(config.bingham_lambda, config.bingham_M),
      conjugate_sampler_(std::abs(config.kappa_v - config.kappa_w),
                         config.kappa_v + config.kappa_w),
      log_i0_(std::abs(config.kappa_v - config.kappa_w), config.kappa_v + config.kappa_w),
      fk_(model, KinematicOutputs(config, model), config.num_particles,
          TranslationNeeded(config, model)),
      lin_data_(model),
      fk_data_(model) {
  position_info_ = config_.position_cov.inverse();
  log_norm_position_ = -0.5 * std::log((2.0 * M_PI * config_.position_cov).determinant());
  log_norm_reference_ = -(std::log(2.0 * M_PI) + LogBesselI0(config_.kappa_w));
  log_norm_conjugate_ =
      -(std::log(2.0 * M_PI) + LogBesselI0(config_.kappa_v) + LogBesselI0(config_.kappa_w));
  // Joint arrays a padded N apart (see BatchKinematics: no 4 KiB aliasing between joints).
  stride_ = (static_cast<size_t>(n_) + 7) / 8 * 8 + 8;
  const size_t total = static_cast<size_t>(nq_) * stride_;
  cos_.assign(total, 1.0);
  sin_.assign(total, 0.0);
  cos2_.assign(total, 1.0);
  sin2_.assign(total, 0.0);
  log_w_.assign(n_, 0.0);
  ll_.assign(n_, 0.0);
  w_.assign(n_, 0.0);
  ancestors_.assign(n_, 0);
  bits_.assign(n_, 0);
  for (FrameId f : config_.position_frames) position_outputs_.push_back(fk_.OutputIndex(f));
  for (FrameId f : config_.orientation_frames) orientation_outputs_.push_back(fk_.OutputIndex(f));
  ee_output_ = config_.end_effector >= 0 ? fk_.OutputIndex(config_.end_effector) : -1;
  quantiles_ = CircularQuantileScratch(n_ + 4);
  scratch_w_.assign(n_, 0.0);
  kept_ = KeptParticles(n_);
  kept_c_.assign(n_ + 4, 0.0);
  kept_s_.assign(n_ + 4, 0.0);
  q_mean_ = Eigen::VectorXd::Zero(nq_);
  if (config_.proposal == Proposal::kLaplace) {
    kept_positions_.resize(config_.position_frames.size());
    kept_orientations_.resize(config_.orientation_frames.size());
    lin_q_ = Eigen::VectorXd::Zero(nq_);
    J_frame_q_ = kinematics::Matrix6Xd::Zero(6, nq_);
    k_.assign(total, 0.0);
  }
  if (RaoBlackwellised(config_)) {
    rb_ = std::make_unique<ConditionalMoments>(model, config_.position_frames,
                                               config_.orientation_frames, position_info_, stride_);
    rb_->Bind(fk_);
    prev_c_.assign(total, 1.0);
    prev_s_.assign(total, 0.0);
  }
  Reset();
}

void ParticleFilter::Reset() {
  rng_.seed(seed_);
  normal_.reset();
  // [PF eq. 29]: every joint of every particle from vM(kappa_0, 0), joint by joint.
  for (int j = 0; j < nq_; ++j) {
    double* c = cos_.data() + static_cast<size_t>(j) * stride_;
    double* s = sin_.data() + static_cast<size_t>(j) * stride_;
    for (int i = 0; i < n_; ++i) {
      const UnitAngle a = initial_.SampleUnit(rng_);
      c[i] = a.c;
      s[i] = a.s;
    }
  }
  std::fill(log_w_.begin(), log_w_.end(), 0.0);
  pending_move_ = false;
  rb_valid_ = false;
  kept_u_valid_ = false;
  num_kept_positions_ = num_kept_orientations_ = 0;
  awaiting_first_reading_ = config_.initial_at_first_reading;
  moves_ = 0;
  log_norm_at_step_start_ = std::log(static_cast<double>(n_));
  shift_ = 0.0;
  last_ess_ = n_;
  last_resampled_ = false;
  resample_count_ = 0;
  ComputeKinematics();
}

// vM(kappa_0, 0) turned by u is vM(kappa_0, u): each joint's particles rotate by its reading.
void ParticleFilter::CentreOnReading(const double* u) {
  awaiting_first_reading_ = false;
  rb_valid_ = false;
  for (int j = 0; j < nq_; ++j) {
    const double cu = std::cos(u[j]), su = std::sin(u[j]);
    double* c = cos_.data() + static_cast<size_t>(j) * stride_;
    double* s = sin_.data() + static_cast<size_t>(j) * stride_;
    for (int i = 0; i < n_; ++i) {
      const double ci = c[i];
      c[i] = ci * cu - s[i] * su;
      s[i] = s[i] * cu + ci * su;
    }
  }
  // A pending move recomputes the kinematics after it.
  if (!pending_move_) ComputeKinematics();
}

void ParticleFilter::ComputeKinematics() {
  if (fk_.num_outputs() > 0) fk_.Compute(cos_.data(), sin_.data(), static_cast<int>(stride_), n_);
  summary_valid_ = false;
}

void ParticleFilter::SetModel(const kinematics::PpoeModel& model) {
  if (model.num_frames() != model_->num_frames() || model.nq() != nq_) {
    throw InputError("particle filter: SetModel with PPOE model '" + model.name() +
                     "', which has other frames than '" + model_->name() + "'");
  }
  model_ = &model;
  fk_.Refold(model);
  // A pending move recomputes the kinematics after it; otherwise the particles stay put.
  if (!pending_move_) ComputeKinematics();
}

FLEXBENCH_PARTICLE_LOOP void ParticleFilter::ResampleIfNeeded() {
  double sum = 0.0;
  double sum2 = 0.0;
  const double* __restrict lw = log_w_.data();
  double* __restrict w = w_.data();
  for (int i = 0; i < n_; ++i) w[i] = std::exp(lw[i]);
  for (int i = 0; i < n_; ++i) {
    sum += w[i];
    sum2 += w[i] * w[i];
  }
  last_ess_ = sum * sum / sum2;
  log_norm_at_step_start_ = std::log(sum);
  shift_ = 0.0;
  last_resampled_ = last_ess_ < config_.ess_threshold * n_;
  if (!last_resampled_) return;
  Resample(config_.resampling, w_.data(), n_, rng_, ancestors_.data());
  for (int j = 0; j < nq_; ++j) {
    const size_t off = static_cast<size_t>(j) * stride_;
    const double* c = cos_.data() + off;
    const double* s = sin_.data() + off;
    double* c2 = cos2_.data() + off;
    double* s2 = sin2_.data() + off;
    for (int i = 0; i < n_; ++i) {
      c2[i] = c[ancestors_[i]];
      s2[i] = s[ancestors_[i]];
    }
  }
  cos_.swap(cos2_);
  sin_.swap(sin2_);
  rb_valid_ = false;
  std::fill(log_w_.begin(), log_w_.end(), 0.0);
  log_norm_at_step_start_ = std::log(static_cast<double>(n_));
  ++resample_count_;
}

void ParticleFilter::PropagateBootstrap() {
  rb_valid_ = false;
  // Rounding moves |(cos, sin)| by about an ulp per rotation: renormalise every 16 steps.
  const bool renormalise = (++moves_ & 15) == 0;
  for (int j = 0; j < nq_; ++j) {
    const size_t off = static_cast<size_t>(j) * stride_;
    system_noise_.RotateByNoise(rng_, cos_.data() + off, sin_.data() + off, n_, bits_.data());
    if (renormalise) RenormaliseUnit(cos_.data() + off, sin_.data() + off, n_);
  }
}

void ParticleFilter::PropagateConjugate(const double* u) {
  rb_valid_ = false;
  std::fill(ll_.begin(), ll_.end(), 0.0);
  const double kv = config_.kappa_v;
  const double kw = config_.kappa_w;
  double* __restrict k = w_.data();  // scratch: the concentrations of this joint's draws
  for (int j = 0; j < nq_; ++j) {
    const double cu = kw * std::cos(u[j]);
    const double su = kw * std::sin(u[j]);
    double* __restrict c = cos_.data() + static_cast<size_t>(j) * stride_;
    double* __restrict s = sin_.data() + static_cast<size_t>(j) * stride_;
    // k e^{i mu} = kappa_v e^{i x_prev} + kappa_w e^{i u}; (c, s) becomes e^{i mu}.
    for (int i = 0; i < n_; ++i) {
      const double zc = kv * c[i] + cu;
      const double zs = kv * s[i] + su;
      const double ki = std::sqrt(zc * zc + zs * zs);
      const bool ok = ki > 1e-300;  // kappa_v = kappa_w and opposite directions: uniform
      k[i] = ok ? ki : 1e-300;
      c[i] = ok ? zc / ki : 1.0;
      s[i] = ok ? zs / ki : 0.0;
    }
    log_i0_.AddTo(k, ll_.data(), n_);  // the weight I0(k) (the constant is in the normaliser)
    conjugate_sampler_.RotateBatch(k, c, s, n_, rng_);
  }
}

void ParticleFilter::Predict() {
  CompleteStep();
  if (config_.proposal != Proposal::kBootstrap) {
    pending_move_ = true;
    return;
  }
  ResampleIfNeeded();
  PropagateBootstrap();
  ComputeKinematics();
}

void ParticleFilter::EnsurePropagated() {
  if (!pending_move_) return;
  pending_move_ = false;
  ResampleIfNeeded();
  PropagateBootstrap();
  ComputeKinematics();
}

bool ParticleFilter::KeepReading(const double* u, FrameId frame, const Vec3* p_frame,
                                 const Vec3* p_base, const Quat* q) {
  if (config_.proposal != Proposal::kLaplace || !pending_move_) return false;
  if (u != nullptr && !kept_u_valid_) {
    std::copy(u, u + nq_, kept_u_);
    kept_u_valid_ = true;
    return true;
  }
  if (p_frame != nullptr && num_kept_positions_ < kept_positions_.size()) {
    kept_positions_[num_kept_positions_++] = {frame, *p_frame, *p_base, false};
    return true;
  }
  if (q != nullptr && num_kept_orientations_ < kept_orientations_.size()) {
    kept_orientations_[num_kept_orientations_++] = {frame, *q, false};
    return true;
  }
  // A second reading of a kind in the step: the move takes what it has, this one is a weight.
  CompleteStep();
  return false;
}

FLEXBENCH_PARTICLE_LOOP void ParticleFilter::CompleteStep() {
  if (config_.proposal != Proposal::kLaplace || !pending_move_) return;
  pending_move_ = false;
  ResampleIfNeeded();
  if (rb_) {
    std::copy(cos_.begin(), cos_.end(), prev_c_.begin());
    std::copy(sin_.begin(), sin_.end(), prev_s_.begin());
  }
  const bool with_u = kept_u_valid_;
  if (!with_u) {
    // Without encoders the step has no conjugate centre: the system model moves the particles.
    PropagateBootstrap();
    ComputeKinematics();
  } else {
    LaplaceMove();
  }
  kept_u_valid_ = false;
  const size_t np = num_kept_positions_, no = num_kept_orientations_;
  num_kept_positions_ = num_kept_orientations_ = 0;
  for (size_t a = 0; a < np; ++a) {
    const KeptPosition& r = kept_positions_[a];
    kept_positions_[a].applied =
        UpdatePosition(r.frame, r.p_frame, r.p_base) == PfStatus::kAccepted;
  }
  for (size_t a = 0; a < no; ++a) {
    KeptOrientation& r = kept_orientations_[a];
    r.applied = UpdateOrientation(r.frame, r.q_base_frame) == PfStatus::kAccepted;
  }
  if (rb_) RaoBlackwellise(with_u ? kept_u_ : nullptr, np, no);
}

// The step's conditional moments from the move's parents, its encoder reading u (or none) and
// the first np / no kept readings that were applied.
void ParticleFilter::RaoBlackwellise(const double* u, size_t np, size_t no) {
  rb_->Begin(*model_, fk_, prev_c_.data(), prev_s_.data(), u, config_.kappa_v, config_.kappa_w, n_);
  for (size_t a = 0; a < np; ++a) {
    if (!kept_positions_[a].applied) continue;
    const KeptPosition& r = kept_positions_[a];
    // The entry UpdatePosition applied (the last one of a frame listed twice).
    int f = -1;
    for (size_t b = 0; b < config_.position_frames.size(); ++b) {
      if (config_.position_frames[b] == r.frame) f = static_cast<int>(b);
    }
    if (f >= 0) rb_->AddPosition(fk_, f, position_outputs_[f], r.p_frame, r.p_base, n_);
  }
  for (size_t a = 0; a < no; ++a) {
    if (!kept_orientations_[a].applied) continue;
    const KeptOrientation& r = kept_orientations_[a];
    int f = -1;
    for (size_t b = 0; b < config_.orientation_frames.size(); ++b) {
      if (config_.orientation_frames[b] == r.frame) f = static_cast<int>(b);
    }
    if (f >= 0) {
      rb_->AddOrientation(fk_, f, orientation_outputs_[f], bingham_.RotationForm(r.q_base_frame).C,
                          n_);
    }
  }
  rb_->Finish(cos_.data(), sin_.data(), n_);
  rb_valid_ = true;
}

void ParticleFilter::LinearisedReadings() {
  const int m = nq_;
  std::fill(H_, H_ + m * m, 0.0);
  std::fill(g_, g_ + m, 0.0);
  kinematics::ForwardKinematics(*model_, lin_data_, lin_q_);
  const auto add = [&](const auto& J, const Mat3& A, const Vec3& grad) {
    for (int a = 0; a < m; ++a) {
      const Vec3 AJa = A * J.col(a);
      g_[a] += J.col(a).dot(grad);
      for (int b = 0; b < m; ++b) H_[a * m + b] += J.col(b).dot(AJa);
    }
  };
  Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, kMaxPfJoints> J(3, m);
  for (size_t a = 0; a < num_kept_positions_; ++a) {
    const KeptPosition& r = kept_positions_[a];
    const lie::SE3& T = lin_data_.T_base_frame[r.frame];
    kinematics::ComputeFrameJacobian(*model_, lin_data_, r.frame, J_frame_q_);
    // p = R p_frame + t moves by R (rho - [p_frame]x theta) for T Exp([rho; theta]).
    const Mat3 R = T.rotation();
    J = R * (J_frame_q_.topRows<3>() - lie::Skew(r.p_frame) * J_frame_q_.bottomRows<3>());
    const Vec3 residual = r.p_base - (R * r.p_frame + T.translation());
    add(J, position_info_, position_info_ * residual);
  }
  for (size_t a = 0; a < num_kept_orientations_; ++a) {
    const KeptOrientation& r = kept_orientations_[a];
    kinematics::ComputeFrameJacobian(*model_, lin_data_, r.frame, J_frame_q_);
    // log B = c0 + tr(C^T R) [PF eq. 27]; at R Exp(w), with B = C^T R, its gradient in w is
    // vee(B^T - B) and its Hessian sym(B) - tr(B) I. The Hessian's concave part is kept.
    const Mat3 B = bingham_.RotationForm(r.q_base_frame).C.transpose() *
                   lin_data_.T_base_frame[r.frame].rotation();
    const Vec3 grad(B(1, 2) - B(2, 1), B(2, 0) - B(0, 2), B(0, 1) - B(1, 0));
    const Mat3 A = B.trace() * Mat3::Identity() - 0.5 * (B + B.transpose());
    const Eigen::SelfAdjointEigenSolver<Mat3> eig(A);
    const Mat3 A_psd = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() *
                       eig.eigenvectors().transpose();
    J = J_frame_q_.bottomRows<3>();
    add(J, A_psd, grad);
  }
}

namespace {
// A coordinate of the angle of (c, s) on the line: 2 tan(angle / 2) (the angle to third order,
// one division) up to 120 degrees, the angle beyond. The proposal below needs a deterministic
// map, not the angle itself: its density is evaluated with the same map.
inline double LinearAngle(double c, double s) {
  return c > -0.5 ? 2.0 * s / (1.0 + c) : std::atan2(s, c);
}
}  // namespace

// Per particle: target k_j cos(x_j - mu_j) + l(x) with l the readings' log-likelihood to second
// order about xbar, in the chart l_j = 2 tan((x_j - xbar_j) / 2) (LinearAngle). The proposal is
// one Gaussian shape for all particles, precision P = diag(kbar) + H (kbar: the weighted mean of
// the conjugate k), about each particle's own mean P^-1 (k o l(mu) + g): l = mean + L^-T z,
// z standard normal, P = L L^T, mapped to the torus by x = xbar + 2 atan(l / 2). Its density is
// exact and needs no trigonometry: N(l; mean, P^-1) prod_j (1 + l_j^2 / 4). A defensive
// share eps of the draws is uniform on the torus (Hesterberg 1995), so the weights stay bounded
// where the Gaussian's tails are thinner than the target's. Particles 2i and 2i + 1 are
// antithetic: the second takes -z (or the mirror image of the uniform draw), a draw of the same
// law, so each particle's weight is as if drawn alone while the pair's mean deviation cancels
// to first order (Hammersley and Morton 1956).
FLEXBENCH_PARTICLE_LOOP void ParticleFilter::LaplaceMove() {
  const int m = nq_;
  const double kv = config_.kappa_v;
  const double kw = config_.kappa_w;
  double* __restrict w = w_.data();
  for (int i = 0; i < n_; ++i) w[i] = std::exp(log_w_[i]);
  double wsum = 0.0;
  for (int i = 0; i < n_; ++i) wsum += w[i];
  // The conjugate centres: k e^{i mu} = kappa_v e^{i x_prev} + kappa_w e^{i u}, (c, s) := e^{i mu}.
  double kbar[kMaxPfJoints];
  for (int j = 0; j < m; ++j) {
    const double cu = kw * std::cos(kept_u_[j]);
    const double su = kw * std::sin(kept_u_[j]);
    const size_t off = static_cast<size_t>(j) * stride_;
    double* __restrict c = cos_.data() + off;
    double* __restrict s = sin_.data() + off;
    double* __restrict k = k_.data() + off;
    double ksum = 0.0;
    for (int i = 0; i < n_; ++i) {
      const double zc = kv * c[i] + cu;
      const double zs = kv * s[i] + su;
      const double ki = std::sqrt(zc * zc + zs * zs);
      const bool ok = ki > 1e-300;
      const double inv = ok ? 1.0 / ki : 0.0;
      k[i] = ok ? ki : 1e-300;
      c[i] = ok ? zc * inv : 1.0;
      s[i] = ok ? zs * inv : 0.0;
      ksum += w[i] * k[i];
    }
    kbar[j] = ksum / wsum;
  }
  // The linearisation point: the weighted circular mean of the centres.
  double cbar[kMaxPfJoints], sbar[kMaxPfJoints];
  for (int j = 0; j < m; ++j) {
    double sc = 0.0, ss = 0.0;
    WeightedResultant(cos_.data() + j * stride_, sin_.data() + j * stride_, w, n_, &sc, &ss);
    lin_q_[j] = std::atan2(ss, sc);
    cbar[j] = std::cos(lin_q_[j]);
    sbar[j] = std::sin(lin_q_[j]);
  }
  LinearisedReadings();
  // P = diag(kbar) + H = L L^T, once for the step.
  constexpr double kMinKappa = 1e-3;  // keeps the draws proper where nothing constrains a joint
  double L[kMaxPfJoints * kMaxPfJoints];
  for (int a = 0; a < m; ++a) {
    for (int b = 0; b <= a; ++b) L[a * m + b] = H_[a * m + b];
    L[a * m + a] += kbar[a];
  }
  for (int a = 0; a < m; ++a) {
    double d = L[a * m + a];
    for (int b = 0; b < a; ++b) d -= L[a * m + b] * L[a * m + b];
    d = std::sqrt(std::max(d, kMinKappa));
    L[a * m + a] = d;
    for (int r = a + 1; r < m; ++r) {
      double v = L[r * m + a];
      for (int b = 0; b < a; ++b) v -= L[r * m + b] * L[a * m + b];
      L[r * m + a] = v / d;
    }
  }
  // log N(l; mean, P^-1) = -|z|^2 / 2 + log_norm_gauss; the uniform share's log density.
  double log_norm_gauss = -0.5 * m * std::log(2.0 * M_PI);
  for (int j = 0; j < m; ++j) log_norm_gauss += std::log(L[j * m + j]);
  const double log_gauss_share = std::log1p(-kDefensiveShare);
  const double log_uniform = std::log(kDefensiveShare) - m * std::log(2.0 * M_PI);
  // Divisions hoisted out of the particle loop: 1 / L_jj.
  double inv_diag[kMaxPfJoints];
  for (int j = 0; j < m; ++j) inv_diag[j] = 1.0 / L[j * m + j];
  double mean[kMaxPfJoints], e[kMaxPfJoints], z[kMaxPfJoints], ell[kMaxPfJoints];
  bool uniform = false;
  for (int i = 0; i < n_; ++i) {
    const bool mirror = (i & 1) != 0;
    // rhs = k o l(mu) + g, then mean := P^-1 rhs (forward then backward substitution).
    for (int a = 0; a < m; ++a) {
      const size_t ia = static_cast<size_t>(a) * stride_ + i;
      const double delta = LinearAngle(cos_[ia] * cbar[a] + sin_[ia] * sbar[a],
                                       sin_[ia] * cbar[a] - cos_[ia] * sbar[a]);
      mean[a] = k_[ia] * delta + g_[a];
    }
    for (int a = 0; a < m; ++a) {
      double v = mean[a];
      for (int b = 0; b < a; ++b) v -= L[a * m + b] * mean[b];
      mean[a] = v * inv_diag[a];
    }
    for (int a = m - 1; a >= 0; --a) {
      double v = mean[a];
      for (int b = a + 1; b < m; ++b) v -= L[b * m + a] * mean[b];
      mean[a] = v * inv_diag[a];
    }
    if (!mirror) uniform = Uniform53(rng_) < kDefensiveShare;
    if (!uniform) {
      // L^T (l - mean) = z, last joint first.
      for (int j = m - 1; j >= 0; --j) {
        z[j] = mirror ? -z[j] : normal_(rng_);
        double v = z[j];
        for (int b = j + 1; b < m; ++b) v -= L[b * m + j] * e[b];
        e[j] = v * inv_diag[j];
        ell[j] = mean[j] + e[j];
      }
    } else {
      // Uniform angles (the mirror: their negatives about xbar), and their z for the density.
      for (int j = 0; j < m; ++j) {
        if (!mirror)
          ell[j] = 2.0 * std::tan(M_PI * (Uniform53(rng_) - 0.5));
        else
          ell[j] = -ell[j];
        e[j] = ell[j] - mean[j];
      }
      for (int j = 0; j < m; ++j) {
        double v = L[j * m + j] * e[j];
        for (int b = j + 1; b < m; ++b) v += L[b * m + j] * e[b];
        z[j] = v;
      }
    }
    double log_target = 0.0, zz = 0.0, jacobian = 1.0;
    for (int j = 0; j < m; ++j) {
      // x = xbar + 2 atan(l / 2): cos and sin of the offset are rational in h = l / 2.
      const double h = 0.5 * ell[j], h2 = h * h, inv = 1.0 / (1.0 + h2);
      const double cd = (1.0 - h2) * inv, sd = 2.0 * h * inv;
      const double cx = cbar[j] * cd - sbar[j] * sd, sx = sbar[j] * cd + cbar[j] * sd;
      const size_t ij = static_cast<size_t>(j) * stride_ + i;
      log_target += k_[ij] * (cx * cos_[ij] + sx * sin_[ij]);
      zz += z[j] * z[j];
      jacobian *= 1.0 + h2;  // dl/dx
      cos_[ij] = cx;
      sin_[ij] = sx;
    }
    const double log_gauss = log_gauss_share + log_norm_gauss - 0.5 * zz + std::log(jacobian);
    const double hi = std::max(log_gauss, log_uniform), lo = std::min(log_gauss, log_uniform);
    ll_[i] = log_target - (hi + std::log1p(std::exp(lo - hi)));
  }
  ComputeKinematics();
  // The target's normaliser: vM(kappa_v) vM(kappa_w) per joint, 1 / (2 pi)^2 I0 I0.
  ApplyLogLikelihood(m * (log_norm_conjugate_ - std::log(2.0 * M_PI)));
}

FLEXBENCH_PARTICLE_LOOP bool ParticleFilter::ApplyLogLikelihood(double constant) {
  double* __restrict lw = log_w_.data();
  double* __restrict ll = ll_.data();
  double m = kNegInf;
  for (int i = 0; i < n_; ++i) {
    double v = lw[i] + ll[i];
    if (std::isnan(v)) v = kNegInf;
    ll[i] = v;
    m = std::max(m, v);
  }
  if (!std::isfinite(m)) return false;
  for (int i = 0; i < n_; ++i) lw[i] = ll[i] - m;
  shift_ += m + constant;
  summary_valid_ = false;
  rb_valid_ = false;
  return true;
}

FLEXBENCH_PARTICLE_LOOP PfStatus ParticleFilter::UpdateReference(const double* u, int n) {
  if (n != nq_) {
    throw InputError("particle filter: joint reading has " + std::to_string(n) +
                     " angles, PPOE model '" + model_->name() + "' has " + std::to_string(nq_));
  }
  for (int j = 0; j < n; ++j) {
    if (!std::isfinite(u[j])) return PfStatus::kRejectedNonFinite;
  }
  if (awaiting_first_reading_) CentreOnReading(u);
  if (KeepReading(u, -1, nullptr, nullptr, nullptr)) return PfStatus::kAccepted;
  if (pending_move_ && config_.proposal == Proposal::kEncoderConjugate) {
    pending_move_ = false;
    ResampleIfNeeded();
    PropagateConjugate(u);
    ComputeKinematics();
    return ApplyLogLikelihood(nq_ * log_norm_conjugate_) ? PfStatus::kAccepted
                                                         : PfStatus::kRejectedAllZero;
  }
  EnsurePropagated();
  const double kw = config_.kappa_w;
  double* __restrict ll = ll_.data();
  for (int j = 0; j < nq_; ++j) {
    const double cu = kw * std::cos(u[j]);
    const double su = kw * std::sin(u[j]);
    const double* __restrict c = cos_.data() + static_cast<size_t>(j) * stride_;
    const double* __restrict s = sin_.data() + static_cast<size_t>(j) * stride_;
    if (j == 0) {
      for (int i = 0; i < n_; ++i) ll[i] = cu * c[i] + su * s[i];  // kappa_w cos(u - x)
    } else {
      for (int i = 0; i < n_; ++i) ll[i] += cu * c[i] + su * s[i];
    }
  }
  return ApplyLogLikelihood(nq_ * log_norm_reference_) ? PfStatus::kAccepted
                                                       : PfStatus::kRejectedAllZero;
}

FLEXBENCH_PARTICLE_LOOP PfStatus ParticleFilter::UpdatePosition(FrameId frame, const Vec3& p_frame,
                                                                const Vec3& p_base) {
  int k = -1;
  for (size_t a = 0; a < config_.position_frames.size(); ++a) {
    if (config_.position_frames[a] == frame) k = position_outputs_[a];
  }
  if (k < 0) return PfStatus::kIgnored;
  if (!p_frame.allFinite() || !p_base.allFinite()) return PfStatus::kRejectedNonFinite;
  if (KeepReading(nullptr, frame, &p_frame, &p_base, nullptr)) return PfStatus::kAccepted;
  EnsurePropagated();
  const double i00 = position_info_(0, 0), i11 = position_info_(1, 1), i22 = position_info_(2, 2);
  const double i01 = 2.0 * position_info_(0, 1), i02 = 2.0 * position_info_(0, 2),
               i12 = 2.0 * position_info_(1, 2);
  const double* __restrict R00 = fk_.R(k, 0, 0);
  const double* __restrict R01 = fk_.R(k, 0, 1);
  const double* __restrict R02 = fk_.R(k, 0, 2);
  const double* __restrict R10 = fk_.R(k, 1, 0);
  const double* __restrict R11 = fk_.R(k, 1, 1);
  const double* __restrict R12 = fk_.R(k, 1, 2);
  const double* __restrict R20 = fk_.R(k, 2, 0);
  const double* __restrict R21 = fk_.R(k, 2, 1);
  const double* __restrict R22 = fk_.R(k, 2, 2);
  const double* __restrict t0 = fk_.t(k, 0);
  const double* __restrict t1 = fk_.t(k, 1);
  const double* __restrict t2 = fk_.t(k, 2);
  double* __restrict ll = ll_.data();
  const double px = p_frame.x(), py = p_frame.y(), pz = p_frame.z();
  const double bx = p_base.x(), by = p_base.y(), bz = p_base.z();
  if (px == 0.0 && py == 0.0 && pz == 0.0) {  // the frame's origin: no rotation needed
    for (int i = 0; i < n_; ++i) {
      const double dx = bx - t0[i], dy = by - t1[i], dz = bz - t2[i];
      ll[i] = -0.5 *
              (dx * (i00 * dx + i01 * dy + i02 * dz) + dy * (i11 * dy + i12 * dz) + i22 * dz * dz);
    }
    return ApplyLogLikelihood(log_norm_position_) ? PfStatus::kAccepted
                                                  : PfStatus::kRejectedAllZero;
  }
  for (int i = 0; i < n_; ++i) {
    // d = p_base - (R p_frame + t); ll = -1/2 d^T R_w^-1 d.
    const double dx = bx - (R00[i] * px + R01[i] * py + R02[i] * pz + t0[i]);
    const double dy = by - (R10[i] * px + R11[i] * py + R12[i] * pz + t1[i]);
    const double dz = bz - (R20[i] * px + R21[i] * py + R22[i] * pz + t2[i]);
    ll[i] =
        -0.5 * (dx * (i00 * dx + i01 * dy + i02 * dz) + dy * (i11 * dy + i12 * dz) + i22 * dz * dz);
  }
  return ApplyLogLikelihood(log_norm_position_) ? PfStatus::kAccepted : PfStatus::kRejectedAllZero;
}

FLEXBENCH_PARTICLE_LOOP PfStatus ParticleFilter::UpdateOrientation(FrameId frame,
                                                                   const Quat& q_base_frame) {
  int k = -1;
  for (size_t a = 0; a < config_.orientation_frames.size(); ++a) {
    if (config_.orientation_frames[a] == frame) k = orientation_outputs_[a];
  }
  if (k < 0) return PfStatus::kIgnored;
  const Vec4 xyzw(q_base_frame.x(), q_base_frame.y(), q_base_frame.z(), q_base_frame.w());
  if (!xyzw.allFinite()) return PfStatus::kRejectedNonFinite;
  if (std::abs(xyzw.norm() - 1.0) > kUnitQuaternionTol) return PfStatus::kRejectedOutside;
  if (KeepReading(nullptr, frame, nullptr, nullptr, &q_base_frame)) return PfStatus::kAccepted;
  EnsurePropagated();
  const BinghamRotationForm form = bingham_.RotationForm(q_base_frame);
  const double c0 = form.c0;
  const double C00 = form.C(0, 0), C01 = form.C(0, 1), C02 = form.C(0, 2);
  const double C10 = form.C(1, 0), C11 = form.C(1, 1), C12 = form.C(1, 2);
  const double C20 = form.C(2, 0), C21 = form.C(2, 1), C22 = form.C(2, 2);
  const double* __restrict R00 = fk_.R(k, 0, 0);
  const double* __restrict R01 = fk_.R(k, 0, 1);
  const double* __restrict R02 = fk_.R(k, 0, 2);
  const double* __restrict R10 = fk_.R(k, 1, 0);
  const double* __restrict R11 = fk_.R(k, 1, 1);
  const double* __restrict R12 = fk_.R(k, 1, 2);
  const double* __restrict R20 = fk_.R(k, 2, 0);
  const double* __restrict R21 = fk_.R(k, 2, 1);
  const double* __restrict R22 = fk_.R(k, 2, 2);
  double* __restrict ll = ll_.data();
  for (int i = 0; i < n_; ++i) {
    ll[i] = c0 + C00 * R00[i] + C01 * R01[i] + C02 * R02[i] + C10 * R10[i] + C11 * R11[i] +
            C12 * R12[i] + C20 * R20[i] + C21 * R21[i] + C22 * R22[i];
  }
  return ApplyLogLikelihood(-bingham_.LogNormaliser()) ? PfStatus::kAccepted
                                                       : PfStatus::kRejectedAllZero;
}

double ParticleFilter::LogSumExpWeights() const {
  double sum = 0.0;
  for (int i = 0; i < n_; ++i) sum += std::exp(log_w_[i]);
  return std::log(sum);
}

double ParticleFilter::StepLogLikelihood() const {
  return shift_ + LogSumExpWeights() - log_norm_at_step_start_;
}

double ParticleFilter::EffectiveSampleSize() const {
  double sum = 0.0;
  double sum2 = 0.0;
  for (int i = 0; i < n_; ++i) {
    const double w = std::exp(log_w_[i]);
    sum += w;
    sum2 += w * w;
  }
  return sum * sum / sum2;
}

double ParticleFilter::Angle(int j, int i) const {
  const size_t idx = static_cast<size_t>(j) * stride_ + i;
  return std::atan2(sin_[idx], cos_[idx]);
}

double ParticleFilter::Weight(int i) const { return std::exp(log_w_[i] - LogSumExpWeights()); }

const ParticleSummary& ParticleFilter::Summary() const {
  if (summary_valid_) return summary_;
  ParticleSummary& out = summary_;
  out.nq = nq_;
  out.ess = NormalisedWeights(log_w_.data(), n_, scratch_w_.data());
  const double* w = scratch_w_.data();
  // Particles below this normalised weight do not move a quantile or a covariance.
  const double negligible = 1e-14;
  kept_.Select(w, n_, negligible);
  for (int j = 0; j < nq_; ++j) {
    const double* c = cos_.data() + static_cast<size_t>(j) * stride_;
    const double* s = sin_.data() + static_cast<size_t>(j) * stride_;
    double sc = 0.0, ss = 0.0;
    if (rb_valid_) {
      WeightedResultant(rb_->moment_c(j), rb_->moment_s(j), w, n_, &sc, &ss);
    } else {
      WeightedResultant(c, s, w, n_, &sc, &ss);
    }
    const double mean = std::atan2(ss, sc);
    const double r = std::min(1.0, std::hypot(sc, ss));
    out.mean[j] = mean >= M_PI ? -M_PI : mean;
    out.circular_std[j] =
        r > 0.0 ? std::sqrt(-2.0 * std::log(r)) : std::numeric_limits<double>::infinity();
    // Weighted 2.5% / 97.5% quantiles of the deviation from the mean (no full sort), looked
    // for first between 1.6 and 2.5 circular standard deviations (1.96 for a wrapped normal).
    const double cm = sc / std::max(r, 1e-300), sm = ss / std::max(r, 1e-300);
    static constexpr double kProbs[2] = {0.025, 0.975};
    const double sigma = out.circular_std[j];
    double dev[2];
    kept_.Gather(c, s, kept_c_.data(), kept_s_.data());
    WeightedCircularTailQuantiles(kept_c_.data(), kept_s_.data(), kept_.weight(), kept_.size(), cm,
                                  sm, negligible, kTailInner * sigma, kTailOuter * sigma, kProbs, 2,
                                  dev, &quantiles_);
    out.lower95[j] = out.mean[j] + dev[0];
    out.upper95[j] = out.mean[j] + dev[1];
  }
  out.has_end_effector = ee_output_ >= 0;
  if (out.has_end_effector) {
    // The pose at the estimated effective angles (the paper's sec. IV-C: the gripper position
    // "from estimated effective joint angles"), not the centroid of the particles' poses,
    // which a broad angular posterior pulls towards the base.
    const int k = ee_output_;
    for (int j = 0; j < nq_; ++j) q_mean_[j] = out.mean[j];
    kinematics::ForwardKinematics(*model_, fk_data_, q_mean_);
    const lie::SE3 mean = fk_data_.T_base_frame[config_.end_effector];
    // The particles' spread about it, in its local tangent space.
    PoseSpread(fk_, k, mean, kept_, &out.cov_ee);
    out.T_base_ee = mean;
  }
  summary_valid_ = true;
  return out;
}

}  // namespace flexbench::pf
