// Which directions of the declared PPOE sources a data set constrains, for sizing an augmented
// model's sources on its rows without shrinking what those rows never saw.
//
// A source xi_k ~ N(0, Sigma_k) at F_{k,p} [PPOE eq. 16] reaches a frame f below it as
// Ad_{T_kp_f^-1} Sigma_k Ad^T [PPOE eq. 18] (summed over the sources on f's path, as
// kinematics::RelativeCovariance does): along a unit direction v of Sigma_k with variance
// lambda, row r's point moves by g_r = R_base_kp (rho_v + theta_v x p_kp) per unit of xi, p_kp
// the point in F_{k,p}, and the source adds lambda g_r g_r^T to the row's predicted covariance.
// What the fit re-estimates for every data set absorbs part of g: a socket's point (the rows
// of a group are compared with their mean) and a measurement frame's pose (any rigid motion
// of the rows measured in it). Those parts are projected out, weighted by the rows' noise N_r,
// leaving g~_r. The direction is constrained when its contribution reaches the noise on some
// row, lambda g~_r^T N_r^-1 g~_r >= 1: below that on every row the residuals look the same with
// the source at its declared size or at zero, so the rows give no grounds to resize it (a
// plate's tilt seen only by socket rows moves every row of a socket alike). The fitted effects
// are not projected out: a direction they share (joint_offset@j3 and j3's source about its
// axis) is one the rows determine, so its leftover is what the rows support.
#pragma once

#include <mujoco/mujoco.h>

#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_model.h"
#include "scenarios/identify/identify.h"
#include "sim/declared_model.h"

namespace flexbench::identify {

// One direction of a declared source: the rotation about its joint's axis (about_axis_rad), or
// an axis of its covariance (a diagonal one) or an eigenvector (a full one).
struct SourceDirection {
  int source = -1;                 // index into DeclaredModel::sources
  bool about_axis = false;         // the joint-axis term, else a direction of `cov`
  kinematics::FrameId frame = -1;  // F_{k,p}, the frame the source perturbs
  Vec6 v = Vec6::Zero();           // unit, [rho; theta] in that frame
  double variance = 0.0;           // the declared variance along v (> 0)
  std::string name;                // "<at>:about_axis", "<at>:rot_y", "<at>:dir2"
};

// Every direction of nonzero variance of d's sources, on the chain built from d and m
// (sim::BuildDeclaredChain's frames "joint/<at>", "body/<at>").
std::vector<SourceDirection> SourceDirections(const mjModel* m, const sim::DeclaredModel& d,
                                              const kinematics::PpoeModel& model);

// Per direction, the largest lambda g~_r^T N_r^-1 g~_r over the rows in metres (point, group
// and pose rows), with g~ as above: p[r] the row's predicted point in the base frame, frame
// points[row.point], noise[r] its N_r. 0 for a direction no row's point lies below.
std::vector<double> SourceSignalToNoise(const kinematics::PpoeModel& model, const DataSet& d,
                                        const std::vector<kinematics::FrameId>& points,
                                        const std::vector<Vec3>& p, const std::vector<Mat3>& noise,
                                        const std::vector<SourceDirection>& dirs);

// A direction is constrained from this signal-to-noise on.
inline constexpr double kConstrainedSignalToNoise = 1.0;

// `model` with each frame's source made of the directions with keep[i] alone.
kinematics::PpoeModel WithSourceDirections(const kinematics::PpoeModel& model,
                                           const std::vector<SourceDirection>& dirs,
                                           const std::vector<bool>& keep);

// Scales the variance of the directions with constrained[i] by `scale` and leaves the others
// as declared, to the bit: a source none of whose directions is constrained is untouched.
void ScaleSourceDirections(const std::vector<SourceDirection>& dirs,
                           const std::vector<bool>& constrained, double scale,
                           std::vector<sim::DeclaredSource>* sources);

}  // namespace flexbench::identify
