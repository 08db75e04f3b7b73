#include "scenarios/runner/common/motion_camera.h"

#include <algorithm>
#include <map>

#include "estimators/error.h"
#include "scenarios/runner/common/render_config.h"
#include "scenarios/runner/common/tag_tracking.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"

namespace flexbench::scenarios {

MotionCameraSpec ParseMotionCamera(const ConfigNode& node, const ConfigNode& root) {
  MotionCameraSpec s;
  s.camera = node.GetString("camera");
  s.rate_hz = node.GetDouble("rate_hz", s.rate_hz);
  if (!(s.rate_hz > 0.0 && s.rate_hz <= 1000.0)) node.Child("rate_hz").Fail("must be in (0, 1000]");
  s.pixel_std_px = node.GetDouble("pixel_std_px", s.pixel_std_px);
  if (!(s.pixel_std_px > 0.0 && s.pixel_std_px <= 100.0)) {
    node.Child("pixel_std_px").Fail("must be > 0 and at most 100");
  }
  s.mode = ParseRenderMode(root, s.mode);
  s.detector = ParseDetectorSettings(root);
  return s;
}

MotionTagCamera::MotionTagCamera(sim::Simulation& truth, MotionCameraSpec spec,
                                 const std::vector<std::string>& observed)
    : spec_(std::move(spec)), model_(truth.model()) {
  cam_id_ = sim::CameraId(model_, spec_.camera, truth.model_name());
  if (std::find(observed.begin(), observed.end(), spec_.camera) == observed.end()) {
    throw InputError("tag_camera '" + spec_.camera +
                     "' is no observed frame of the declared model (its optical frame is)");
  }
  intrinsics_ = sim::CameraIntrinsics(model_, cam_id_);
  for (const render::TagInModel& t : render::ApplyTagTextures(truth.mutable_model())) {
    const std::string geom = sim::ObjectName(model_, mjOBJ_GEOM, t.geom_id);
    if (std::find(observed.begin(), observed.end(), geom) != observed.end()) tags_.push_back(t);
  }
  if (tags_.empty()) {
    throw InputError("tag_camera '" + spec_.camera +
                     "': no tag of the model is on an observed frame of the declared model");
  }
}

MotionTagCamera::~MotionTagCamera() = default;

void MotionTagCamera::AfterPoll(const sim::Simulation& s) {
  if (next_t_ >= 0.0 && s.time() < next_t_ - 1e-9) return;
  if (!renderer_) {
    renderer_ = std::make_unique<render::Renderer>(model_, spec_.mode);
    detector_ = std::make_unique<render::TagDetector>(spec_.detector);
  }
  // On the camera's own clock; a rate above the step rate renders at every step.
  next_t_ = (next_t_ < 0.0 ? s.time() : next_t_) + 1.0 / spec_.rate_hz;
  if (next_t_ <= s.time()) next_t_ = s.time() + 1.0 / spec_.rate_hz;
  // The body poses of this state: after a step MuJoCo's are still the step's start's until
  // something asks for them.
  s.Pose(sim::FrameRef{sim::FrameType::kCamera, cam_id_, spec_.camera});
  renderer_->RenderRgbInto(const_cast<mjData*>(s.data()), cam_id_, &image_);
  seen_.emplace_back(s.time(), detector_->Detect(image_));
  ++frames_;
}

int MotionTagCamera::AddTo(sim::RecordedLog* log) {
  std::map<int, kinematics::FrameId> on_observed;
  for (const render::TagInModel& t : tags_) on_observed[t.id] = kinematics::FrameId{};
  AddTagCameraToLog(model_, spec_.camera, intrinsics_, tags_, on_observed, spec_.pixel_std_px,
                    /*centres=*/false, log);
  const int camera = static_cast<int>(log->cameras.size()) - 1;
  for (const auto& [t, det] : seen_) others_ += AddDetectionsToLog(det, t, camera, log);
  return frames_;
}

}  // namespace flexbench::scenarios
