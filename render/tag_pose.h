// Tag pose from one detection through libapriltag's estimate_tag_pose (homography
// initialisation, orthogonal iteration, the Schweighofer-Pinz second minimum; the better of the
// two by object-space error), with a guard: libapriltag can return a rotation with det = -1
// (apriltag#181), so the rotation is projected onto SO(3) (det = +1) and the pose is returned
// only when it then reprojects the detected corners within a bound.
//
// Frames (libapriltag's): the camera is the optical frame (x right, y down, z forward); the tag
// frame has its origin at the tag centre, x to the right and y down on the printed tag, z into
// the tag (away from a viewer in front of it). det.corners[k] is the tag point
// (s/2) * ((-1,+1), (+1,+1), (+1,-1), (-1,-1))[k] with s the black border's edge length.
#pragma once

#include <Eigen/Geometry>
#include <array>
#include <optional>

#include "estimators/camera/pinhole.h"
#include "render/tag_detector.h"

namespace flexbench::render {

struct TagPose {
  Eigen::Isometry3d T_cam_tag = Eigen::Isometry3d::Identity();
  double reprojection_rms_px = 0.0;
  double object_error = 0.0;  // libapriltag's object-space error of the chosen candidate
};

// Object-space corners of a tag of edge `size_m`, in TagDetection corner order.
std::array<Eigen::Vector3d, 4> TagObjectCorners(double size_m);

// Nearest rotation matrix (Frobenius) with det = +1: U diag(1, 1, det(U V^T)) V^T.
Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& M);

// The pose of the tag in the camera, or nothing when no candidate reprojects within
// `max_reprojection_rms_px` (or is in front of the camera).
std::optional<TagPose> EstimateTagPose(const TagDetection& det, const PinholeCamera& camera,
                                       double size_m, double max_reprojection_rms_px = 2.0);

}  // namespace flexbench::render
