// AprilTag detection through libapriltag.
#pragma once

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "render/image.h"

namespace flexbench::render {

struct DetectorSettings {
  std::string family = "tag36h11";
  double decimate = 1.0;  // quad_decimate: >1 is faster, less precise
  double sigma = 0.0;     // quad_sigma: Gaussian blur before quad detection
  int threads = 1;
  bool refine_edges = true;
  // Detections whose shortest edge is below this many pixels are dropped and counted: tiny tags
  // decode but their corners are unreliable.
  double min_edge_px = 0.0;
  // Grazing-view gate: a detection seen more obliquely than this is dropped and counted.
  // libapriltag still decodes tags at 78-85 deg, with corner errors of 1-8 px (a wrong pose).
  // The angle is estimated from the homography alone (no intrinsics): the ratio of the singular
  // values of its Jacobian at the tag centre is cos(view angle) for a weak-perspective view,
  // whatever the in-plane rotation (near 0 deg the estimate is coarse: acos is steep at 1, so
  // 0.1 px of corner noise reads as a few degrees; at 60-85 deg it is within about a degree).
  // 90 keeps every detection.
  double max_view_angle_deg = 90.0;
  // Visibility gate: a detection with a corner closer than this to the image border (a tag
  // partly outside the frame) is dropped and counted. 0 keeps every detection.
  double border_margin_px = 0.0;
  // Standard deviation of the pixel noise of the detector's gray input (gray levels), for the
  // corner and centre covariances (render/tag_covariance.h). 0 for a clean render.
  double pixel_noise_std = 0.0;
};

struct TagDetection {
  int id = -1;
  int hamming = 0;
  double decision_margin = 0.0;
  // libapriltag's order (counter-clockwise in the image): tag-frame (-1,+1), (+1,+1), (+1,-1),
  // (-1,-1), x right and y down on the printed tag. Pixel convention of
  // estimators/camera/pinhole.h.
  std::array<Eigen::Vector2d, 4> corners;
  Eigen::Vector2d center;
  // Maps tag coordinates [-1, 1]^2 to pixels (libapriltag's det->H).
  Eigen::Matrix3d homography;
  // Covariances (pixels^2) from the pixel-noise model of render/tag_covariance.h: the four
  // corners stacked (u0, v0, ..., u3, v3), and the centre.
  Eigen::Matrix<double, 8, 8> corners_cov = Eigen::Matrix<double, 8, 8>::Zero();
  Eigen::Matrix2d center_cov = Eigen::Matrix2d::Zero();
  // View angle estimated from the homography (see DetectorSettings::max_view_angle_deg).
  double view_angle_deg = 0.0;

  Eigen::Matrix2d CornerCov(int k) const { return corners_cov.block<2, 2>(2 * k, 2 * k); }
};

struct DetectionResult {
  std::vector<TagDetection> detections;
  int dropped_small = 0;    // detections below min_edge_px
  int dropped_grazing = 0;  // detections beyond max_view_angle_deg
  int dropped_border = 0;   // detections within border_margin_px of the image border

  int dropped() const { return dropped_small + dropped_grazing + dropped_border; }
};

// The view angle (deg) of a tag from its homography (tag [-1, 1]^2 -> pixels): acos of the
// ratio of the singular values of the homography's Jacobian at the tag centre.
double ViewAngleFromHomography(const Eigen::Matrix3d& H);

// Throws InputError "detector.<key>: ..." for a setting libapriltag cannot take (ranges, family).
void ValidateDetectorSettings(const DetectorSettings& settings);

class TagDetector {
 public:
  // Throws InputError for an unknown family or bad parameters.
  explicit TagDetector(const DetectorSettings& settings);
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;

  // `image` may be gray or RGB. Detections are sorted by id.
  DetectionResult Detect(const Image& image) const;

  const DetectorSettings& settings() const { return settings_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  DetectorSettings settings_;
};

}  // namespace flexbench::render
