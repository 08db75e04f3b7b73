// Rao-Blackwellised joint estimates for the particle filter: each particle contributes to the
// circular mean [PF eq. 5] of joint j not e^{i x_j} but the exact conditional first moment
// E[e^{i x_j} | x_{-j}, x_prev, u, y] of its step's target [PF eqs. 23, 26-28, 30].
//
// Why it is exact: with the other joints fixed, every frame below joint j moves by a rotation
// about the joint's axis line in the world, Rot(w, d) = cos d I + sin d [w]x + (1 - cos d) w w^T.
// The Bingham term c0 + tr(C^T Rot R) [PF eq. 27] and, when R_w = sigma^2 I, the position term
// -|y - Rot p|^2 / (2 sigma^2) [PF eq. 26] are then a cos d + b sin d + const, as are the system
// [PF eq. 30] and encoder [PF eq. 28] terms: the conditional is one von Mises vM(kappa, mu),
// kappa e^{i mu} the sum of the terms' phasors, and its first moment A1(kappa) e^{i mu}. Since
// E[e^{i x_j}] = E[E[e^{i x_j} | rest]], the weighted sum of these moments estimates the same
// posterior mean with less Monte-Carlo variance (the conditional's own spread is integrated,
// not sampled). With a non-isotropic R_w the position term has second harmonics: joints with a
// position reading below them then keep the particles' own e^{i x_j} (exact() says which).
//
// Per-particle arrays are structure-of-arrays [joint][stride], as the filter's; allocation only
// at construction.
#pragma once

#include <cstdint>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/pf/batch_kinematics.h"
#include "estimators/pf/bessel.h"

namespace flexbench::pf {

class ConditionalMoments {
 public:
  // `position_frames` / `orientation_frames`: the filter's F_P and F_Q; `position_info`: R_w^-1.
  ConditionalMoments(const kinematics::PpoeModel& model,
                     const std::vector<FrameId>& position_frames,
                     const std::vector<FrameId>& orientation_frames, const Mat3& position_info,
                     std::size_t stride);

  // The frames whose poses Add* read from the batch kinematics: the joint frames of the joints
  // with a reading below them. Bind takes their output indices in `fk` (which must have them).
  static std::vector<FrameId> JointFrames(const kinematics::PpoeModel& model,
                                          const std::vector<FrameId>& position_frames,
                                          const std::vector<FrameId>& orientation_frames);
  const std::vector<FrameId>& joint_frames() const { return joint_frames_; }
  void Bind(const BatchKinematics& fk);
  // Whether joint j's conditional is exactly von Mises (see above).
  bool exact(int j) const { return (exact_ >> j) & 1u; }

  // Starts a step: the system term kappa_v e^{i x_prev} for every joint (prev_c and prev_s are
  // read again by Finish) and, when u is given, the encoder term kappa_w e^{i u}; the joints'
  // axes from `fk`, which holds the particles'
  // poses of joint_frames() (Bind). Clears the readings' terms.
  void Begin(const kinematics::PpoeModel& model, const BatchKinematics& fk, const double* prev_c,
             const double* prev_s, const double* u, double kappa_v, double kappa_w, int n);
  // Adds position reading a (index into F_P) of point p_frame read at p_base; `fk` output
  // k_frame holds the particles' poses of its frame.
  void AddPosition(const BatchKinematics& fk, int a, int k_frame, const Vec3& p_frame,
                   const Vec3& p_base, int n);
  // Adds orientation reading a (index into F_Q), log B = c0 + tr(C^T R).
  void AddOrientation(const BatchKinematics& fk, int a, int k_frame, const Mat3& C, int n);
  // The moments at the particles' angles (cos, sin), [nq][stride]: moment_c()/moment_s().
  void Finish(const double* cos, const double* sin, int n);

  const double* moment_c(int j) const { return mc_.data() + j * stride_; }
  const double* moment_s(int j) const { return ms_.data() + j * stride_; }

 private:
  int nq_;
  std::size_t stride_;
  std::uint32_t exact_ = 0;
  double position_scale_ = 0.0;  // 1 / sigma^2 when R_w = sigma^2 I
  std::vector<std::uint32_t> position_below_, orientation_below_;  // joints above each frame
  std::vector<FrameId> joint_frames_;
  std::vector<FrameId> joint_frame_ids_;  // joint_frame(j) of the model, every j
  std::vector<int> joint_output_;         // joint -> fk output of its joint frame (-1: none)
  // The step's system and encoder terms: kappa_v e^{i x_prev} (the caller's arrays, which must
  // outlive Finish) and kappa_w e^{i u} per joint.
  const double* prev_c_ = nullptr;
  const double* prev_s_ = nullptr;
  double kappa_v_ = 0.0;
  double cu_[32] = {}, su_[32] = {};
  std::vector<double> a_, b_;  // the readings' a cos d + b sin d about the particle's angle
  std::vector<double> mc_, ms_;
  BesselRatioA1Interpolant a1_;
  std::vector<double> axis_[6];     // [nq][stride]: the joint's world axis w (0-2), a point o (3-5)
  std::vector<double> scratch_[9];  // [stride]: a reading's point or G = R C^T per particle
};

}  // namespace flexbench::pf
