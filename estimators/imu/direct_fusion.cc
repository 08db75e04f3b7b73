#include "estimators/imu/direct_fusion.h"

#include <cmath>
#include <vector>

#include "estimators/error.h"
#include "estimators/imu/imu_orientations.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/pf/bingham.h"

namespace flexbench::estimators {
namespace {

using kinematics::JointType;
using kinematics::PpoeModel;

// Nearest frame at or above `frame` with a joint variable (base if none), and the constant
// transform from it to `frame`.
std::pair<FrameId, lie::SE3> NearestJointFrame(const PpoeModel& model, FrameId frame) {
  lie::SE3 T = lie::SE3::Identity();
  while (frame != kinematics::kBaseFrame) {
    const kinematics::PpoeFrame& f = model.frame(frame);
    if (f.q_index >= 0) return {frame, T};
    T = f.T_parent_ip * T;
    frame = f.parent;
  }
  return {kinematics::kBaseFrame, T};
}

class DirectFusion : public Estimator {
 public:
  DirectFusion(const EstimatorSetup& setup, imu::EulerOrder order, const char* name)
      : name_(name),
        order_(order),
        model_(*setup.model),
        kin_(*setup.model, setup.effects),
        data_(*setup.model),
        ee_(setup.end_effector) {
    setup.params.CheckAllUsed(name_);
    if (ee_ < 0 || ee_ >= model_.num_frames()) {
      throw InputError(name_ + ": the setup has no valid end-effector frame");
    }
    if (setup.imus.empty()) throw InputError(name_ + ": needs at least one IMU in the setup");
    for (const ImuSetup& imu : setup.imus) {
      if (imu.frame < 0 || imu.frame >= model_.num_frames()) {
        throw InputError(name_ + ": IMU frame id " + std::to_string(imu.frame) + " does not exist");
      }
      const auto [joint_frame, T_link_imu] = NearestJointFrame(model_, imu.frame);
      if (joint_frame == kinematics::kBaseFrame) {
        throw InputError(name_ + ": IMU frame '" + model_.frame(imu.frame).name +
                         "' has no joint above it");
      }
      const kinematics::PpoeFrame& jf = model_.frame(joint_frame);
      if (jf.joint.type != JointType::kRevolute) {
        throw InputError(name_ + ": the joint of IMU frame '" + model_.frame(imu.frame).name +
                         "' is not revolute");
      }
      Link link;
      link.imu_frame = imu.frame;
      link.joint_frame = joint_frame;
      link.q_index = jf.q_index;
      link.R_link_imu = T_link_imu.rotation();
      link.axis = jf.joint.axis;
      const auto [parent_joint, T_pj_parent] = NearestJointFrame(model_, jf.parent);
      link.parent_joint_frame = parent_joint;
      link.R_parent_ip = (T_pj_parent * jf.T_parent_ip).rotation();
      for (const Link& other : links_) {
        if (other.q_index == link.q_index) {
          throw InputError(name_ + ": two IMUs measure the joint of frame '" + jf.name + "'");
        }
      }
      links_.push_back(link);
    }
    for (Link& link : links_) {
      for (size_t k = 0; k < links_.size(); ++k) {
        if (links_[k].joint_frame == link.parent_joint_frame) link.parent_imu = static_cast<int>(k);
      }
    }
    q_enc_ = Eigen::VectorXd::Zero(model_.nq());
    q_ = q_enc_;
    imu_ = std::make_unique<imu::ImuOrientations>(setup.imus);
    Reset();
  }

  void Reset() override {
    belief_ = Belief{};
    has_enc_ = false;
    for (Link& l : links_) l.has_reading = false;
    imu_->Reset();
  }

  void Predict(double t) override { belief_.t = t; }

