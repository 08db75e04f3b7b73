// Tag detection sweep: one AprilTag on a mocap board in front of an MJCF camera, swept over
// distance, out-of-plane view angle and in-plane rotation. Every frame is rendered offscreen,
// degraded (seeded), detected by libapriltag and compared with the tag's true corners projected
// through the camera's intrinsics and true poses.
//
// Outputs: sweep.csv (one row per frame: geometry, detected or why not, corner error in px,
// corner NEES from the detector's covariance, pose error), sweep.png (detection rate and corner
// RMSE against pixels per tag cell and against view angle), frames/*.png (a few frames with
// truth, detection, covariance ellipses and the estimated tag frame drawn on them).
// Metrics: detection_rate_frontal and corner_rmse_px_frontal over frontal views (view angle 0)
// with the tag at least `frontal_min_width_px` wide; wrong_detections counts detections with a
// wrong id or corners off by more than `wrong_corner_px` (the "never a wrong pose" check).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <random>

#include "estimators/camera/pinhole.h"
#include "estimators/conventions.h"
#include "render/camera_stream.h"
#include "render/degrade.h"
#include "render/overlay.h"
#include "render/plot.h"
#include "render/renderer.h"
#include "render/tag_covariance.h"
#include "render/tag_detector.h"
#include "render/tag_pose.h"
#include "render/tag_texture.h"
#include "scenarios/runner/common/render_config.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"

namespace flexbench::scenarios {
namespace {

struct FrameRow {
  int frame = 0;
  double distance_m = 0.0;
  double view_deg = 0.0;
  double rotation_deg = 0.0;
  double width_px = 0.0;
  double px_per_cell = 0.0;
  bool detected = false;
  std::string status;  // detected, missing, small, grazing, border, wrong
  double corner_rmse_px = NAN;
  double center_err_px = NAN;
  double corner_nees = NAN;  // mean over the four corners of e^T S^-1 e (2 dof each)
  double est_view_deg = NAN;
  double decision_margin = NAN;
  double pose_rot_err_deg = NAN;
  double pose_pos_err_mm = NAN;
  double pose_det = NAN;
};

std::vector<double> PositiveList(const ConfigNode& parent, const std::string& key, bool allow_zero,
                                 double max) {
  const ConfigNode node = parent.Child(key);
  const std::vector<double> v = node.AsDoubleList();
  if (v.empty()) node.Fail("must list at least one value");
  for (double x : v) {
    if (!std::isfinite(x) || x < 0.0 || (!allow_zero && x == 0.0) || x > max) {
      node.Fail("values must be in " + std::string(allow_zero ? "[0, " : "(0, ") +
                std::to_string(max) + "]");
    }
  }
  return v;
}

class TagDetectionSweepKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    const ConfigNode model = root.Child("model");
    model_path_ = model.ResolvePath(model.AsString());
    camera_ = root.GetString("camera");
    board_body_ = root.GetString("board_body");
    mode_ = ParseRenderMode(root, render::RenderMode::kFast);
    detector_ = ParseDetectorSettings(root);
    if (const auto g = root.Optional("degradation")) {
      degradation_.noise_std = g->GetDouble("noise_std", 0.0);
      degradation_.blur_sigma_px = g->GetDouble("blur_sigma_px", 0.0);
      degradation_.gain = g->GetDouble("gain", 1.0);
      degradation_.offset = g->GetDouble("offset", 0.0);
      degradation_.occlusion_probability = g->GetDouble("occlusion_probability", 0.0);
      degradation_.occlusion_size_px = g->GetDouble("occlusion_size_px", 0.0);
      render::ValidateDegradation(degradation_, g->WhereKey());
    }
    const ConfigNode sweep = root.Child("sweep");
    distances_ = PositiveList(sweep, "distances_m", false, 100.0);
    views_ = PositiveList(sweep, "view_angles_deg", true, 89.0);
    rotations_ = PositiveList(sweep, "rotations_deg", true, 360.0);
    frames_per_pose_ = sweep.GetInt("frames_per_pose", 1);
    if (frames_per_pose_ < 1) sweep.Child("frames_per_pose").Fail("must be >= 1");
    if (const auto j = sweep.Optional("jitter")) {
      jitter_pos_m_ = j->GetDouble("position_m", 0.0);
      jitter_angle_deg_ = j->GetDouble("angle_deg", 0.0);
      if (jitter_pos_m_ < 0.0 || jitter_angle_deg_ < 0.0) j->Fail("jitter must be >= 0");
    }
    frontal_min_width_px_ = root.GetDouble("frontal_min_width_px", 60.0);
    wrong_corner_px_ = root.GetDouble("wrong_corner_px", 1.5);
    saved_frames_ = root.GetInt("saved_frames", 6);
    if (saved_frames_ < 0) root.Child("saved_frames").Fail("must be >= 0");

