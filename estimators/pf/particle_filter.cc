#include "estimators/pf/particle_filter.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "estimators/error.h"
#include "estimators/lie/so3.h"
#include "estimators/pf/bessel.h"

namespace flexbench::pf {
namespace {

constexpr double kNegInf = -std::numeric_limits<double>::infinity();

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

// Keeps |(c, s)| = 1 after a product of unit vectors: one Newton step of 1/sqrt at 1.
inline void Renormalise(double& c, double& s) {
  const double k = 0.5 * (3.0 - (c * c + s * s));
  c *= k;
  s *= k;
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
std::vector<FrameId> KinematicOutputs(const ParticleFilterConfig& c) {
  std::vector<FrameId> out;
  const auto add = [&](FrameId f) {
    if (f >= 0 && std::find(out.begin(), out.end(), f) == out.end()) out.push_back(f);
  };
  for (FrameId f : c.position_frames) add(f);
  for (FrameId f : c.orientation_frames) add(f);
  add(c.end_effector);
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
    : model_(model),
      config_(Validated(config, model)),
      seed_(seed),
      n_(config.num_particles),
      nq_(model.nq()),
      rng_(seed),
      system_noise_(config.kappa_v),
      initial_(config.kappa_0),
      bingham_(config.bingham_lambda, config.bingham_M),
      fk_(model, KinematicOutputs(config), config.num_particles) {
  position_info_ = config_.position_cov.inverse();
  log_norm_position_ = -0.5 * std::log((2.0 * M_PI * config_.position_cov).determinant());
  log_norm_reference_ = -(std::log(2.0 * M_PI) + LogBesselI0(config_.kappa_w));
  log_norm_conjugate_ =
      -(std::log(2.0 * M_PI) + LogBesselI0(config_.kappa_v) + LogBesselI0(config_.kappa_w));
  const size_t total = static_cast<size_t>(nq_) * n_;
  cos_.assign(total, 1.0);
  sin_.assign(total, 0.0);
  cos2_.assign(total, 1.0);
  sin2_.assign(total, 0.0);
  log_w_.assign(n_, 0.0);
  ll_.assign(n_, 0.0);
  w_.assign(n_, 0.0);
  ancestors_.assign(n_, 0);
  for (FrameId f : config_.position_frames) position_outputs_.push_back(fk_.OutputIndex(f));
  for (FrameId f : config_.orientation_frames) orientation_outputs_.push_back(fk_.OutputIndex(f));
  ee_output_ = config_.end_effector >= 0 ? fk_.OutputIndex(config_.end_effector) : -1;
  scratch_pairs_.reserve(n_);
  scratch_w_.assign(n_, 0.0);
  Reset();
}

void ParticleFilter::Reset() {
  rng_.seed(seed_);
  // Eq. 29: every joint of every particle from vM(kappa_0, 0), joint by joint.
  for (int j = 0; j < nq_; ++j) {
    double* c = cos_.data() + static_cast<size_t>(j) * n_;
    double* s = sin_.data() + static_cast<size_t>(j) * n_;
    for (int i = 0; i < n_; ++i) {
      const UnitAngle a = initial_.SampleUnit(rng_);
      c[i] = a.c;
      s[i] = a.s;
    }
  }
  std::fill(log_w_.begin(), log_w_.end(), 0.0);
  pending_move_ = false;
  log_norm_at_step_start_ = std::log(static_cast<double>(n_));
  shift_ = 0.0;
  last_ess_ = n_;
  last_resampled_ = false;
  resample_count_ = 0;
  ComputeKinematics();
}

void ParticleFilter::ComputeKinematics() {
  if (fk_.num_outputs() > 0) fk_.Compute(cos_.data(), sin_.data(), n_, n_);
  summary_valid_ = false;
}

void ParticleFilter::ResampleIfNeeded() {
  double sum = 0.0;
  double sum2 = 0.0;
  for (int i = 0; i < n_; ++i) {
    const double w = std::exp(log_w_[i]);
    w_[i] = w;
    sum += w;
    sum2 += w * w;
  }
  last_ess_ = sum * sum / sum2;
  log_norm_at_step_start_ = std::log(sum);
  shift_ = 0.0;
  last_resampled_ = last_ess_ < config_.ess_threshold * n_;
  if (!last_resampled_) return;
  Resample(config_.resampling, w_.data(), n_, rng_, ancestors_.data());
  for (int j = 0; j < nq_; ++j) {
    const size_t off = static_cast<size_t>(j) * n_;
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
  std::fill(log_w_.begin(), log_w_.end(), 0.0);
  log_norm_at_step_start_ = std::log(static_cast<double>(n_));
  ++resample_count_;
}

void ParticleFilter::PropagateBootstrap() {
  for (int j = 0; j < nq_; ++j) {
    double* __restrict c = cos_.data() + static_cast<size_t>(j) * n_;
    double* __restrict s = sin_.data() + static_cast<size_t>(j) * n_;
    for (int i = 0; i < n_; ++i) {
      const UnitAngle v = system_noise_.SampleUnit(rng_);
      double cn = c[i] * v.c - s[i] * v.s;
      double sn = s[i] * v.c + c[i] * v.s;
      Renormalise(cn, sn);
      c[i] = cn;
      s[i] = sn;
    }
  }
}

void ParticleFilter::PropagateConjugate(const double* u) {
  std::fill(ll_.begin(), ll_.end(), 0.0);
  const double kv = config_.kappa_v;
  const double kw = config_.kappa_w;
  for (int j = 0; j < nq_; ++j) {
    const double cu = kw * std::cos(u[j]);
    const double su = kw * std::sin(u[j]);
    double* __restrict c = cos_.data() + static_cast<size_t>(j) * n_;
    double* __restrict s = sin_.data() + static_cast<size_t>(j) * n_;
    for (int i = 0; i < n_; ++i) {
      const double zc = kv * c[i] + cu;
      const double zs = kv * s[i] + su;
      double k = std::sqrt(zc * zc + zs * zs);
      double mc = 1.0, ms = 0.0;
      if (k > 1e-300) {
        mc = zc / k;
        ms = zs / k;
      } else {
        k = 1e-300;  // kappa_v = kappa_w and opposite directions: uniform
      }
      const VonMisesSampler sampler(k);
      const UnitAngle v = sampler.SampleUnit(rng_);
      double cn = mc * v.c - ms * v.s;
      double sn = ms * v.c + mc * v.s;
      Renormalise(cn, sn);
      c[i] = cn;
      s[i] = sn;
      ll_[i] += LogBesselI0(k);
    }
  }
}

void ParticleFilter::Predict() {
  if (config_.proposal == Proposal::kEncoderConjugate) {
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

bool ParticleFilter::ApplyLogLikelihood(double constant) {
  double m = kNegInf;
  for (int i = 0; i < n_; ++i) {
    double v = log_w_[i] + ll_[i];
    if (std::isnan(v)) v = kNegInf;
    ll_[i] = v;
    m = std::max(m, v);
  }
  if (!std::isfinite(m)) return false;
  for (int i = 0; i < n_; ++i) log_w_[i] = ll_[i] - m;
  shift_ += m + constant;
  summary_valid_ = false;
  return true;
}

PfStatus ParticleFilter::UpdateReference(const double* u, int n) {
  if (n != nq_) {
    throw InputError("particle filter: joint reading has " + std::to_string(n) +
                     " angles, PPOE model '" + model_.name() + "' has " + std::to_string(nq_));
  }
  for (int j = 0; j < n; ++j) {
    if (!std::isfinite(u[j])) return PfStatus::kRejectedNonFinite;
  }
  if (pending_move_ && config_.proposal == Proposal::kEncoderConjugate) {
    pending_move_ = false;
    ResampleIfNeeded();
    PropagateConjugate(u);
    ComputeKinematics();
    return ApplyLogLikelihood(nq_ * log_norm_conjugate_) ? PfStatus::kAccepted
                                                         : PfStatus::kRejectedAllZero;
  }
  EnsurePropagated();
  std::fill(ll_.begin(), ll_.end(), 0.0);
  const double kw = config_.kappa_w;
  for (int j = 0; j < nq_; ++j) {
    const double cu = kw * std::cos(u[j]);
    const double su = kw * std::sin(u[j]);
    const double* __restrict c = cos_.data() + static_cast<size_t>(j) * n_;
    const double* __restrict s = sin_.data() + static_cast<size_t>(j) * n_;
    for (int i = 0; i < n_; ++i) ll_[i] += cu * c[i] + su * s[i];  // kappa_w cos(u - x)
  }
  return ApplyLogLikelihood(nq_ * log_norm_reference_) ? PfStatus::kAccepted
                                                       : PfStatus::kRejectedAllZero;
}

PfStatus ParticleFilter::UpdatePosition(FrameId frame, const Vec3& p_frame, const Vec3& p_base) {
  int k = -1;
  for (size_t a = 0; a < config_.position_frames.size(); ++a) {
    if (config_.position_frames[a] == frame) k = position_outputs_[a];
  }
  if (k < 0) return PfStatus::kIgnored;
  if (!p_frame.allFinite() || !p_base.allFinite()) return PfStatus::kRejectedNonFinite;
  EnsurePropagated();
  const Mat3& I = position_info_;
  const double *R[3][3], *t[3];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R[r][c] = fk_.R(k, r, c);
    t[r] = fk_.t(k, r);
  }
  const double px = p_frame.x(), py = p_frame.y(), pz = p_frame.z();
  for (int i = 0; i < n_; ++i) {
    // d = p_base - (R p_frame + t)
    const double dx = p_base.x() - (R[0][0][i] * px + R[0][1][i] * py + R[0][2][i] * pz + t[0][i]);
    const double dy = p_base.y() - (R[1][0][i] * px + R[1][1][i] * py + R[1][2][i] * pz + t[1][i]);
    const double dz = p_base.z() - (R[2][0][i] * px + R[2][1][i] * py + R[2][2][i] * pz + t[2][i]);
    const double q = dx * (I(0, 0) * dx + 2.0 * I(0, 1) * dy + 2.0 * I(0, 2) * dz) +
                     dy * (I(1, 1) * dy + 2.0 * I(1, 2) * dz) + dz * I(2, 2) * dz;
    ll_[i] = -0.5 * q;
  }
  return ApplyLogLikelihood(log_norm_position_) ? PfStatus::kAccepted : PfStatus::kRejectedAllZero;
}

PfStatus ParticleFilter::UpdateOrientation(FrameId frame, const Quat& q_base_frame) {
  int k = -1;
  for (size_t a = 0; a < config_.orientation_frames.size(); ++a) {
    if (config_.orientation_frames[a] == frame) k = orientation_outputs_[a];
  }
  if (k < 0) return PfStatus::kIgnored;
  const Vec4 xyzw(q_base_frame.x(), q_base_frame.y(), q_base_frame.z(), q_base_frame.w());
  if (!xyzw.allFinite()) return PfStatus::kRejectedNonFinite;
  if (std::abs(xyzw.norm() - 1.0) > kUnitQuaternionTol) return PfStatus::kRejectedOutside;
  EnsurePropagated();
  const BinghamRotationForm form = bingham_.RotationForm(q_base_frame);
  const double* R[9];
  double C[9];
  for (int e = 0; e < 9; ++e) {
    R[e] = fk_.R(k, e / 3, e % 3);
    C[e] = form.C(e / 3, e % 3);
  }
  for (int i = 0; i < n_; ++i) {
    ll_[i] = form.c0 + C[0] * R[0][i] + C[1] * R[1][i] + C[2] * R[2][i] + C[3] * R[3][i] +
             C[4] * R[4][i] + C[5] * R[5][i] + C[6] * R[6][i] + C[7] * R[7][i] + C[8] * R[8][i];
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
  const size_t idx = static_cast<size_t>(j) * n_ + i;
  return std::atan2(sin_[idx], cos_[idx]);
}

double ParticleFilter::Weight(int i) const { return std::exp(log_w_[i] - LogSumExpWeights()); }

const ParticleSummary& ParticleFilter::Summary() const {
  if (summary_valid_) return summary_;
  ParticleSummary& out = summary_;
  out.nq = nq_;
  double sum = 0.0;
  double sum2 = 0.0;
  for (int i = 0; i < n_; ++i) {
    const double w = std::exp(log_w_[i]);
    scratch_w_[i] = w;
    sum += w;
    sum2 += w * w;
  }
  out.ess = sum * sum / sum2;
  const double inv = 1.0 / sum;
  for (int i = 0; i < n_; ++i) scratch_w_[i] *= inv;
  const double* w = scratch_w_.data();
  // Particles below this normalised weight do not move a quantile or a covariance.
  const double negligible = 1e-14;
  for (int j = 0; j < nq_; ++j) {
    const double* c = cos_.data() + static_cast<size_t>(j) * n_;
    const double* s = sin_.data() + static_cast<size_t>(j) * n_;
    double sc = 0.0, ss = 0.0;
    for (int i = 0; i < n_; ++i) {
      sc += w[i] * c[i];
      ss += w[i] * s[i];
    }
    const double mean = std::atan2(ss, sc);
    const double r = std::min(1.0, std::hypot(sc, ss));
    out.mean[j] = mean >= M_PI ? -M_PI : mean;
    out.circular_std[j] =
        r > 0.0 ? std::sqrt(-2.0 * std::log(r)) : std::numeric_limits<double>::infinity();
    // Weighted 2.5% / 97.5% quantiles of the deviation from the mean.
    const double cm = sc / std::max(r, 1e-300), sm = ss / std::max(r, 1e-300);
    scratch_pairs_.clear();
    double kept = 0.0;
    for (int i = 0; i < n_; ++i) {
      if (w[i] < negligible) continue;
      const double d = std::atan2(s[i] * cm - c[i] * sm, c[i] * cm + s[i] * sm);
      scratch_pairs_.emplace_back(d, w[i]);
      kept += w[i];
    }
    std::sort(scratch_pairs_.begin(), scratch_pairs_.end());
    // Each sample's mass sits at the middle of its step of the cumulative distribution.
    const auto quantile = [&](double p) {
      const double target = p * kept;
      double cum = 0.0;
      double prev_mid = -1.0, prev_d = scratch_pairs_.front().first;
      for (const auto& [d, wi] : scratch_pairs_) {
        const double mid = cum + 0.5 * wi;
        if (mid >= target) {
          if (prev_mid < 0.0) return d;
          return prev_d + (d - prev_d) * (target - prev_mid) / (mid - prev_mid);
        }
        cum += wi;
        prev_mid = mid;
        prev_d = d;
      }
      return scratch_pairs_.back().first;
    };
    out.lower95[j] = out.mean[j] + quantile(0.025);
    out.upper95[j] = out.mean[j] + quantile(0.975);
  }
  out.has_end_effector = ee_output_ >= 0;
  if (out.has_end_effector) {
    const int k = ee_output_;
    Vec3 t = Vec3::Zero();
    Mat3 Rsum = Mat3::Zero();
    for (int i = 0; i < n_; ++i) {
      if (w[i] < negligible) continue;
      for (int a = 0; a < 3; ++a) {
        t(a) += w[i] * fk_.t(k, a)[i];
        for (int b = 0; b < 3; ++b) Rsum(a, b) += w[i] * fk_.R(k, a, b)[i];
      }
    }
    const lie::SE3 mean(lie::SO3Project(Rsum), t);
    const lie::SE3 mean_inv = mean.Inverse();
    Mat6 cov = Mat6::Zero();
    for (int i = 0; i < n_; ++i) {
      if (w[i] < negligible) continue;
      const Vec6 xi = (mean_inv * fk_.Pose(k, i)).Log();
      cov.noalias() += w[i] * xi * xi.transpose();
    }
    out.T_base_ee = mean;
    out.cov_ee = cov;
  }
  summary_valid_ = true;
  return out;
}

}  // namespace flexbench::pf