  UpdateStatus Update(const Measurement& z) override {
    if (const auto* j = std::get_if<JointReading>(&z)) {
      if (j->q.size() != model_.nq()) {
        throw InputError(name_ + ": joint reading has " + std::to_string(j->q.size()) +
                         " angles, the declared model " + std::to_string(model_.nq()));
      }
      if (!j->q.allFinite()) return UpdateStatus::kRejectedNonFinite;
      kin_.Update(j->q);
      q_enc_ = kin_.q();
      has_enc_ = true;
      belief_.t = j->t;
      Recompute();
      return UpdateStatus::kAccepted;
    }
    if (const auto* r = std::get_if<ImuReading>(&z)) {
      // Its filter's orientation, as if it had come as an OrientationReading.
      const UpdateStatus s = imu_->Feed(*r);
      if (s != UpdateStatus::kAccepted) return s;
      return Update(imu_->Take(r->imu));
    }
    if (const auto* o = std::get_if<OrientationReading>(&z)) {
      for (Link& l : links_) {
        if (l.imu_frame != o->frame) continue;
        const Vec4 xyzw(o->q_base_frame.x(), o->q_base_frame.y(), o->q_base_frame.z(),
                        o->q_base_frame.w());
        if (!xyzw.allFinite()) return UpdateStatus::kRejectedNonFinite;
        if (std::abs(xyzw.norm() - 1.0) > pf::kUnitQuaternionTol) {
          return UpdateStatus::kRejectedOutside;
        }
        l.R_base_imu = o->q_base_frame.normalized().toRotationMatrix();
        l.has_reading = true;
        belief_.t = o->t;
        Recompute();
        return UpdateStatus::kAccepted;
      }
      return UpdateStatus::kIgnored;
    }
    return UpdateStatus::kIgnored;
  }

  Belief Estimate() const override { return belief_; }

 private:
  struct Link {
    FrameId imu_frame = -1;
    FrameId joint_frame = -1;
    FrameId parent_joint_frame = -1;
    int parent_imu = -1;
    int q_index = -1;
    Mat3 R_link_imu = Mat3::Identity();
    Mat3 R_parent_ip = Mat3::Identity();
    Vec3 axis = Vec3::UnitZ();
    bool has_reading = false;
    Mat3 R_base_imu = Mat3::Identity();
  };

  // Yaw-cancelled orientation of a link measured by IMU k.
  Mat3 MeasuredLink(const Link& l) const {
    return imu::CancelYaw(l.R_base_imu * l.R_link_imu.transpose(), order_);
  }

  void Recompute() {
    if (!has_enc_) return;
    q_ = q_enc_;
    kinematics::ForwardKinematics(kin_.model(), data_, q_enc_);
    for (const Link& l : links_) {
      if (!l.has_reading) continue;
      const Mat3 Rc = MeasuredLink(l);
      Mat3 Rp;
      if (l.parent_imu >= 0 && links_[l.parent_imu].has_reading) {
        Rp = MeasuredLink(links_[l.parent_imu]);
      } else {
        Rp = imu::CancelYaw(data_.T_base_frame[l.parent_joint_frame].rotation(), order_);
      }
      // R_parent_link = R_parent_ip Rot(axis, q): the joint's rotation is what remains.
      const Quat d(l.R_parent_ip.transpose() * Rp.transpose() * Rc);
      const double w = std::abs(d.w());
      const Vec3 v = d.w() < 0.0 ? Vec3(-d.vec()) : Vec3(d.vec());
      const double angle = 2.0 * std::atan2(v.norm(), w);
      q_[l.q_index] = v.dot(l.axis) < 0.0 ? -angle : angle;
    }
    kinematics::ForwardKinematicsWithCovariance(kin_.model(), data_, q_,
                                                lie::CompoundOrder::kSecond);
    belief_.T_base_ee = data_.T_base_frame[ee_];
    belief_.cov = data_.Sigma_frame[ee_];
    belief_.has_joints = true;
    belief_.q = q_;
    belief_.q_std = JointVector::Zero(model_.nq());
  }

  std::string name_;
  imu::EulerOrder order_;
  // The IMU links' geometry is the declared one; the encoders' joint map and the chain's
  // identified effects (kin_) apply to the encoder-driven joints and the end-effector pose.
  const PpoeModel& model_;
  kinematics::EffectiveChain kin_;
  kinematics::PpoeData data_;
  FrameId ee_;
  std::vector<Link> links_;
  Eigen::VectorXd q_enc_;
  Eigen::VectorXd q_;
  bool has_enc_ = false;
  Belief belief_;
  std::unique_ptr<imu::ImuOrientations> imu_;  // the IMUs' filters, fed with raw readings
};

}  // namespace

std::unique_ptr<Estimator> MakeDirectFusion(const EstimatorSetup& setup, imu::EulerOrder order,
                                            const char* name) {
  if (!setup.model) throw InputError(std::string(name) + ": no declared model");
  return std::make_unique<DirectFusion>(setup, order, name);
}

std::unique_ptr<Estimator> MakeDirectFusionXyz(const EstimatorSetup& setup) {
  return MakeDirectFusion(setup, imu::EulerOrder::kXYZ, "direct_fusion_xyz");
}

std::unique_ptr<Estimator> MakeDirectFusionYxz(const EstimatorSetup& setup) {
  return MakeDirectFusion(setup, imu::EulerOrder::kYXZ, "direct_fusion_yxz");
}

}  // namespace flexbench::estimators
