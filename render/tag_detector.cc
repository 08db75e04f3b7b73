#include "render/tag_detector.h"

#include <apriltag/apriltag.h>

#include <algorithm>
#include <cmath>

#include "estimators/error.h"
#include "render/apriltag_family.h"

namespace flexbench::render {

struct TagDetector::Impl {
  FamilyPtr family;
  apriltag_detector_t* detector = nullptr;
};

TagDetector::TagDetector(const DetectorSettings& settings)
    : impl_(std::make_unique<Impl>()), settings_(settings) {
  if (!(settings.decimate >= 1.0)) throw InputError("detector.decimate: must be >= 1");
  if (!(settings.sigma >= 0.0)) throw InputError("detector.sigma: must be >= 0");
  if (settings.threads < 1) throw InputError("detector.threads: must be >= 1");
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
  const Image gray = ToGray(image);
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
    if (min_edge < settings_.min_edge_px) {
      ++result.dropped_small;
    } else {
      result.detections.push_back(d);
    }
  }
  apriltag_detections_destroy(found);
  std::sort(result.detections.begin(), result.detections.end(),
            [](const TagDetection& a, const TagDetection& b) { return a.id < b.id; });
  return result;
}

}  // namespace flexbench::render
