#include "render/tag_pose.h"

#include <apriltag/apriltag.h>
#include <apriltag/apriltag_pose.h>
#include <apriltag/common/matd.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace flexbench::render {
namespace {

double ReprojectionRms(const Eigen::Matrix3d& R, const Eigen::Vector3d& t, const TagDetection& det,
                       const PinholeCamera& camera, double size_m) {
  const auto object = TagObjectCorners(size_m);
  double sum = 0.0;
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector2d uv;
    if (!camera.Project(R * object[k] + t, &uv)) return std::numeric_limits<double>::infinity();
    sum += (uv - det.corners[k]).squaredNorm();
  }
  return std::sqrt(sum / 4.0);
}

// Debian's libapriltag 3.3 exports estimate_tag_pose but not the matd_* helpers, so matrices
// are allocated here the way matd_create does (header + row-major data, calloc) and released
// with free, which is all matd_destroy does.
matd_t* NewMatd(unsigned rows, unsigned cols) {
  auto* m = static_cast<matd_t*>(std::calloc(1, sizeof(matd_t) + rows * cols * sizeof(double)));
  m->nrows = rows;
  m->ncols = cols;
  return m;
}

}  // namespace

std::array<Eigen::Vector3d, 4> TagObjectCorners(double size_m) {
  const double h = 0.5 * size_m;
  return {Eigen::Vector3d(-h, h, 0), Eigen::Vector3d(h, h, 0), Eigen::Vector3d(h, -h, 0),
          Eigen::Vector3d(-h, -h, 0)};
}

Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& M) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

std::optional<TagPose> EstimateTagPose(const TagDetection& det, const PinholeCamera& camera,
                                       double size_m, double max_reprojection_rms_px) {
  apriltag_detection_t raw{};
  raw.id = det.id;
  raw.hamming = det.hamming;
  raw.decision_margin = static_cast<float>(det.decision_margin);
  raw.H = NewMatd(3, 3);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) MATD_EL(raw.H, r, c) = det.homography(r, c);
  }
  for (int k = 0; k < 4; ++k) {
    raw.p[k][0] = det.corners[k].x();
    raw.p[k][1] = det.corners[k].y();
  }
  raw.c[0] = det.center.x();
  raw.c[1] = det.center.y();
  apriltag_detection_info_t info{&raw, size_m, camera.fx, camera.fy, camera.cx, camera.cy};

  // The better of libapriltag's two candidates (homography + orthogonal iteration, and the
  // Schweighofer-Pinz second minimum), by object-space error.
  apriltag_pose_t pose{nullptr, nullptr};
  const double err = estimate_tag_pose(&info, &pose);

  std::optional<TagPose> best;
  if (pose.R && pose.t) {
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = MATD_EL(pose.R, r, c);
      t[r] = MATD_EL(pose.t, r, 0);
    }
    if (R.allFinite() && t.allFinite() && t.z() > 0.0) {
      // apriltag#181: the rotation may be a reflection (det -1) or drift off SO(3).
      R = ProjectToRotation(R);
      const double rms = ReprojectionRms(R, t, det, camera, size_m);
      if (rms <= max_reprojection_rms_px) {
        TagPose p;
        p.T_cam_tag.linear() = R;
        p.T_cam_tag.translation() = t;
        p.reprojection_rms_px = rms;
        p.object_error = err;
        best = p;
      }
    }
  }
  std::free(pose.R);
  std::free(pose.t);
  std::free(raw.H);
  return best;
}

}  // namespace flexbench::render