    // Load now: every bad-input case fails before any output exists.
    model_ = sim::LoadModel(model_path_);
    if (model_->ncam == 0) {
      throw InputError(model_path_ +
                       ": the model has no camera; the sweep renders from an "
                       "MJCF <camera>");
    }
    camera_id_ = sim::CameraId(model_.get(), camera_, model_path_);
    const int body = sim::BodyId(model_.get(), board_body_, model_path_);
    mocap_id_ = model_->body_mocapid[body];
    if (mocap_id_ < 0) {
      throw InputError(model_path_ + ": body '" + board_body_ +
                       "' (board_body) must be a mocap body (mocap=\"true\")");
    }
    tags_ = render::ApplyTagTextures(model_.get());
    for (const auto& t : tags_) {
      if (t.family == detector_.family) tag_ = t;
    }
    if (tag_.id < 0) {
      throw InputError(model_path_ + ": the model has no AprilTag of family " + detector_.family);
    }
    detector_instance_ = std::make_unique<render::TagDetector>(detector_);
  }

  // Per frame: place the board -> project the true corners -> capture and detect -> score.
  void Run(RunContext& ctx) override {
    sim::MjDataPtr data = sim::MakeData(model_.get());
    mj_forward(model_.get(), data.get());
    const View v = MakeView(data.get());
    render::Renderer renderer(model_.get(), mode_);
    ctx.log("GL_RENDERER: " + renderer.gl_renderer());
    // The sweep is not a dynamic simulation: frame k is taken at t = k / rate, so the stream's
    // clock stamps frames as a camera at `kRate` would.
    constexpr double kRate = 30.0;
    render::CameraStream stream(&renderer, camera_id_, kRate, degradation_, ctx.seed);
    std::mt19937_64 jitter_rng(ctx.seed ^ 0x9e3779b97f4a7c15ULL);
    const int total =
        static_cast<int>(distances_.size() * views_.size() * rotations_.size()) * frames_per_pose_;
    std::vector<FrameRow> rows;
    rows.reserve(total);
    int frame = 0;
    for (double distance : distances_) {
      for (double view : views_) {
        for (double rotation : rotations_) {
          for (int rep = 0; rep < frames_per_pose_; ++rep, ++frame) {
            PlaceBoard(v, distance, view, rotation, &jitter_rng, data.get());
            FrameRow row;
            row.frame = frame;
            row.distance_m = distance;
            row.view_deg = view;
            row.rotation_deg = rotation;
            const TagTruth truth = ProjectTruth(v, data.get(), &row);
            const render::PixelRect roi = BoundingBox(truth.px, v.cam);
            const render::CameraFrame shot =
                stream.Capture(data.get(), static_cast<double>(frame) / kRate, &roi);
            const render::DetectionResult result = Detect(shot);
            const render::TagDetection* det = Score(result, truth, v, &row);
            rows.push_back(row);
            if (WritesFrame(ctx.frames, frame, total, saved_frames_)) {
              SaveOverlay(ctx, shot.rgb, row, truth.px, det, v.cam);
            }
            ctx.progress("frames", frame + 1, total);
          }
        }
      }
    }
    WriteCsv(ctx, rows);
    WritePlot(ctx, rows);
    FillMetrics(ctx, rows);
  }

