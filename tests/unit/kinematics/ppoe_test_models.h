// PPOE models built in code for tests and benchmarks: the paper's planar 3R arm (sec. IV-C,
// Fig. 3) and random chains and trees with a fixed seed.
#pragma once

#include <cmath>
#include <random>
#include <string>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/sampling.h"
#include "estimators/lie/se3.h"

namespace flexbench::kinematics::testing {

// Entries uniform in [-scale, scale], drawn in a fixed order (function-argument evaluation order
// is unspecified, so never draw inside an argument list).
inline Vec3 UniformVec3(std::mt19937_64& rng, double scale = 1.0) {
  std::uniform_real_distribution<double> u(-scale, scale);
  Vec3 v;
  for (int i = 0; i < 3; ++i) v[i] = u(rng);
  return v;
}

// Rotational-only source of standard deviation sd about the (local) axis.
inline Mat6 AxisSource(const Vec3& axis, double sd) {
  Mat6 cov = Mat6::Zero();
  const Vec3 u = axis.normalized();
  cov.block<3, 3>(kRotIdx, kRotIdx) = sd * sd * u * u.transpose();
  return cov;
}

// Full 6-DoF source with random correlations, standard deviations trans_sd (m) and rot_sd (rad).
inline Mat6 RandomSource(std::mt19937_64& rng, double trans_sd, double rot_sd) {
  std::normal_distribution<double> n(0.0, 1.0);
  Mat6 A;
  for (int i = 0; i < 36; ++i) A(i) = n(rng);
  Mat6 C = A * A.transpose() + 6.0 * Mat6::Identity();
  const Vec6 d = C.diagonal().cwiseSqrt().cwiseInverse();
  Vec6 sd;
  sd << trans_sd, trans_sd, trans_sd, rot_sd, rot_sd, rot_sd;
  C = (sd.cwiseProduct(d)).asDiagonal() * C * (sd.cwiseProduct(d)).asDiagonal();
  return C;
}

// The paper's planar arm: three revolute z joints, links of length `link` along x, rotational
// sources of `sd` about each joint axis, and an "ee" frame at the tip.
inline PpoeModel PlanarArm3R(double sd, double link = 1.0) {
  PpoeModel model("planar3r");
  FrameId parent = kBaseFrame;
  for (int i = 0; i < 3; ++i) {
    const lie::SE3 p = i == 0 ? lie::SE3() : lie::SE3::Translation(Vec3(link, 0.0, 0.0));
    parent = model.AddLink(parent, "link" + std::to_string(i + 1), p,
                           Joint::Revolute(Vec3::UnitZ()), AxisSource(Vec3::UnitZ(), sd));
  }
  model.AddFrame(parent, "ee", lie::SE3::Translation(Vec3(link, 0.0, 0.0)));
  return model;
}

struct RandomChainOptions {
  int dof = 7;
  double trans_sd = 0.0;           // per-source translational standard deviation (m)
  double rot_sd = 0.0;             // per-source rotational standard deviation (rad)
  bool mixed_joints = false;       // revolute axes through off-origin points and prismatic joints
  bool fixed_base_source = false;  // a passive, non-actuated compliance at the base
  bool grasp = false;              // an uncertain grasp frame below the end effector
  bool tag = true;                 // a rigid "tag" frame on link N-2
};

// Every structural feature on: mixed joint types, a base compliance, an uncertain grasp.
inline RandomChainOptions EveryFeature(int dof, double trans_sd, double rot_sd) {
  RandomChainOptions o;
  o.dof = dof;
  o.trans_sd = trans_sd;
  o.rot_sd = rot_sd;
  o.mixed_joints = true;
  o.fixed_base_source = true;
  o.grasp = true;
  return o;
}

// A serial chain with random geometry (links ~0.3 m) and a 6-DoF source at every joint. Frames:
// "base_plate" (if requested), "link1".."linkN", "ee", "tag" (a rigid frame on link N-2, if
// requested), "grasp" (if requested).
inline PpoeModel RandomChain(std::mt19937_64& rng, const RandomChainOptions& o) {
  PpoeModel model("random" + std::to_string(o.dof));
  const bool sources = o.trans_sd > 0.0 || o.rot_sd > 0.0;
  FrameId parent = kBaseFrame;
  if (o.fixed_base_source) {
    parent = model.AddFrame(parent, "base_plate", lie::SE3::Translation(Vec3(0.0, 0.0, 0.05)),
                            RandomSource(rng, 0.5 * o.trans_sd + 1e-4, 0.5 * o.rot_sd + 1e-3));
  }
  FrameId tag_parent = parent;
  for (int i = 0; i < o.dof; ++i) {
    const lie::SE3 T = lie::RandomSE3(rng, 0.3);
    const Vec3 axis = UniformVec3(rng);
    const Vec3 point = UniformVec3(rng, 0.1);
    Joint joint = Joint::Revolute(axis);
    if (o.mixed_joints && i % 3 == 1) joint = Joint::Prismatic(axis);
    if (o.mixed_joints && i % 3 == 2) joint = Joint::Revolute(axis, point);
    const Mat6 cov = sources ? RandomSource(rng, o.trans_sd, o.rot_sd) : Mat6::Zero();
    parent = model.AddLink(parent, "link" + std::to_string(i + 1), T, joint, cov);
    if (i == o.dof - 3) tag_parent = parent;
  }
  const FrameId ee = model.AddFrame(parent, "ee", lie::RandomSE3(rng, 0.1));
  const lie::SE3 T_link_tag = lie::RandomSE3(rng, 0.1);
  if (o.tag) model.AddFrame(tag_parent, "tag", T_link_tag);
  if (o.grasp) {
    model.AddFrame(ee, "grasp", lie::SE3::Translation(Vec3(0.0, 0.0, 0.1)),
                   RandomSource(rng, 0.5 * o.trans_sd + 1e-4, 0.5 * o.rot_sd + 1e-3));
  }
  return model;
}

// Joint values in [-pi, pi) (revolute) and [-0.2, 0.2] m (prismatic).
inline Eigen::VectorXd RandomQ(std::mt19937_64& rng, const PpoeModel& model) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd q(model.nq());
  for (int k = 0; k < model.nq(); ++k) {
    const bool prismatic = model.frame(model.joint_frame(k)).joint.type == JointType::kPrismatic;
    q[k] = prismatic ? 0.2 * u(rng) : M_PI * u(rng);
  }
  return q;
}

}  // namespace flexbench::kinematics::testing
