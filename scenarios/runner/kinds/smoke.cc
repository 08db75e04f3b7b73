// The smoke scenario: load an arm, set a configuration, render one frame offscreen, detect the
// end-effector tag with libapriltag and compare its corners with the true corners projected
// through the camera's intrinsics and the ground-truth poses.
#include <cmath>
#include <fstream>
#include <map>

#include "estimators/camera/pinhole.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "scenarios/runner/common/render_config.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"

namespace flexbench::scenarios {
namespace {

class SmokeKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    const ConfigNode model = root.Child("model");
    model_path_ = model.ResolvePath(model.AsString());
    camera_ = root.GetString("camera");
    if (const auto cfg = root.Optional("configuration")) {
      for (const std::string& joint : cfg->Keys()) {
        const ConfigNode value = cfg->Child(joint);
        const double angle = value.AsDouble();
        // The calibration CSV's joint range (rad, or m for slides): beyond it the pose
        // overflows and every metric is NaN.
        if (std::abs(angle) > 1e3) value.Fail("out of range (|value| <= 1000)");
        configuration_.emplace_back(joint, angle);
      }
    }
    mode_ = ParseRenderMode(root, render::RenderMode::kQuality);
    detector_ = ParseDetectorSettings(root);
    // Load now: a model MuJoCo rejects, a missing camera or joint is bad input, found before
    // any output is created.
    model_ = sim::LoadModel(model_path_);
    camera_id_ = sim::CameraId(model_.get(), camera_, model_path_);
    for (const auto& [joint, angle] : configuration_) {
      sim::JointId(model_.get(), joint, model_path_);
    }
    tags_ = render::ApplyTagTextures(model_.get());
    if (tags_.empty()) throw InputError(model_path_ + ": the model has no AprilTag texture");
    detector_instance_ = std::make_unique<render::TagDetector>(detector_);
  }

  void Run(RunContext& ctx) override {
    mjModel* m = model_.get();
    sim::MjDataPtr data = sim::MakeData(m);
    mjData* d = data.get();
    for (const auto& [joint, angle] : configuration_) {
      d->qpos[m->jnt_qposadr[sim::JointId(m, joint)]] = angle;
    }
    mj_forward(m, d);

    render::Renderer renderer(m, mode_);
    ctx.log("GL_RENDERER: " + renderer.gl_renderer());
    const render::Image frame = renderer.RenderRgb(d, camera_id_);
    render::WritePng(frame, (ctx.out->FramesDir() / "smoke.png").string());

    const render::DetectionResult result = detector_instance_->Detect(frame);
    const PinholeCamera cam = sim::CameraIntrinsics(m, camera_id_);
    const Eigen::Isometry3d T_cam_w = sim::WorldFromOptical(d, camera_id_).inverse();

    std::ofstream csv(ctx.out->File("corners.csv"));
    csv << "tag_id,corner,u_detected_px,v_detected_px,u_true_px,v_true_px,error_px\n";
    double sum_sq = 0.0;
    int n_corners = 0;
    int detections = 0;
    for (const render::TagDetection& det : result.detections) {
      const render::TagInModel* tag = nullptr;
      for (const auto& t : tags_) {
        if (t.id == det.id && t.family == detector_.family) tag = &t;
      }
      if (!tag) continue;  // a decode of something that is not in the model
      ++detections;
      const auto corners_w = render::TagCornersWorld(d, *tag);
      for (int k = 0; k < 4; ++k) {
        Eigen::Vector2d uv;
        if (!cam.Project(T_cam_w * corners_w[k], &uv)) continue;
        const double err = (det.corners[k] - uv).norm();
        sum_sq += err * err;
        ++n_corners;
        char line[256];
        std::snprintf(line, sizeof(line), "%d,%d,%.6f,%.6f,%.6f,%.6f,%.6f\n", det.id, k,
                      det.corners[k].x(), det.corners[k].y(), uv.x(), uv.y(), err);
        csv << line;
      }
    }
    Json& metrics = (*ctx.summary)["metrics"];
    metrics["detections"] = detections;
    metrics["tags_in_model"] = static_cast<int>(tags_.size());
    metrics["dropped_small"] = result.dropped_small;
    metrics["corner_rmse_px"] = n_corners > 0 ? Json(std::sqrt(sum_sq / n_corners)) : Json();
    metrics["frame_width_px"] = frame.width;
    metrics["frame_height_px"] = frame.height;
  }

 private:
  std::string model_path_;
  std::string camera_;
  std::vector<std::pair<std::string, double>> configuration_;
  render::RenderMode mode_ = render::RenderMode::kQuality;
  render::DetectorSettings detector_;
  sim::MjModelPtr model_;
  int camera_id_ = -1;
  std::vector<render::TagInModel> tags_;
  std::unique_ptr<render::TagDetector> detector_instance_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeSmokeKind() { return std::make_unique<SmokeKind>(); }

}  // namespace flexbench::scenarios
