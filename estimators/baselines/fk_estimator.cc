#include "estimators/baselines/fk_estimator.h"

#include "estimators/error.h"
#include "estimators/estimator.h"
#include "estimators/kinematics/forward_kinematics.h"

namespace flexbench::estimators {
namespace {

class FkEstimator : public Estimator {
 public:
  explicit FkEstimator(const EstimatorSetup& setup)
      : kin_(*setup.model, setup.effects),
        data_(*setup.model),
        ee_(setup.end_effector),
        ref_(setup.reference_frame) {
    const double order = setup.params.Scalar("covariance_order", 2.0);
    if (order != 2.0 && order != 4.0) {
      throw InputError("fk: covariance_order must be 2 or 4");
    }
    order_ = order == 4.0 ? lie::CompoundOrder::kFourth : lie::CompoundOrder::kSecond;
    reading_noise_ = ReadingNoiseFlag(setup.params, "fk", ref_);
    if (ref_ < 0 || ref_ >= setup.model->num_frames()) {
      throw InputError("fk: reference frame " + std::to_string(ref_) + " not in the model");
    }
    if (ref_ != kinematics::kBaseFrame && order_ == lie::CompoundOrder::kFourth) {
      throw InputError("fk: covariance_order 4 is not available in a reference frame");
    }
    setup.params.CheckAllUsed("fk");
    Reset();
  }

  void Reset() override { belief_ = Belief{}; }
  bool FusesExternalMeasurements() const override { return false; }
  bool HasConfigurationPrior() const override { return true; }

  void Predict(double t) override { belief_.t = t; }

  UpdateStatus Update(const Measurement& z) override {
    const auto* joints = std::get_if<JointReading>(&z);
    if (!joints) return UpdateStatus::kIgnored;
    const kinematics::PpoeModel& declared = kin_.declared();
    if (joints->q.size() != declared.nq()) {
      throw InputError("fk: joint reading has " + std::to_string(joints->q.size()) +
                       " angles, the declared model " + std::to_string(declared.nq()));
    }
    if (!joints->q.allFinite()) return UpdateStatus::kRejectedNonFinite;
    kin_.Update(joints->q);
    const kinematics::PpoeModel& model = kin_.model();
    kinematics::ForwardKinematicsWithCovariance(model, data_, kin_.q(), order_);
    belief_.t = joints->t;
    if (ref_ == kinematics::kBaseFrame) {
      belief_.T_base_ee = data_.T_base_frame[ee_];
      belief_.cov = data_.Sigma_frame[ee_];
      if (reading_noise_ && joints->std.size() == model.nq() && joints->std.allFinite()) {
        kinematics::AddJointNoiseCovariance(model, data_, ee_, joints->std, J_, &belief_.cov);
      }
    } else {  // the end effector seen from the reference frame
      belief_.T_base_ee = data_.T_base_frame[ref_].Between(data_.T_base_frame[ee_]);
      kinematics::RelativeCovariance(model, data_, ref_, ee_, &belief_.cov);
    }
    belief_.has_joints = true;
    belief_.q = kin_.q();
    belief_.q_std = joints->std;
    return UpdateStatus::kAccepted;
  }

  Belief Estimate() const override { return belief_; }

 private:
  kinematics::EffectiveChain kin_;
  kinematics::PpoeData data_;
  bool reading_noise_ = false;
  kinematics::Matrix6Xd J_{6, kin_.declared().nq()};
  FrameId ee_;
  FrameId ref_;
  lie::CompoundOrder order_ = lie::CompoundOrder::kSecond;
  Belief belief_;
};

}  // namespace

std::unique_ptr<Estimator> MakeFkEstimator(const EstimatorSetup& setup) {
  return std::make_unique<FkEstimator>(setup);
}

}  // namespace flexbench::estimators
