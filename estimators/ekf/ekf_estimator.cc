#include "estimators/ekf/ekf_estimator.h"

#include <cmath>

#include "estimators/ekf/lg_ekf.h"
#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"

namespace flexbench::estimators {
namespace {

enum class PriorKind { kPpoe, kNaive };

class EkfEstimator : public Estimator {
 public:
  EkfEstimator(const EstimatorSetup& setup, PriorKind kind, const char* name)
      : kin_(*setup.model, setup.effects),
        data_(*setup.model),
        ee_(setup.end_effector),
        ref_(setup.reference_frame),
        cameras_(setup.cameras),
        kind_(kind),
        name_(name) {
    const Params& p = setup.params;
    if (kind == PriorKind::kPpoe) {
      const double order = p.Scalar("covariance_order", 2.0);
      if (order != 2.0 && order != 4.0)
        throw InputError(name_ + ": covariance_order must be 2 or 4");
      order_ = order == 4.0 ? lie::CompoundOrder::kFourth : lie::CompoundOrder::kSecond;
    } else if (p.Scalar("ppoe_diagonal", 0.0) != 0.0) {
      // The paper's sec. V-B baseline: the PPOE covariance with its correlations dropped.
      ppoe_diagonal_ = true;
    } else {
      const std::vector<double> t = p.List("std_trans_m", 3);
      const std::vector<double> r = p.List("std_rot_deg", 3);
      naive_cov_.setZero();
      for (int i = 0; i < 3; ++i) {
        if (!(t[i] > 0.0) || !(r[i] > 0.0)) {
          throw InputError(name_ + ": std_trans_m and std_rot_deg must be > 0");
        }
        naive_cov_(i, i) = t[i] * t[i];
        naive_cov_(3 + i, 3 + i) = std::pow(r[i] * M_PI / 180.0, 2);
      }
    }
    if (ref_ < 0 || ref_ >= setup.model->num_frames()) {
      throw InputError(name_ + ": reference frame " + std::to_string(ref_) + " not in the model");
    }
    if (ref_ != kinematics::kBaseFrame && order_ == lie::CompoundOrder::kFourth) {
      throw InputError(name_ + ": covariance_order 4 is not available in a reference frame");
    }
    if (kind == PriorKind::kPpoe) reading_noise_ = ReadingNoiseFlag(p, name_, ref_);
    options_.max_iterations = static_cast<int>(p.Scalar("max_iterations", 10));
    options_.numeric_jacobians = p.Scalar("numeric_jacobians", 0.0) != 0.0;
    options_.gate_nis = p.Scalar("gate_nis", 0.0);
    if (options_.max_iterations < 1) throw InputError(name_ + ": max_iterations must be >= 1");
    p.CheckAllUsed(name_);
    Reset();
  }

  void Reset() override {
    belief_ = Belief{};
    have_prior_ = false;
  }

  void Predict(double t) override { belief_.t = std::max(belief_.t, t); }

  UpdateStatus Update(const Measurement& z) override {
    if (const auto* j = std::get_if<JointReading>(&z)) return SetPrior(*j);
    if (!have_prior_) return UpdateStatus::kIgnored;
    return std::visit([this](const auto& m) { return Correct(m); }, z);
  }

  Belief Estimate() const override { return belief_; }

  int covariance_repairs() const override { return prior_repairs_; }
  bool HasConfigurationPrior() const override { return kind_ == PriorKind::kPpoe; }

 private:
  UpdateStatus SetPrior(const JointReading& j) {
    if (j.q.size() != kin_.declared().nq()) {
      throw InputError(name_ + ": joint reading has " + std::to_string(j.q.size()) +
                       " angles, the declared model " + std::to_string(kin_.declared().nq()));
    }
    if (!j.q.allFinite()) return UpdateStatus::kRejectedNonFinite;
    kin_.Update(j.q);
    const kinematics::PpoeModel& model = kin_.model();
    if (kind_ == PriorKind::kPpoe) {
      kinematics::ForwardKinematicsWithCovariance(model, data_, kin_.q(), order_);
      belief_.cov = PriorCovariance();
      if (reading_noise_ && j.std.size() == model.nq() && j.std.allFinite()) {
        kinematics::AddJointNoiseCovariance(model, data_, ee_, j.std, J_, &belief_.cov);
      }
      // PPOE covariances are PSD by construction (often singular: rotational sources only);
      // a negative eigenvalue beyond rounding would mean a broken model: repair and count.
      Mat6 repaired = belief_.cov;
      if (RepairCovariance(&repaired, 0.0)) {
        const double scale = std::max(1e-300, belief_.cov.cwiseAbs().maxCoeff());
        if ((repaired - belief_.cov).cwiseAbs().maxCoeff() > 1e-9 * scale) ++prior_repairs_;
        belief_.cov = repaired;
      }
    } else if (ppoe_diagonal_) {
      kinematics::ForwardKinematicsWithCovariance(model, data_, kin_.q(), order_);
      belief_.cov = PriorCovariance().diagonal().asDiagonal();
    } else {
      kinematics::ForwardKinematics(model, data_, kin_.q());
      belief_.cov = naive_cov_;
    }
    belief_.t = j.t;
    belief_.T_base_ee = InRef(ee_);
    belief_.has_joints = true;
    belief_.q = kin_.q();
    belief_.q_std = j.std;
    have_prior_ = true;
    return UpdateStatus::kAccepted;
  }

