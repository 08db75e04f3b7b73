#include "sim/camera.h"

#include <cmath>

#include "estimators/conventions.h"

namespace flexbench::sim {

PinholeCamera CameraIntrinsics(const mjModel* m, int cam_id) {
  PinholeCamera c;
  c.width = m->vis.global.offwidth;
  c.height = m->vis.global.offheight;
  const double fovy = m->cam_fovy[cam_id] * M_PI / 180.0;
  c.fy = 0.5 * c.height / std::tan(0.5 * fovy);
  c.fx = c.fy;
  c.cx = 0.5 * c.width;
  c.cy = 0.5 * c.height;
  return c;
}

Eigen::Isometry3d WorldFromOptical(const mjData* d, int cam_id) {
  const Mat3 R_w_mjcam = RotFromRowMajor(d->cam_xmat + 9 * cam_id);
  const Mat3 R_mjcam_optical = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  Eigen::Isometry3d T_w_cam = Eigen::Isometry3d::Identity();
  T_w_cam.linear() = R_w_mjcam * R_mjcam_optical;
  T_w_cam.translation() = Eigen::Map<const Eigen::Vector3d>(d->cam_xpos + 3 * cam_id);
  return T_w_cam;
}

}  // namespace flexbench::sim
