#include "estimators/kinematics/forward_kinematics.h"

#include <cmath>
#include <sstream>

#include "estimators/error.h"

namespace flexbench::kinematics {
namespace {

using lie::SE3;

void CheckInputs(const PpoeModel& model, const PpoeData& data,
                 const Eigen::Ref<const Eigen::VectorXd>& q, const char* caller) {
  if (data.num_frames != model.num_frames() || data.nq != model.nq() ||
      static_cast<int>(data.T_base_frame.size()) != model.num_frames() ||
      static_cast<int>(data.Sigma_frame.size()) != model.num_frames() ||
      static_cast<int>(data.sigma_is_zero.size()) != model.num_frames()) {
    std::ostringstream msg;
    msg << caller << ": PpoeData was built for a model with " << data.num_frames << " frames and "
        << data.nq << " joints, but PPOE model '" << model.name() << "' has " << model.num_frames()
        << " frames and " << model.nq() << " joints";
    throw InputError(msg.str());
  }
  if (q.size() != model.nq()) {
    std::ostringstream msg;
    msg << caller << ": q has " << q.size() << " entries, PPOE model '" << model.name() << "' has "
        << model.nq() << " joints";
    throw InputError(msg.str());
  }
  if (!q.allFinite()) {
    for (int k = 0; k < q.size(); ++k) {
      if (!std::isfinite(q[k])) {
        std::ostringstream msg;
        msg << caller << ": q[" << k << "] (joint of frame '"
            << model.frame(model.joint_frame(k)).name << "' in PPOE model '" << model.name()
            << "') is " << q[k];
        throw InputError(msg.str());
      }
    }
  }
}

double JointValue(const PpoeFrame& f, const Eigen::Ref<const Eigen::VectorXd>& q) {
  return f.q_index >= 0 ? q[f.q_index] : 0.0;
}

// T_parent_i at the mean: T_parent_ip * Exp(zeta q) with the precomputed Rodrigues terms.
SE3 RelativeMean(const PpoeFrame& f, double q) {
  const Mat3& R_p = f.T_parent_ip.rotation();
  switch (f.joint.type) {
    case JointType::kRevolute: {
      const double s = std::sin(q);
      const double sh = std::sin(0.5 * q);
      const Mat3 R = R_p + s * f.K1 + (2.0 * sh * sh) * f.K2;
      return SE3(R, f.u0 - R * f.joint.point);
    }
    case JointType::kPrismatic:
      return SE3(R_p, f.T_parent_ip.translation() + q * f.u1);
    case JointType::kFixed:
      break;
  }
  return f.T_parent_ip;
}

// Exp(zeta q) alone, for moving a covariance across the joint.
SE3 JointTransform(const PpoeFrame& f, double q) {
  if (f.joint.type == JointType::kPrismatic) {
    return SE3::Translation(q * f.joint.axis);
  }
  const double s = std::sin(q);
  const double sh = std::sin(0.5 * q);
  const Mat3 W = lie::Skew(f.joint.axis);
  const Mat3 R = Mat3::Identity() + s * W + (2.0 * sh * sh) * (W * W);
  return SE3(R, f.joint.point - R * f.joint.point);
}

}  // namespace

void ForwardKinematics(const PpoeModel& model, PpoeData& data,
                       const Eigen::Ref<const Eigen::VectorXd>& q) {
  CheckInputs(model, data, q, "ForwardKinematics");
  const std::vector<PpoeFrame>& frames = model.frames();
  data.T_base_frame[kBaseFrame] = SE3::Identity();
  for (int i = 1; i < data.num_frames; ++i) {
    const PpoeFrame& f = frames[i];
    data.T_base_frame[i] = data.T_base_frame[f.parent] * RelativeMean(f, JointValue(f, q));
  }
}

void ForwardKinematicsWithCovariance(const PpoeModel& model, PpoeData& data,
                                     const Eigen::Ref<const Eigen::VectorXd>& q,
                                     lie::CompoundOrder order) {
  CheckInputs(model, data, q, "ForwardKinematicsWithCovariance");
  if (order != lie::CompoundOrder::kSecond && order != lie::CompoundOrder::kFourth) {
    throw InputError("ForwardKinematicsWithCovariance: order must be kSecond or kFourth, got " +
                     std::to_string(static_cast<int>(order)));
  }
  const std::vector<PpoeFrame>& frames = model.frames();
  data.T_base_frame[kBaseFrame] = SE3::Identity();
  data.Sigma_frame[kBaseFrame].setZero();
  data.sigma_is_zero[kBaseFrame] = 1;
  for (int i = 1; i < data.num_frames; ++i) {
    const PpoeFrame& f = frames[i];
    const double q_i = JointValue(f, q);
    const SE3 T_parent_i = RelativeMean(f, q_i);
    data.T_base_frame[i] = data.T_base_frame[f.parent] * T_parent_i;

    const bool parent_zero = data.sigma_is_zero[f.parent] != 0;
    const Mat6& Sigma_parent = data.Sigma_frame[f.parent];
    Mat6& Sigma_i = data.Sigma_frame[i];
    data.sigma_is_zero[i] = parent_zero && !f.has_source;
    if (!f.has_source) {
      // No source: the whole of eq. 16 is a fixed transform, moved exactly (eq. 11b).
      if (parent_zero) {
        Sigma_i.setZero();
      } else {
        Sigma_i = lie::TransportCovariance(T_parent_i, Sigma_parent);
      }
      continue;
    }
    // Accumulated covariance at F_{i,p}, then the source (eq. 18 or its 4th-order form).
    const Mat6 Sigma_ixi =
        parent_zero ? f.source_cov
                    : lie::BchSecondMoment(lie::TransportCovariance(f.T_parent_ip, Sigma_parent),
                                           f.source_cov, order);
    if (f.joint.type == JointType::kFixed) {
      Sigma_i = Sigma_ixi;
    } else {
      Sigma_i = lie::TransportCovariance(JointTransform(f, q_i), Sigma_ixi);
    }
  }
}

void ComputeFrameJacobian(const PpoeModel& model, const PpoeData& data, FrameId frame,
                          Eigen::Ref<Matrix6Xd> J_frame_q) {
  if (frame < 0 || frame >= model.num_frames()) {
    throw InputError("ComputeFrameJacobian: frame id " + std::to_string(frame) +
                     " does not exist in PPOE model '" + model.name() + "'");
  }
  if (J_frame_q.cols() != model.nq() ||
      static_cast<int>(data.T_base_frame.size()) != model.num_frames()) {
    throw InputError("ComputeFrameJacobian: J_frame_q has " + std::to_string(J_frame_q.cols()) +
                     " columns, PPOE model '" + model.name() + "' has " +
                     std::to_string(model.nq()) + " joints");
  }
  J_frame_q.setZero();
  const SE3 T_frame_base = data.T_base_frame[frame].Inverse();
  for (FrameId j = frame; j != kBaseFrame; j = model.frame(j).parent) {
    const PpoeFrame& f = model.frame(j);
    if (f.q_index < 0) continue;
    // Exp(zeta (q + dq)) = Exp(zeta q) Exp(zeta dq): the increment sits at F_j and reaches the
    // frame through the rigid T_j_frame.
    J_frame_q.col(f.q_index) = (T_frame_base * data.T_base_frame[j]).AdjointTimes(f.zeta);
  }
}

}  // namespace flexbench::kinematics
