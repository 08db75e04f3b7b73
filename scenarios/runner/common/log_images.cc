#include "scenarios/runner/common/log_images.h"

#include "estimators/error.h"
#include "render/image.h"
#include "scenarios/runner/common/tag_tracking.h"
#include "sim/config.h"

namespace flexbench::scenarios {

int DetectLogImages(const render::DetectorSettings& settings, sim::RecordedLog* log) {
  if (log->images.empty()) return 0;
  const render::TagDetector detector(settings);
  int others = 0;
  for (const sim::LogImage& frame : log->images) {
    const render::Image image = render::ReadPng(frame.path);
    const PinholeCamera& cam = log->cameras[frame.camera].intrinsics;
    if (image.width != cam.width || image.height != cam.height) {
      throw InputError(CapForMessage(frame.path) + ": " + std::to_string(image.width) + " x " +
                       std::to_string(image.height) + " pixels; camera '" +
                       log->cameras[frame.camera].name + "' has " + std::to_string(cam.width) +
                       " x " + std::to_string(cam.height));
    }
    others += AddDetectionsToLog(detector.Detect(image), frame.t, frame.camera, log);
  }
  log->tag_stats = log->image_stats;
  log->tag_stats.rows = static_cast<int>(log->tag_rows.size());
  return others;
}

}  // namespace flexbench::scenarios
