// The particles' end-effector spread about the estimate's pose, for the particle filter's
// summary: computed on the batch kinematics' columns, block by block, with no
// per-particle SE3 object and no libm call, so the loops vectorise. The per-particle SE3::Log it
// replaces was half the cost of a summary.
#pragma once

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"
#include "estimators/pf/batch_kinematics.h"
#include "estimators/pf/particle_moments.h"

namespace flexbench::pf {

// sum_i w_i xi_i xi_i^T with xi_i = Log(T_mean^-1 T_i) (conventions.h order: translation, then
// rotation), T_i output k of particle i, over the kept particles (w_i >= negligible, the weights
// and lanes of KeptParticles): the particles' second moment in T_mean's local tangent space.
// Equals the definition written with lie::SE3::Log to rounding (tests/unit/pf/pose_spread_test.cc);
// rotations within ~0.8 rad of pi of T_mean go through lie::SE3::Log itself.
void PoseSpread(const BatchKinematics& fk, int k, const lie::SE3& T_mean, const KeptParticles& kept,
                Mat6* cov);

namespace internal {
// atan2(y, x) for y >= 0 and x > -0.7 y-proportionally (angles in [0, 3 pi / 4)), branch-free
// (Cephes' rational approximation of atan): within 2 ulp of std::atan2 (tested).
double Atan2UpperHalf(double y, double x);
}  // namespace internal

}  // namespace flexbench::pf
