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
};

struct TagDetection {
  int id = -1;
  int hamming = 0;
  double decision_margin = 0.0;
  // libapriltag's order (counter-clockwise in the image): tag-frame (-1,+1), (+1,+1), (+1,-1),
  // (-1,-1), x right and y down on the printed tag. Pixel convention of estimators/camera/pinhole.h.
  std::array<Eigen::Vector2d, 4> corners;
  Eigen::Vector2d center;
  // Maps tag coordinates [-1, 1]^2 to pixels (libapriltag's det->H).
  Eigen::Matrix3d homography;
};

struct DetectionResult {
  std::vector<TagDetection> detections;
  int dropped_small = 0;  // detections below min_edge_px
};

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