  // The end effector's PPOE covariance in the estimator's frame (after ForwardKinematics*).
  Mat6 PriorCovariance() const {
    if (ref_ == kinematics::kBaseFrame) return data_.Sigma_frame[ee_];
    Mat6 cov;
    kinematics::RelativeCovariance(kin_.model(), data_, ref_, ee_, &cov);
    return cov;
  }

  // Mean pose of a frame in the estimator's frame (the base, or the reference frame).
  lie::SE3 InRef(FrameId frame) const {
    if (ref_ == kinematics::kBaseFrame) return data_.T_base_frame[frame];
    return data_.T_base_frame[ref_].Between(data_.T_base_frame[frame]);
  }

  // Pose of a frame in the end-effector frame, from the mean kinematics at the prior's q: the
  // frames an EKF of the end-effector pose can use are rigidly attached to it.
  lie::SE3 T_ee(FrameId frame) const {
    return data_.T_base_frame[ee_].Between(data_.T_base_frame[frame]);
  }

  const CameraSetup& Camera(int index) const {
    if (index < 0 || index >= static_cast<int>(cameras_.size())) {
      throw InputError(name_ + ": measurement names camera " + std::to_string(index) +
                       ", set-up has " + std::to_string(cameras_.size()));
    }
    return cameras_[index];
  }

  UpdateStatus Run(const MeasurementModel& model, double t) {
    const LgEkfResult r = LgEkfUpdate(model, options_, &belief_.T_base_ee, &belief_.cov);
    if (r.status == UpdateStatus::kAccepted) belief_.t = std::max(belief_.t, t);
    return r.status;
  }

  UpdateStatus Correct(const PixelPoint& m) {
    const CameraSetup& cam = Camera(m.camera);
    if (!m.uv.allFinite() || !m.cov.allFinite() || !m.p_frame.allFinite()) {
      return UpdateStatus::kRejectedNonFinite;
    }
    if (!cam.intrinsics.InImage(m.uv)) return UpdateStatus::kRejectedOutside;
    const PixelPointModel model(cam.intrinsics, InRef(cam.frame), T_ee(m.frame) * m.p_frame, m.uv,
                                m.cov);
    return Run(model, m.t);
  }

  UpdateStatus Correct(const TagCorners& m) {
    const CameraSetup& cam = Camera(m.camera);
    if (!m.cov.allFinite()) return UpdateStatus::kRejectedNonFinite;
    std::array<Vec3, 4> p_ee;
    const lie::SE3 T_ee_frame = T_ee(m.frame);
    for (int k = 0; k < 4; ++k) {
      if (!m.uv[k].allFinite() || !m.p_frame[k].allFinite()) {
        return UpdateStatus::kRejectedNonFinite;
      }
      if (!cam.intrinsics.InImage(m.uv[k])) return UpdateStatus::kRejectedOutside;
      p_ee[k] = T_ee_frame * m.p_frame[k];
    }
    const TagCornersModel model(cam.intrinsics, InRef(cam.frame), p_ee, m.uv, m.cov);
    return Run(model, m.t);
  }

  UpdateStatus Correct(const PlaneContact& m) {
    if (!std::isfinite(m.distance) || !m.plane_cov.allFinite() || !std::isfinite(m.std) ||
        !m.p_frame.allFinite()) {
      return UpdateStatus::kRejectedNonFinite;
    }
    const PlaneDistanceModel model(m.T_base_plane, m.plane_cov, m.std, T_ee(m.frame) * m.p_frame,
                                   m.distance);
    return Run(model, m.t);
  }

  UpdateStatus Correct(const PositionReading& m) {
    if (!m.p_base.allFinite() || !m.cov.allFinite() || !m.p_frame.allFinite()) {
      return UpdateStatus::kRejectedNonFinite;
    }
    const PositionModel model(T_ee(m.frame) * m.p_frame, m.p_base, m.cov);
    return Run(model, m.t);
  }

  UpdateStatus Correct(const PoseReading& m) {
    if (!m.cov.allFinite() || !m.T_base_frame.rotation().allFinite() ||
        !m.T_base_frame.translation().allFinite()) {
      return UpdateStatus::kRejectedNonFinite;
    }
    const PoseModel model(T_ee(m.frame), m.T_base_frame, m.cov);
    return Run(model, m.t);
  }

  UpdateStatus Correct(const JointReading&) { return UpdateStatus::kIgnored; }
  UpdateStatus Correct(const ImuReading&) { return UpdateStatus::kIgnored; }
  UpdateStatus Correct(const OrientationReading&) { return UpdateStatus::kIgnored; }

  kinematics::EffectiveChain kin_;
  kinematics::PpoeData data_;
  bool reading_noise_ = false;
  kinematics::Matrix6Xd J_{6, kin_.declared().nq()};
  FrameId ee_;
  FrameId ref_;
  std::vector<CameraSetup> cameras_;
  PriorKind kind_;
  std::string name_;
  lie::CompoundOrder order_ = lie::CompoundOrder::kSecond;
  Mat6 naive_cov_ = Mat6::Zero();
  bool ppoe_diagonal_ = false;
  LgEkfOptions options_;
  Belief belief_;
  bool have_prior_ = false;
  int prior_repairs_ = 0;
};

}  // namespace

std::unique_ptr<Estimator> MakePpoeEkf(const EstimatorSetup& setup) {
  return std::make_unique<EkfEstimator>(setup, PriorKind::kPpoe, "ppoe_ekf");
}

std::unique_ptr<Estimator> MakeNaiveEkf(const EstimatorSetup& setup) {
  return std::make_unique<EkfEstimator>(setup, PriorKind::kNaive, "naive_ekf");
}

}  // namespace flexbench::estimators
