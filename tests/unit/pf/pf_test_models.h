// Small PPOE models for the particle-filter tests, built in code.
#pragma once

#include <random>

#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/sampling.h"

namespace flexbench::pf::testing {

// The paper's 4-DoF arm shape (Fig. 7), close to models/jsk_arm.xml: a yaw joint, two pitch
// joints with IMU frames on their links, a gripper pitch joint and a grasp point. Frames are
// named like the declared chain's.
struct JskLikeArm {
  kinematics::PpoeModel model{"jsk_like"};
  kinematics::FrameId imu2 = -1, imu3 = -1, grasp = -1, finger = -1;

  JskLikeArm() {
    using kinematics::Joint;
    using lie::SE3;
    const auto T = [](double x, double y, double z) { return SE3::Translation(Vec3(x, y, z)); };
    const int l1 =
        model.AddLink(0, "joint/link1_yaw_joint", T(0, 0, 0.84), Joint::Revolute(Vec3::UnitZ()));
    const int l2 =
        model.AddLink(l1, "joint/link2_pitch_joint", T(0, 0, 0.06), Joint::Revolute(Vec3::UnitY()));
    imu2 = model.AddFrame(l2, "site/imu_link2", T(0.025, 0, 0.19));
    const int l3 =
        model.AddLink(l2, "joint/link3_pitch_joint", T(0, 0, 0.26), Joint::Revolute(Vec3::UnitY()));
    imu3 = model.AddFrame(l3, "site/imu_link3", T(0.022, 0, 0.15));
    const int g = model.AddFrame(l3, "body/gripper_link", T(0, 0, 0.20));
    grasp = model.AddFrame(g, "site/grasp_point", T(0, 0, 0.10));
    finger =
        model.AddLink(g, "joint/gripper_joint", T(0.02, 0, 0.04), Joint::Revolute(Vec3::UnitY()));
  }
};

// A random tree-free chain with fixed frames between joints, joint axes through off-axis points,
// rotated static transforms and sources (which the mean kinematics ignore).
inline kinematics::PpoeModel RandomRevoluteChain(std::mt19937_64& rng, int dof,
                                                 std::vector<kinematics::FrameId>* outputs) {
  using kinematics::Joint;
  kinematics::PpoeModel model("random_chain");
  std::normal_distribution<double> n(0.0, 1.0);
  int parent = 0;
  for (int k = 0; k < dof; ++k) {
    const lie::SE3 Tp = lie::RandomSE3(rng, 0.3);
    if (k % 2 == 1) {
      parent = model.AddFrame(parent, "fixed" + std::to_string(k), lie::RandomSE3(rng, 0.2));
      outputs->push_back(parent);
    }
    const Vec3 axis(n(rng), n(rng), n(rng));
    const Vec3 point(0.1 * n(rng), 0.1 * n(rng), 0.1 * n(rng));
    Mat6 cov = Mat6::Zero();
    cov.diagonal().setConstant(1e-4);
    parent =
        model.AddLink(parent, "link" + std::to_string(k), Tp, Joint::Revolute(axis, point), cov);
    if (k % 3 == 0) outputs->push_back(parent);
  }
  outputs->push_back(model.AddFrame(parent, "ee", lie::RandomSE3(rng, 0.1)));
  return model;
}

}  // namespace flexbench::pf::testing