 private:
  // The fixed camera, and the board's pose at view 0, rotation 0.
  struct View {
    Eigen::Isometry3d T_w_cam, T_cam_w;
    PinholeCamera cam;
    // The board frame in the optical frame at view 0, rotation 0: the tag faces the camera,
    // printed x to the right and printed y down in the image (body +z towards the camera).
    Mat3 R_cam_board0 = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
    Eigen::Vector3d tag_center_geom;
  };

  View MakeView(const mjData* d) const {
    View v;
    v.T_w_cam = sim::WorldFromOptical(d, camera_id_);
    v.T_cam_w = v.T_w_cam.inverse();
    v.cam = sim::CameraIntrinsics(model_.get(), camera_id_);
    v.tag_center_geom = 0.25 * (tag_.corners_geom[0] + tag_.corners_geom[1] + tag_.corners_geom[2] +
                                tag_.corners_geom[3]);
    return v;
  }

  // The board at this pose plus jitter, the tag's centre (not the board origin) on the optical
  // axis; the mocap body moved and the model forwarded.
  void PlaceBoard(const View& v, double distance, double view, double rotation,
                  std::mt19937_64* rng, mjData* d) const {
    const mjModel* m = model_.get();
    const double jx = jitter_pos_m_ * (2 * render::Uniform01(*rng) - 1);
    const double jy = jitter_pos_m_ * (2 * render::Uniform01(*rng) - 1);
    const double jv = jitter_angle_deg_ * (2 * render::Uniform01(*rng) - 1);
    const double jr = jitter_angle_deg_ * (2 * render::Uniform01(*rng) - 1);
    const Mat3 R_cam_board =
        v.R_cam_board0 *
        Eigen::AngleAxisd((view + jv) * M_PI / 180, Eigen::Vector3d::UnitY()).matrix() *
        Eigen::AngleAxisd((rotation + jr) * M_PI / 180, Eigen::Vector3d::UnitZ()).matrix();
    const Mat3 R_board_geom = GeomInBody(m);
    const Eigen::Vector3d p_center_board = R_board_geom * v.tag_center_geom + GeomPosInBody(m);
    const Eigen::Vector3d p_cam_board =
        Eigen::Vector3d(jx, jy, distance) - R_cam_board * p_center_board;
    const Eigen::Vector3d p_w = v.T_w_cam * p_cam_board;
    const Quat q_w(v.T_w_cam.linear() * R_cam_board);
    for (int i = 0; i < 3; ++i) d->mocap_pos[3 * mocap_id_ + i] = p_w[i];
    QuatToWxyz(q_w.normalized(), d->mocap_quat + 4 * mocap_id_);
    mj_forward(m, d);
  }

  // The tag's true corners: in the world, the camera and the image.
  struct TagTruth {
    std::array<Eigen::Vector3d, 4> corners_w, corners_cam;
    std::array<Eigen::Vector2d, 4> px;
    bool visible = true;
  };

  // The true corners, and the row's apparent size (mean edge, pixels per cell).
  TagTruth ProjectTruth(const View& v, const mjData* d, FrameRow* row) const {
    TagTruth t;
    t.corners_w = render::TagCornersWorld(d, tag_);
    for (int k = 0; k < 4; ++k) {
      t.corners_cam[k] = v.T_cam_w * t.corners_w[k];
      t.visible = v.cam.Project(t.corners_cam[k], &t.px[k]) && t.visible;
    }
    double edge_sum = 0.0;
    for (int k = 0; k < 4; ++k) edge_sum += (t.px[(k + 1) % 4] - t.px[k]).norm();
    row->width_px = edge_sum / 4;
    const double area = 0.5 * std::abs((t.px[2] - t.px[0]).x() * (t.px[3] - t.px[1]).y() -
                                       (t.px[2] - t.px[0]).y() * (t.px[3] - t.px[1]).x());
    row->px_per_cell = std::sqrt(area) / tag_.border_cells;
    return t;
  }

