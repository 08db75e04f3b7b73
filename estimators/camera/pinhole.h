// Pinhole camera model shared by the renderer's ground truth and the estimators' measurement
// models ([PPOE eq. 25]: u = f * p / z + c).
//
// Pixel coordinates follow libapriltag 3.3: the top-left pixel covers [0,1] x [0,1], so its
// centre is (0.5, 0.5); u to the right, v down. (Measured: rendered tags projected with the
// centre-at-0 convention were off by +0.5 px in u and v. OpenCV puts pixel centres at integers:
// subtract 0.5 at that boundary.) The camera frame is the optical frame: x right, y down, z
// forward. (MuJoCo cameras look along -z with y up; sim/render converts at the boundary.)
#pragma once

#include <Eigen/Core>

namespace flexbench {

struct PinholeCamera {
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  int width = 0;
  int height = 0;

  // Projects a point in the optical frame. Returns false when it is behind the camera.
  bool Project(const Eigen::Vector3d& p_cam, Eigen::Vector2d* uv) const {
    if (p_cam.z() <= 1e-9) return false;
    (*uv) << fx * p_cam.x() / p_cam.z() + cx, fy * p_cam.y() / p_cam.z() + cy;
    return true;
  }

  // Whether uv falls on the sensor: [0, width] x [0, height] in the convention above (the
  // outer edges of the border pixels), not the pixel centres' [-0.5, width - 0.5] of OpenCV's.
  bool InImage(const Eigen::Vector2d& uv) const {
    return uv.x() >= 0.0 && uv.y() >= 0.0 && uv.x() <= width && uv.y() <= height;
  }
};

}  // namespace flexbench
