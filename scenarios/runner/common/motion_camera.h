// A fixed camera of the truth that watches a moving arm's AprilTags while its log is simulated
// (closed_loop_dynamic's `tag_camera`): the OSMesa frame rendered at the camera's rate, run
// through libapriltag, and what it finds written as the log's cameras, tags and tags.csv rows,
// as a user's camera would give them.
//
//   tag_camera: {camera: external_camera, rate_hz: 30, pixel_std_px: 1}
//   render: {mode: fast}   detector: {...}    # render_config.h, optional
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "sim/config.h"
#include "sim/recorded_log.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {

struct MotionCameraSpec {
  std::string camera;  // an MJCF camera, and an observed frame of the declared model
  double rate_hz = 30.0;
  double pixel_std_px = 1.0;  // what the log states as each corner's noise
  render::RenderMode mode = render::RenderMode::kQuality;
  render::DetectorSettings detector;
};

// `node`: the tag_camera block; `root`: the scenario (its render and detector blocks).
MotionCameraSpec ParseMotionCamera(const ConfigNode& node, const ConfigNode& root);

class MotionTagCamera {
 public:
  // Textures `truth`'s tags (before any renderer of it is made). The tags kept are those on a
  // frame in `observed` (the declared model's observed frames); InputError naming the camera
  // when the model has no such camera, it is no observed frame, or no tag is on one.
  MotionTagCamera(sim::Simulation& truth, MotionCameraSpec spec,
                  const std::vector<std::string>& observed);
  ~MotionTagCamera();

  // Renders and detects when a camera period has passed since the last frame (the first at the
  // first call): the hook of sim::MotionLogOptions::after_poll.
  void AfterPoll(const sim::Simulation& s);
  // The camera, its tags and every detection so far into `log`; returns the frames rendered.
  int AddTo(sim::RecordedLog* log);
  // Detections of tags on no observed frame (AddTo leaves them out).
  int others() const { return others_; }

 private:
  MotionCameraSpec spec_;
  const mjModel* model_ = nullptr;
  int cam_id_ = -1;
  PinholeCamera intrinsics_;
  std::vector<render::TagInModel> tags_;  // on observed frames
  std::unique_ptr<render::Renderer> renderer_;
  std::unique_ptr<render::TagDetector> detector_;
  render::Image image_;
  double next_t_ = -1.0;
  int frames_ = 0;
  int others_ = 0;
  std::vector<std::pair<double, render::DetectionResult>> seen_;
};

}  // namespace flexbench::scenarios