  // The row's status and errors from what the detector returned; the tag's detection or null.
  const render::TagDetection* Score(const render::DetectionResult& result, const TagTruth& t,
                                    const View& v, FrameRow* row) {
    const render::TagDetection* det = nullptr;
    int wrong = 0;
    for (const auto& dd : result.detections) {
      if (dd.id == tag_.id) {
        det = &dd;
      } else {
        ++wrong;  // a decode that is not the tag in view
      }
    }
    if (det && t.visible) {
      ScoreDetection(*det, t, v, row);
    } else {
      row->status = result.dropped_small > 0     ? "small"
                    : result.dropped_grazing > 0 ? "grazing"
                    : result.dropped_border > 0  ? "border"
                                                 : "missing";
    }
    if (wrong > 0) row->status = "wrong";
    wrong_ids_ += wrong;
    dropped_small_ += result.dropped_small;
    dropped_grazing_ += result.dropped_grazing;
    dropped_border_ += result.dropped_border;
    return det;
  }

  // Corner error and NEES, centre error, and the tag pose's error from the detection.
  void ScoreDetection(const render::TagDetection& det, const TagTruth& t, const View& v,
                      FrameRow* row) const {
    double sq = 0.0;
    double nees = 0.0;
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector2d e = det.corners[k] - t.px[k];
      sq += e.squaredNorm();
      nees += render::Mahalanobis2(e, det.CornerCov(k));
    }
    row->corner_rmse_px = std::sqrt(sq / 4);
    row->corner_nees = nees / 4;
    Eigen::Vector2d c_true;
    v.cam.Project(
        v.T_cam_w * (0.25 * (t.corners_w[0] + t.corners_w[1] + t.corners_w[2] + t.corners_w[3])),
        &c_true);
    row->center_err_px = (det.center - c_true).norm();
    row->est_view_deg = det.view_angle_deg;
    row->decision_margin = det.decision_margin;
    if (const auto pose = render::EstimateTagPose(det, v.cam, tag_.size_m)) {
      const Eigen::Isometry3d T_true = TrueTagPose(t.corners_cam);
      const Eigen::AngleAxisd dR(T_true.linear().transpose() * pose->T_cam_tag.linear());
      row->pose_rot_err_deg = std::abs(dR.angle()) * 180 / M_PI;
      row->pose_pos_err_mm = 1000 * (pose->T_cam_tag.translation() - T_true.translation()).norm();
      row->pose_det = pose->T_cam_tag.linear().determinant();
    }
    row->detected = row->corner_rmse_px <= wrong_corner_px_;
    row->status = row->detected ? "detected" : "wrong";
  }

  render::DetectionResult Detect(const render::CameraFrame& shot) {
    render::DetectorSettings s = detector_;
    s.pixel_noise_std = shot.gray_noise_std;
    if (!noisy_detector_ || noisy_detector_->settings().pixel_noise_std != s.pixel_noise_std) {
      noisy_detector_ = std::make_unique<render::TagDetector>(s);
    }
    return noisy_detector_->Detect(shot.gray);
  }

  // Orientation and position of the tag geom in its body (the board).
  Mat3 GeomInBody(const mjModel* m) const {
    return QuatFromWxyz(m->geom_quat + 4 * tag_.geom_id).toRotationMatrix();
  }
  Eigen::Vector3d GeomPosInBody(const mjModel* m) const {
    return Eigen::Map<const Eigen::Vector3d>(m->geom_pos + 3 * tag_.geom_id);
  }

  // The true pose of libapriltag's tag frame (render/tag_pose.h) in the camera: the rigid
  // transform taking the object corners onto the true corners (Kabsch / Umeyama, no scale).
  Eigen::Isometry3d TrueTagPose(const std::array<Eigen::Vector3d, 4>& corners_cam) const {
    const auto object = render::TagObjectCorners(tag_.size_m);
    Eigen::Matrix<double, 3, 4> src;
    Eigen::Matrix<double, 3, 4> dst;
    for (int k = 0; k < 4; ++k) {
      src.col(k) = object[k];
      dst.col(k) = corners_cam[k];
    }
    Eigen::Isometry3d T;
    T.matrix() = Eigen::umeyama(src, dst, false);
    return T;
  }

  static render::PixelRect BoundingBox(const std::array<Eigen::Vector2d, 4>& p,
                                       const PinholeCamera& cam) {
    double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
    for (const auto& q : p) {
      x0 = std::min(x0, q.x());
      y0 = std::min(y0, q.y());
      x1 = std::max(x1, q.x());
      y1 = std::max(y1, q.y());
    }
    const auto clampi = [](double v, int hi) {
      return static_cast<int>(std::clamp(v, 0.0, static_cast<double>(hi)));
    };
    return {clampi(x0, cam.width), clampi(y0, cam.height), clampi(x1, cam.width),
            clampi(y1, cam.height)};
  }

  void SaveOverlay(RunContext& ctx, render::Image image, const FrameRow& row,
                   const std::array<Eigen::Vector2d, 4>& truth, const render::TagDetection* det,
                   const PinholeCamera& cam) {
    using render::DrawText;
    std::vector<Eigen::Vector2d> poly(truth.begin(), truth.end());
    render::DrawPolyline(&image, poly, true, render::kGreen, 1);
    constexpr double kEllipseGain = 20.0;  // corner covariances are sub-pixel: magnify them
    if (det) {
      std::vector<Eigen::Vector2d> found(det->corners.begin(), det->corners.end());
      render::DrawPolyline(&image, found, true, render::kRed, 1);
      for (int k = 0; k < 4; ++k) {
        render::DrawCovarianceEllipse(&image, det->corners[k],
                                      kEllipseGain * kEllipseGain * det->CornerCov(k), 0.95,
                                      render::kYellow, 1);
      }
      if (const auto pose = render::EstimateTagPose(*det, cam, tag_.size_m)) {
        render::DrawFrameAxes(&image, cam, pose->T_cam_tag, 0.5 * tag_.size_m, 2);
      }
    }
    char line[200];
    std::snprintf(line, sizeof(line), "d=%.2fm view=%.0fdeg rot=%.0fdeg  %.1f px/cell  %s",
                  row.distance_m, row.view_deg, row.rotation_deg, row.px_per_cell,
                  row.status.c_str());
    DrawText(&image, line, Eigen::Vector2d(8, 20), render::kWhite);
    DrawText(&image, "green: truth  red: detected  yellow: 95% corner ellipses x20  axes: pose",
             Eigen::Vector2d(8, image.height - 10.0), render::kWhite, 0.4);
    char name[64];
    std::snprintf(name, sizeof(name), "sweep_%04d.png", row.frame);
    render::WritePng(image, (ctx.out->FramesDir() / name).string());
  }

  void WriteCsv(RunContext& ctx, const std::vector<FrameRow>& rows) const {
    std::ofstream csv(ctx.out->File("sweep.csv"));
    csv << "frame,distance_m,view_angle_deg,rotation_deg,tag_width_px,px_per_cell,detected,"
           "status,corner_rmse_px,center_err_px,corner_nees,est_view_angle_deg,"
           "decision_margin,pose_rot_err_deg,pose_pos_err_mm,pose_det\n";
    const auto num = [](double v) {
      if (!std::isfinite(v)) return std::string();
      char b[32];
      std::snprintf(b, sizeof(b), "%.6g", v);
      return std::string(b);
    };
    for (const FrameRow& r : rows) {
      csv << r.frame << ',' << num(r.distance_m) << ',' << num(r.view_deg) << ','
          << num(r.rotation_deg) << ',' << num(r.width_px) << ',' << num(r.px_per_cell) << ','
          << (r.detected ? 1 : 0) << ',' << r.status << ',' << num(r.corner_rmse_px) << ','
          << num(r.center_err_px) << ',' << num(r.corner_nees) << ',' << num(r.est_view_deg) << ','
          << num(r.decision_margin) << ',' << num(r.pose_rot_err_deg) << ','
          << num(r.pose_pos_err_mm) << ',' << num(r.pose_det) << '\n';
    }
  }

  // Detection rate and corner RMSE of a group of rows.
  static std::pair<double, double> RateAndRmse(const std::vector<const FrameRow*>& group) {
    if (group.empty()) return {NAN, NAN};
    int detected = 0;
    double sq = 0.0;
    for (const FrameRow* r : group) {
      if (!r->detected) continue;
      ++detected;
      sq += r->corner_rmse_px * r->corner_rmse_px;
    }
    return {static_cast<double>(detected) / group.size(),
            detected > 0 ? std::sqrt(sq / detected) : NAN};
  }

  void WritePlot(RunContext& ctx, const std::vector<FrameRow>& rows) const {
    render::Figure fig(1200, 860, 2, 2);
    fig.title = "AprilTag detection sweep (" + tag_.family + " id " + std::to_string(tag_.id) +
                ", " + (mode_ == render::RenderMode::kFast ? "fast" : "quality") + " render)";
    // Against pixels per cell: one line per view angle, one point per distance.
    render::Axes& rate_px = fig.axes(0, 0);
    render::Axes& rmse_px = fig.axes(1, 0);
    rate_px.title = "detection rate vs tag resolution";
    rate_px.x_label = "pixels per tag cell";
    rate_px.y_label = "detection rate";
    rate_px.x_min = 0.0;
    rate_px.y_min = 0.0;
    rate_px.y_max = 1.05;
    rate_px.legend_position = render::LegendPosition::kBottomRight;
    rmse_px.title = "corner RMSE vs tag resolution (detected frames)";
    rmse_px.x_label = "pixels per tag cell";
    rmse_px.y_label = "corner RMSE [px]";
    rmse_px.x_min = 0.0;
    rmse_px.y_min = 0.0;
    rmse_px.legend = false;  // same colours as the panel above
    for (double view : views_) {
      std::vector<double> x, rate, rmse;
      for (double distance : distances_) {
        std::vector<const FrameRow*> g;
        double ppc = 0.0;
        for (const FrameRow& r : rows) {
          if (r.view_deg == view && r.distance_m == distance) {
            g.push_back(&r);
            ppc += r.px_per_cell;
          }
        }
        const auto [rt, rm] = RateAndRmse(g);
        x.push_back(ppc / std::max<size_t>(1, g.size()));
        rate.push_back(rt);
        rmse.push_back(rm);
      }
      char label[32];
      std::snprintf(label, sizeof(label), "view %.0f deg", view);
      rate_px.AddLine(label, x, rate).marker = render::Marker::kCircle;
      rmse_px.AddLine(label, x, rmse).marker = render::Marker::kCircle;
    }
    rmse_px.AddHLine(0.5, "0.5 px gate (frontal)");
    // Against view angle: one line per distance.
    render::Axes& rate_v = fig.axes(0, 1);
    render::Axes& rmse_v = fig.axes(1, 1);
    rate_v.title = "detection rate vs view angle";
    rate_v.x_label = "out-of-plane view angle [deg]";
    rate_v.y_label = "detection rate";
    rate_v.x_min = 0.0;
    rate_v.x_max = 90.0;
    rate_v.y_min = 0.0;
    rate_v.y_max = 1.05;
    rate_v.legend_position = render::LegendPosition::kBottomLeft;
    rmse_v.title = "corner RMSE vs view angle (detected frames)";
    rmse_v.x_label = "out-of-plane view angle [deg]";
    rmse_v.y_label = "corner RMSE [px]";
    rmse_v.x_min = 0.0;
    rmse_v.x_max = 90.0;
    rmse_v.y_min = 0.0;
    rmse_v.legend = false;  // same colours as the panel above
    for (double distance : distances_) {
      std::vector<double> x, rate, rmse;
      for (double view : views_) {
        std::vector<const FrameRow*> g;
        for (const FrameRow& r : rows) {
          if (r.view_deg == view && r.distance_m == distance) g.push_back(&r);
        }
        const auto [rt, rm] = RateAndRmse(g);
        x.push_back(view);
        rate.push_back(rt);
        rmse.push_back(rm);
      }
      char label[32];
      std::snprintf(label, sizeof(label), "%.2f m", distance);
      rate_v.AddLine(label, x, rate).marker = render::Marker::kCircle;
      rmse_v.AddLine(label, x, rmse).marker = render::Marker::kCircle;
    }
    rate_v.AddVLine(detector_.max_view_angle_deg, "view gate");
    fig.SavePng(ctx.out->File("sweep.png").string());
  }

  void FillMetrics(RunContext& ctx, const std::vector<FrameRow>& rows) const {
    std::vector<const FrameRow*> frontal, all;
    int wrong = 0;
    double nees_sum = 0.0;
    int nees_n = 0;
    double nees_resolved_sum = 0.0;
    int nees_resolved_n = 0;
    double max_det_dev = 0.0;
    for (const FrameRow& r : rows) {
      all.push_back(&r);
      if (r.view_deg == 0.0 && r.width_px >= frontal_min_width_px_) frontal.push_back(&r);
      if (r.status == "wrong") ++wrong;
      if (r.detected && std::isfinite(r.corner_nees)) {
        nees_sum += r.corner_nees;
        ++nees_n;
        if (r.px_per_cell >= 5.0 && r.view_deg <= 55.0) {
          nees_resolved_sum += r.corner_nees;
          ++nees_resolved_n;
        }
      }
      if (std::isfinite(r.pose_det)) max_det_dev = std::max(max_det_dev, std::abs(r.pose_det - 1));
    }
    const auto [rate_f, rmse_f] = RateAndRmse(frontal);
    const auto [rate_a, rmse_a] = RateAndRmse(all);
    Json& metrics = (*ctx.summary)["metrics"];
    const auto num = [](double v) { return std::isfinite(v) ? Json(v) : Json(); };
    metrics["frames"] = static_cast<int>(rows.size());
    metrics["frontal_frames"] = static_cast<int>(frontal.size());
    metrics["detection_rate_frontal"] = num(rate_f);
    metrics["corner_rmse_px_frontal"] = num(rmse_f);
    metrics["detection_rate_all"] = num(rate_a);
    metrics["corner_rmse_px_all_detected"] = num(rmse_a);
    // Mean over detected frames of the per-corner e^T S^-1 e (2 when the covariance is right):
    // over all frames, and where render/tag_covariance.h's model was validated (>= 5 px per
    // cell, view <= 55 deg). Tiny and steep tags have larger errors than the model predicts.
    metrics["corner_nees_mean"] = nees_n > 0 ? Json(nees_sum / nees_n) : Json();
    metrics["corner_nees_mean_resolved"] =
        nees_resolved_n > 0 ? Json(nees_resolved_sum / nees_resolved_n) : Json();
    metrics["wrong_detections"] = wrong;
    metrics["wrong_ids"] = wrong_ids_;
    metrics["dropped_small"] = dropped_small_;
    metrics["dropped_grazing"] = dropped_grazing_;
    metrics["dropped_border"] = dropped_border_;
    metrics["pose_det_max_deviation"] = max_det_dev;
  }

  std::string model_path_;
  std::string camera_;
  std::string board_body_;
  render::RenderMode mode_ = render::RenderMode::kFast;
  render::DetectorSettings detector_;
  render::Degradation degradation_;
  std::vector<double> distances_;
  std::vector<double> views_;
  std::vector<double> rotations_;
  int frames_per_pose_ = 1;
  double jitter_pos_m_ = 0.0;
  double jitter_angle_deg_ = 0.0;
  double frontal_min_width_px_ = 60.0;
  double wrong_corner_px_ = 1.5;
  int saved_frames_ = 6;

  sim::MjModelPtr model_;
  int camera_id_ = -1;
  int mocap_id_ = -1;
  std::vector<render::TagInModel> tags_;
  render::TagInModel tag_;
  std::unique_ptr<render::TagDetector> detector_instance_;
  std::unique_ptr<render::TagDetector> noisy_detector_;
  int wrong_ids_ = 0;
  int dropped_small_ = 0;
  int dropped_grazing_ = 0;
  int dropped_border_ = 0;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeTagDetectionSweepKind() {
  return std::make_unique<TagDetectionSweepKind>();
}

}  // namespace flexbench::scenarios
