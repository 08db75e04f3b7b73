#include "estimators/pf/pf_estimator.h"

#include <cmath>
#include <sstream>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"

namespace flexbench::estimators {
namespace {

const Vec4 kAxisym(-800.0, -800.0, 0.0, 0.0);
const Vec4 kUnimodal(-800.0, -800.0, -800.0, 0.0);

bool Flag(const Params& p, const std::string& key, bool fallback, const std::string& name) {
  const double v = p.Scalar(key, fallback ? 1.0 : 0.0);
  if (v != 0.0 && v != 1.0) {
    std::ostringstream msg;
    msg << name << ": parameter '" << key << "' must be 0 or 1, got " << v;
    throw InputError(msg.str());
  }
  return v == 1.0;
}

int Integer(double v, const std::string& key, const std::string& name) {
  if (!std::isfinite(v) || v != std::floor(v) || std::abs(v) > 1e9) {
    std::ostringstream msg;
    msg << name << ": parameter '" << key << "' must be an integer, got " << v;
    throw InputError(msg.str());
  }
  return static_cast<int>(v);
}

UpdateStatus ToUpdateStatus(pf::PfStatus s) {
  switch (s) {
    case pf::PfStatus::kAccepted:
      return UpdateStatus::kAccepted;
    case pf::PfStatus::kIgnored:
      return UpdateStatus::kIgnored;
    case pf::PfStatus::kRejectedNonFinite:
      return UpdateStatus::kRejectedNonFinite;
    case pf::PfStatus::kRejectedOutside:
      return UpdateStatus::kRejectedOutside;
    case pf::PfStatus::kRejectedAllZero:
      return UpdateStatus::kRejectedGating;
  }
  return UpdateStatus::kIgnored;
}

}  // namespace

pf::ParticleFilterConfig MakePfConfig(const EstimatorSetup& setup,
                                      const PfEstimator::Variant& variant) {
  const std::string name = variant.name;
  if (!setup.model) throw InputError(name + ": no declared model");
  const Params& p = setup.params;
  pf::ParticleFilterConfig c;
  c.num_particles = Integer(p.Scalar("particles", 2048.0), "particles", name);
  c.kappa_w = p.Scalar("kappa_w", 15.0);
  c.kappa_v = p.Scalar("kappa_v", 5.0);
  c.kappa_0 = p.Scalar("kappa_0", 0.1);
  const std::vector<double> lambda =
      p.List("bingham_lambda",
             {variant.lambda(0), variant.lambda(1), variant.lambda(2), variant.lambda(3)});
  c.bingham_lambda = Vec4(lambda[0], lambda[1], lambda[2], lambda[3]);
  const std::vector<double> var =
      p.Has("ee_variance") ? p.List("ee_variance", 0) : std::vector<double>{0.01};
  if (var.size() == 1) {
    c.position_cov = var[0] * Mat3::Identity();
  } else if (var.size() == 3) {
    c.position_cov = Vec3(var[0], var[1], var[2]).asDiagonal();
  } else {
    throw InputError(name + ": parameter 'ee_variance' needs 1 or 3 values, got " +
                     std::to_string(var.size()));
  }
  for (double v : var) {
    if (!(v > 0.0) || !std::isfinite(v)) {
      std::ostringstream msg;
      msg << name << ": parameter 'ee_variance' must be finite and > 0, got " << v;
      throw InputError(msg.str());
    }
  }
  c.ess_threshold = p.Scalar("ess_threshold", 0.5);
  c.resampling = Flag(p, "systematic_resampling", false, name) ? pf::ResamplingScheme::kSystematic
                                                               : pf::ResamplingScheme::kStratified;
  const bool conjugate = Flag(p, "conjugate_proposal", false, name);
  const bool laplace = Flag(p, "laplace_proposal", false, name);
  if (conjugate && laplace) {
    throw InputError(name + ": 'conjugate_proposal' and 'laplace_proposal' exclude each other");
  }
  c.proposal = laplace     ? pf::Proposal::kLaplace
               : conjugate ? pf::Proposal::kEncoderConjugate
                           : pf::Proposal::kBootstrap;
  c.rao_blackwell = Flag(p, "rao_blackwell", true, name);
  c.initial_at_first_reading = Flag(p, "initial_at_first_reading", false, name);
  c.end_effector = setup.end_effector;
  if (Flag(p, "ee_position", variant.ee_position, name)) {
    if (setup.end_effector < 0) throw InputError(name + ": the setup has no end-effector frame");
    c.position_frames.push_back(setup.end_effector);
  }
  std::vector<double> imus;
  if (variant.imus) {
    for (size_t k = 0; k < setup.imus.size(); ++k) imus.push_back(static_cast<double>(k));
  }
  if (p.Has("imus")) imus = p.List("imus", 0);  // any length, unlike the fallback form
  for (double v : imus) {
    const int k = Integer(v, "imus", name);
    if (k < 0 || k >= static_cast<int>(setup.imus.size())) {
      throw InputError(name + ": parameter 'imus' names IMU " + std::to_string(k) +
                       ", the setup has " + std::to_string(setup.imus.size()));
    }
    c.orientation_frames.push_back(setup.imus[k].frame);
  }
  if (variant.imus && c.orientation_frames.empty()) {
    throw InputError(name + ": needs at least one IMU in the setup");
  }
  pf::ValidateConfig(c, *setup.model, name);
  return c;
}

PfEstimator::PfEstimator(const EstimatorSetup& setup, const Variant& variant)
    : name_(variant.name) {
  const pf::ParticleFilterConfig config = MakePfConfig(setup, variant);
  setup.params.CheckAllUsed(name_);
  kin_ = std::make_unique<kinematics::EffectiveChain>(*setup.model, setup.effects);
  filter_ = std::make_unique<pf::ParticleFilter>(kin_->model(), config, setup.seed);
  if (!config.orientation_frames.empty()) {
    imu_ = std::make_unique<imu::ImuOrientations>(setup.imus);
    // The IMUs whose orientations enter, by index (two IMUs may share a frame): the `imus`
    // parameter's (MakePfConfig checked them), else every one.
    imu_used_.assign(setup.imus.size(), setup.params.Has("imus") ? 0 : 1);
    if (setup.params.Has("imus")) {
      for (double k : setup.params.List("imus", 0)) imu_used_[static_cast<size_t>(k)] = 1;
    }
  }
  if (setup.effects != nullptr && !setup.effects->uncertainty.empty() && setup.end_effector >= 0) {
    bare_ = std::make_unique<kinematics::PpoeModel>(*setup.model);
    for (FrameId f = 1; f < bare_->num_frames(); ++f) bare_->SetSourceCovariance(f, Mat6::Zero());
    param_kin_ = std::make_unique<kinematics::EffectiveChain>(*bare_, setup.effects);
    param_data_ = std::make_unique<kinematics::PpoeData>(*bare_);
  }
}

UpdateStatus PfEstimator::UpdateJoints(const JointReading& j) {
  const int n = static_cast<int>(j.q.size());
  if (!kin_->active() || n != kin_->declared().nq() || !j.q.allFinite()) {
    return ToUpdateStatus(filter_->UpdateReference(j.q.data(), n));  // it checks them
  }
  kin_->Update(j.q);
  if (kin_->varies()) filter_->SetModel(kin_->model());
  if (param_kin_) ParameterCovariance(j.q);
  return ToUpdateStatus(filter_->UpdateReference(kin_->q().data(), n));
}

// The identified parameters' covariance at the end effector, at reading q (no allocation).
void PfEstimator::ParameterCovariance(const Eigen::VectorXd& q) {
  param_kin_->Update(q);
  kinematics::ForwardKinematicsWithCovariance(param_kin_->model(), *param_data_, param_kin_->q(),
                                              lie::CompoundOrder::kSecond);
  param_cov_ = param_data_->Sigma_frame[filter_->config().end_effector];
}

void PfEstimator::Reset() {
  filter_->Reset();
  param_cov_.setZero();
  has_t_ = false;
  t_ = 0.0;
  if (imu_) imu_->Reset();
  joints_in_step_ = false;
}

void PfEstimator::Predict(double t) {
  if (has_t_ && !(t > t_)) return;
  if (has_t_ && !joints_in_step_) ApplyImuTerms();
  joints_in_step_ = false;
  filter_->Predict();
  has_t_ = true;
  t_ = t;
}

void PfEstimator::ApplyImuTerms() {
  if (!imu_) return;
  for (int k = 0; k < imu_->size(); ++k) {
    if (!imu_used_[k] || !imu_->ready(k) || !imu_->fresh(k)) continue;
    const OrientationReading o = imu_->Take(k);
    const UpdateStatus s = ToUpdateStatus(filter_->UpdateOrientation(o.frame, o.q_base_frame));
    if (s != UpdateStatus::kAccepted && s != UpdateStatus::kIgnored) ++imu_terms_rejected_;
  }
}

UpdateStatus PfEstimator::Update(const Measurement& z) {
  if (const auto* j = std::get_if<JointReading>(&z)) {
    const UpdateStatus s = UpdateJoints(*j);
    joints_in_step_ = true;
    ApplyImuTerms();
    return s;
  }
  if (const auto* r = std::get_if<ImuReading>(&z)) {
    if (!imu_) return UpdateStatus::kIgnored;
    const UpdateStatus s = imu_->Feed(*r);
    return s == UpdateStatus::kAccepted && !imu_used_[r->imu] ? UpdateStatus::kIgnored : s;
  }
  if (const auto* o = std::get_if<OrientationReading>(&z)) {
    return ToUpdateStatus(filter_->UpdateOrientation(o->frame, o->q_base_frame));
  }
  if (const auto* p = std::get_if<PositionReading>(&z)) {
    return ToUpdateStatus(filter_->UpdatePosition(p->frame, p->p_frame, p->p_base));
  }
  return UpdateStatus::kIgnored;
}

Belief PfEstimator::Estimate() const {
  filter_->CompleteStep();  // the step's readings are all in: the Laplace move may run
  const pf::ParticleSummary& s = filter_->Summary();
  Belief b;
  b.t = t_;
  if (s.has_end_effector) {
    b.T_base_ee = s.T_base_ee;
    b.cov = s.cov_ee + param_cov_;
  }
  b.has_joints = true;
  b.q.resize(s.nq);
  b.q_std.resize(s.nq);
  for (int j = 0; j < s.nq; ++j) {
    b.q[j] = s.mean[j];
    b.q_std[j] = s.circular_std[j];
  }
  return b;
}

std::unique_ptr<Estimator> MakePfEncoders(const EstimatorSetup& setup) {
  return std::make_unique<PfEstimator>(setup,
                                       PfEstimator::Variant{"pf_encoders", false, false, kAxisym});
}
std::unique_ptr<Estimator> MakePfEncodersEe(const EstimatorSetup& setup) {
  return std::make_unique<PfEstimator>(
      setup, PfEstimator::Variant{"pf_encoders_ee", true, false, kAxisym});
}
std::unique_ptr<Estimator> MakePfEncodersImu(const EstimatorSetup& setup) {
  return std::make_unique<PfEstimator>(
      setup, PfEstimator::Variant{"pf_encoders_imu", false, true, kAxisym});
}
std::unique_ptr<Estimator> MakePfAll(const EstimatorSetup& setup) {
  return std::make_unique<PfEstimator>(setup, PfEstimator::Variant{"pf_all", true, true, kAxisym});
}
std::unique_ptr<Estimator> MakePfBinghamUnimodal(const EstimatorSetup& setup) {
  return std::make_unique<PfEstimator>(
      setup, PfEstimator::Variant{"pf_bingham_unimodal", false, true, kUnimodal});
}
std::unique_ptr<Estimator> MakePfBinghamAxisym(const EstimatorSetup& setup) {
  return std::make_unique<PfEstimator>(
      setup, PfEstimator::Variant{"pf_bingham_axisym", false, true, kAxisym});
}

}  // namespace flexbench::estimators
