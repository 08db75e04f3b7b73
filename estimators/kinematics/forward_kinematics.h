// Probabilistic forward kinematics of a PPOE model (PPOE paper sec. IV-B).
//
// All functions read a constant PpoeModel and write into a PpoeData built for it; with the data
// preallocated they do not allocate (error paths excepted: they throw InputError).
#pragma once

#include <Eigen/Core>

#include "estimators/kinematics/ppoe_data.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/compound.h"

namespace flexbench::kinematics {

using Matrix6Xd = Eigen::Matrix<double, 6, Eigen::Dynamic>;

// Mean poses of all frames, [PPOE eqs. 16-17] with xi = 0: data.T_base_frame. Throws InputError if
// q.size() != model.nq() or if any q is NaN or infinite (naming the joint);
// std::invalid_argument if data was built for another model.
void ForwardKinematics(const PpoeModel& model, PpoeData& data,
                       const Eigen::Ref<const Eigen::VectorXd>& q);

// Mean poses and local covariances of all frames: data.T_base_frame and data.Sigma_frame.
// Covariances are compounded source by source along the tree [PPOE eq. 14]: the fixed parts of
// [PPOE eq. 16] move the accumulated covariance exactly by the adjoint [PPOE eq. 11b]; at each
// source the accumulated and the new perturbation are combined with [PPOE eq. 15] / [PPOE eq. 18]
// (kSecond) or the 4th-order BCH moments (kFourth, see lie/compound.h), assuming sources are
// independent.
void ForwardKinematicsWithCovariance(const PpoeModel& model, PpoeData& data,
                                     const Eigen::Ref<const Eigen::VectorXd>& q,
                                     lie::CompoundOrder order);

namespace internal {
// The baseline-CPU path of ForwardKinematicsWithCovariance (no input checks), callable on any
// CPU so that tests compare it bit for bit with the dispatched one.
void ForwardKinematicsWithCovarianceBaseline(const PpoeModel& model, PpoeData& data,
                                             const Eigen::Ref<const Eigen::VectorXd>& q,
                                             lie::CompoundOrder order);
}  // namespace internal

// Covariance of the relative pose T_ref_frame = T_base_ref^-1 T_base_frame in its local tangent
// space, to 2nd order [PPOE eq. 18]: the sum over every source k on the path from the two frames'
// lowest common ancestor down to either frame of Ad_{T_kp_frame^-1} Sigma_k Ad^T, with
// T_kp_frame = T_base_kp^-1 T_base_frame (a source on `ref`'s branch enters with a minus sign,
// which the covariance does not see). Sources on the common trunk move both frames alike and
// cancel exactly. This is the prior of an estimate made in a sensor's frame, e.g. the end
// effector seen from a camera on another branch ([PPOE eq. 25]: X is the end effector in
// the camera frame). With ref = kBaseFrame it equals ForwardKinematicsWithCovariance's kSecond
// Sigma_frame. Reads the mean poses in `data` (call ForwardKinematics* with the same q first);
// does not allocate. Throws InputError for a frame id the model lacks.
void RelativeCovariance(const PpoeModel& model, const PpoeData& data, FrameId ref, FrameId frame,
                        Mat6* Sigma_ref_frame);

// J_frame_q (6 x nq): T_base_frame(q + dq) = T_base_frame(q) * Exp(J_frame_q dq) to first
// order (right/local tangent, xi = [rho; theta]). Column k is Ad_{T_frame_j} zeta_j for the
// frame j moved by q[k] if j is `frame` or one of its ancestors, else zero. Reads the mean poses
// in `data`: call ForwardKinematics* with the same q first. Throws InputError for a frame id the
// model lacks, std::invalid_argument when J_frame_q is not 6 x nq.
void ComputeFrameJacobian(const PpoeModel& model, const PpoeData& data, FrameId frame,
                          Eigen::Ref<Matrix6Xd> J_frame_q);

// Adds the joint readings' own noise to a frame's local covariance: Sigma += J diag(std^2) J^T
// with J = J_frame_q at the mean poses in `data` (first order; the PPOE sources know nothing of
// the encoders' noise). `J_frame_q` is scratch of 6 x nq. Throws InputError when q_std has
// another size than nq, std::invalid_argument when J_frame_q does.
void AddJointNoiseCovariance(const PpoeModel& model, const PpoeData& data, FrameId frame,
                             const Eigen::Ref<const Eigen::VectorXd>& q_std,
                             Eigen::Ref<Matrix6Xd> J_frame_q, Mat6* Sigma);

}  // namespace flexbench::kinematics
