// The particle-filter paper's direct-fusion baseline (sec. IV-D, Fig. 9): joint angles read off
// the IMU orientations by hand, without a filter.
//
// For each IMU (setup.imus) the joint it measures is the nearest joint at or above its frame
// (link2_pitch_joint for the IMU on link2). Per step:
//   1. the IMU orientation, from its raw readings (ImuReading, through one Madgwick filter per IMU:
//      imu_orientations.h) or given as an OrientationReading, is turned into the orientation of
//      the joint's link with the mounting rotation of the declared model;
//   2.-4. CancelYaw (euler.h): Euler angles in the chosen order ('xyz' or 'yxz'), yaw := 0,
//      recomposed;
//   5. the parent link's orientation gets the same treatment (another IMU's link when the parent
//      carries one, else the forward kinematics of the encoder angles: for link2 that is the
//      yaw-only link1, i.e. "the identity quaternion"), and the joint angle is the rotation angle
//      of the difference quaternion, 2 atan2(|v|, |w|), signed by its component along the joint
//      axis.
// The other joints keep their encoder readings (the yaw joint, because a 6-axis IMU cannot see
// yaw; the gripper, which has no IMU). The belief is the declared model's forward kinematics at
// these angles, with its PPOE covariance. Near the Euler order's gimbal lock (middle angle at
// +-90 deg) the yaw is not separable from the first angle and the fused angle fails, as the paper
// shows for 'xyz' on a horizontal link.
//
// Registered as direct_fusion_xyz and direct_fusion_yxz; no parameters.
#pragma once

#include <memory>

#include "estimators/estimator.h"
#include "estimators/imu/euler.h"

namespace flexbench::estimators {

std::unique_ptr<Estimator> MakeDirectFusion(const EstimatorSetup& setup, imu::EulerOrder order,
                                            const char* name);
std::unique_ptr<Estimator> MakeDirectFusionXyz(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakeDirectFusionYxz(const EstimatorSetup& setup);

}  // namespace flexbench::estimators
