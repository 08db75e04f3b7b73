// MuJoCo cameras as pinhole cameras: intrinsics from the MJCF (fovy, offscreen resolution) and
// the true pose of the optical frame.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Geometry>

#include "estimators/camera/pinhole.h"

namespace flexbench::sim {

// Intrinsics of MJCF camera `cam_id` for the model's offscreen frame size (visual/global
// offwidth, offheight). MuJoCo renders with square pixels and the principal point at the image
// centre, which is (W/2, H/2) in the pixel convention of estimators/camera/pinhole.h.
PinholeCamera CameraIntrinsics(const mjModel* m, int cam_id);

// Pose of the optical frame (x right, y down, z forward) in the world, after mj_kinematics /
// mj_forward. MuJoCo's camera frame has y up and looks along -z.
Eigen::Isometry3d WorldFromOptical(const mjData* d, int cam_id);

}  // namespace flexbench::sim
