// Workspace for PPOE forward kinematics: sized once from a PpoeModel, then reused so the FK
// calls never allocate (Pinocchio's Model/Data split).
#pragma once

#include <cstdint>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/se3.h"

namespace flexbench::kinematics {

struct PpoeData {
  explicit PpoeData(const PpoeModel& model);

  // Mean pose of every frame in the base frame ([PPOE eq. 17] evaluated with all xi = 0), indexed
  // by FrameId; T_base_frame[kBaseFrame] is the identity.
  std::vector<lie::SE3> T_base_frame;
  // Mean pose of every frame in its parent, T_parent_i(q) ([PPOE eq. 16] with xi = 0). Computed in
  // a first pass over all frames, which has no serial dependency and pipelines well.
  std::vector<lie::SE3> T_parent_frame;
  // Covariance of every frame in its own local (right) tangent space: the true pose is
  // T_base_frame[i] * Exp(xi), E[xi xi^T] = Sigma_frame[i] [PPOE eqs. 9, 18]. Only written by
  // ForwardKinematicsWithCovariance. Use lie::TransformCovariance for the global form [PPOE eq.
  // 10].
  std::vector<Mat6> Sigma_frame;
  // Whether Sigma_frame[i] is exactly zero (no source upstream): lets the kernels skip work.
  std::vector<std::uint8_t> sigma_is_zero;

  // The model size this workspace was built for (checked by every FK call).
  int num_frames = 0;
  int nq = 0;
};

}  // namespace flexbench::kinematics
