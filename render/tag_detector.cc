#include "render/tag_detector.h"

#include <apriltag/apriltag.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "estimators/error.h"
#include "render/apriltag_family.h"
#include "render/tag_covariance.h"

namespace flexbench::render {

struct TagDetector::Impl {
  FamilyPtr family;
  apriltag_detector_t* detector = nullptr;
};

void ValidateDetectorSettings(const DetectorSettings& settings) {
  // Upper bounds too: the AprilTag library crashes on a decimation that leaves no image or a
  // blur kernel sized from a huge sigma.
  if (!(settings.decimate >= 1.0 && settings.decimate <= 8.0)) {
    throw InputError("detector.decimate: must be in [1, 8]");
  }
  if (!(settings.sigma >= 0.0 && settings.sigma <= 10.0)) {
    throw InputError("detector.sigma: must be in [0, 10]");
  }
  if (settings.threads < 1 || settings.threads > 64) {
    throw InputError("detector.threads: must be in [1, 64]");
  }
  if (!(settings.min_edge_px >= 0.0 && settings.min_edge_px <= 1e4)) {
    throw InputError("detector.min_edge_px: must be in [0, 10000]");
  }
  if (!(settings.max_view_angle_deg > 0.0 && settings.max_view_angle_deg <= 90.0)) {
    throw InputError("detector.max_view_angle_deg: must be in (0, 90]");
  }
  if (!(settings.border_margin_px >= 0.0 && settings.border_margin_px <= 1e4)) {
    throw InputError("detector.border_margin_px: must be in [0, 10000]");
  }
  if (!(settings.pixel_noise_std >= 0.0 && settings.pixel_noise_std <= 1e3)) {
    throw InputError("detector.pixel_noise_std: must be in [0, 1000]");
  }
  MakeFamily(settings.family, "detector.family");
}

TagDetector::TagDetector(const DetectorSettings& settings)
    : impl_(std::make_unique<Impl>()), settings_(settings) {
  ValidateDetectorSettings(settings);
  impl_->family = MakeFamily(settings.family, "detector.family");
  impl_->detector = apriltag_detector_create();
  apriltag_detector_add_family(impl_->detector, impl_->family.get());
  impl_->detector->quad_decimate = static_cast<float>(settings.decimate);
  impl_->detector->quad_sigma = static_cast<float>(settings.sigma);
  impl_->detector->nthreads = settings.threads;
  impl_->detector->refine_edges = settings.refine_edges ? 1 : 0;
}

TagDetector::~TagDetector() {
  if (impl_->detector) apriltag_detector_destroy(impl_->detector);
}

DetectionResult TagDetector::Detect(const Image& image) const {
  // Gray input is used in place; RGB is converted once.
  Image converted;
  if (image.channels != 1) converted = ToGray(image);
  const Image& gray = image.channels == 1 ? image : converted;
  image_u8_t im{gray.width, gray.height, gray.width, const_cast<uint8_t*>(gray.data.data())};
  zarray_t* found = apriltag_detector_detect(impl_->detector, &im);
  DetectionResult result;
  for (int i = 0; i < zarray_size(found); ++i) {
    apriltag_detection_t* det = nullptr;
    zarray_get(found, i, &det);
    TagDetection d;
    d.id = det->id;
    d.hamming = det->hamming;
    d.decision_margin = det->decision_margin;
    for (int k = 0; k < 4; ++k) d.corners[k] = Eigen::Vector2d(det->p[k][0], det->p[k][1]);
    d.center = Eigen::Vector2d(det->c[0], det->c[1]);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) d.homography(r, c) = MATD_EL(det->H, r, c);
    }
    double min_edge = INFINITY;
    for (int k = 0; k < 4; ++k) {
      min_edge = std::min(min_edge, (d.corners[(k + 1) % 4] - d.corners[k]).norm());
    }
    d.view_angle_deg = ViewAngleFromHomography(d.homography);
    bool near_border = false;
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d& p = d.corners[k];
      const double m = settings_.border_margin_px;
      near_border = near_border || p.x() < m || p.y() < m || p.x() > gray.width - m ||
                    p.y() > gray.height - m;
    }
    if (min_edge < settings_.min_edge_px) {
      ++result.dropped_small;
    } else if (d.view_angle_deg > settings_.max_view_angle_deg) {
      ++result.dropped_grazing;
    } else if (settings_.border_margin_px > 0.0 && near_border) {
      ++result.dropped_border;
    } else {
      const TagCovariance cov = EstimateTagCovariance(gray, d, settings_.pixel_noise_std);
      d.corners_cov = cov.corners;
      d.center_cov = cov.center;
      result.detections.push_back(d);
    }
  }
  apriltag_detections_destroy(found);
  std::sort(result.detections.begin(), result.detections.end(),
            [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  return result;
}

double ViewAngleFromHomography(const Eigen::Matrix3d& H) {
  // d/d(x, y) of (H [x y 1]^T) dehomogenised, at (0, 0).
  const double w = H(2, 2);
  Eigen::Matrix2d J;
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) J(r, c) = (H(r, c) * w - H(r, 2) * H(2, c)) / (w * w);
  }
  const Eigen::Vector2d sv = Eigen::JacobiSVD<Eigen::Matrix2d>(J).singularValues();
  if (!(sv[0] > 0.0)) return 90.0;
  return std::acos(std::clamp(sv[1] / sv[0], 0.0, 1.0)) * 180.0 / M_PI;
}

}  // namespace flexbench::render
