// Tag fusion (PPOE paper sec. V-C, Table I): the truth arm (with its effects) settles in each
// configuration, the camera renders a frame, libapriltag detects the end-effector tags, and
// every estimator fuses the tag corners with the encoder readings of its declared model. The
// end-effector estimates are scored against MuJoCo's true pose: lateral error (across the
// end-effector axis, the paper's metric), position, rotation and NEES.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <random>

#include "estimators/estimator.h"
#include "render/overlay.h"
#include "render/plot.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "scenarios/runner/common/error_stats.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/log_export.h"
#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/common/pose.h"
#include "scenarios/runner/common/render_config.h"
#include "scenarios/runner/common/sim_readings.h"
#include "scenarios/runner/common/stage_timer.h"
#include "scenarios/runner/common/tag_tracking.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/common/truth_rig.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/camera.h"
#include "sim/declared_chain.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {
namespace {

// The configurations' frames a report shows by default (three, spread evenly from the first):
// the others are written with --frames all.
constexpr int kKeyFrames = 3;

class TagFusionKind : public ScenarioKind {
 public:
  bool ExportsLog() const final { return true; }

  void Configure(const ConfigNode& root) override {
    rig_.declared = ReadModelAndDeclared(root, &model_path_);
    effects_ = sim::ParseEffects(root.Child("effects"));
    camera_ = root.GetString("camera");
    pixel_std_ = root.GetDouble("pixel_noise_std_px", 0.5);
    // The paper fuses 2-D bearings: the tag centre's pixel [PPOE eq. 25]. All four corners (8-D)
    // pin the pose almost alone, which hides the prior's role.
    const std::string measurement = root.GetString("measurement", "center");
    if (measurement != "center" && measurement != "corners") {
      root.Child("measurement").Fail("expected center or corners");
    }
    use_corners_ = measurement == "corners";
    if (!(pixel_std_ > 0.0)) root.Child("pixel_noise_std_px").Fail("must be > 0");
    mode_ = ParseRenderMode(root, render::RenderMode::kFast);
    detector_ = ParseDetectorSettings(root);
    ParseConfigurations(root);
    // Point a pan-tilt camera at a frame of the nominal arm (the rover looks at its hand).
    if (const auto aim = root.Optional("aim_camera")) {
      aim_pan_ = aim->GetString("pan");
      aim_tilt_ = aim->GetString("tilt");
      aim_at_ = aim->GetString("at");
    }
    save_frames_ = root.GetBool("save_frames", true);
    // The paper's Table I for the chart: {estimator: [mean_cm, std_cm]}.
    if (root.Has("paper_lateral_cm")) {
      const ConfigNode paper = root.Child("paper_lateral_cm");
      for (const std::string& name : paper.Keys()) {
        const ConfigNode v = paper.Child(name);
        const std::vector<double> ms = v.AsDoubleList();
        if (ms.size() != 2 || !(ms[0] >= 0.0) || !(ms[1] >= 0.0)) {
          v.Fail("expected [mean_cm, std_cm], both >= 0");
        }
        paper_lateral_cm_.emplace_back(name, ms);
      }
    }
    estimators_ = ParseEstimators(root.Child("estimators"));

    // Everything that can be wrong is checked now, before any output exists.
    LoadTruth();
    MakeEstimators(root);
  }

  // collect (settle, render, detect) -> estimate -> score, per configuration; then report.
  void Run(RunContext& ctx) override {
    render::Renderer renderer(rig_.sim->model(), mode_);
    ctx.log("GL_RENDERER: " + renderer.gl_renderer());
    if (random_count_ > 0) SampleConfigurations(renderer, ctx);
    RunState state(instances_.size(), ctx.out->File("configurations.csv"));
    std::optional<sim::RecordedLog> log;
    if (!ctx.export_log.empty()) log = StartLog();
    FittedRangeCheck range(rig_.declared, rig_.chain->q_joints, rig_.sim->nominal_model(),
                           rig_.chain.get());
    for (size_t c = 0; c < configurations_.size(); ++c) {
      const Frame frame = Collect(c, renderer, &state);
      range.Observe(frame.joints.q.data(), static_cast<int>(frame.joints.q.size()));
      if (log) {
        AddStepToLog(frame.joints, frame.T_base_ee, &*log);
        AddDetectionsToLog(frame.det, frame.joints.t, 0, &*log);
      }
      render::Image overlay = TruthOverlay(frame);
      for (size_t e = 0; e < instances_.size(); ++e) {
        const estimators::Belief b = Estimate(e, frame, &state);
        Score(c, e, frame, b, &state);
        DrawEstimate(e, frame, b, &overlay);
      }
      if (save_frames_ && WritesFrame(ctx.frames, static_cast<int>(c),
                                      static_cast<int>(configurations_.size()), kKeyFrames)) {
        char name[64];
        std::snprintf(name, sizeof(name), "config_%02zu.png", c);
        render::WritePng(overlay, (ctx.out->FramesDir() / name).string());
      }
      ctx.progress("configurations", static_cast<int>(c + 1),
                   static_cast<int>(configurations_.size()));
    }
    if (log) {
      WriteLogWithDeclared(*log, rig_.declared, ctx.export_log);
      ctx.log("readings of the configurations written to " + ctx.export_log);
    }
    range.Report(ctx);
    state.timer.Write(ctx.timing, "frame", static_cast<int>(configurations_.size()));
    WriteMetrics(state, ctx);
    PlotLateralError(ctx);
    // The paper's exp. II finding is that PPOE and naive end up alike: |ppoe - naive|.
    const Json& est = (*ctx.summary)["estimators"];
    if (est.contains("ppoe_ekf") && est.contains("naive_ekf")) {
      (*ctx.summary)["metrics"]["ppoe_naive_lateral_abs_diff_m"] =
          std::abs(est["ppoe_ekf"]["metrics"]["lateral_err_mean_m"].get<double>() -
                   est["naive_ekf"]["metrics"]["lateral_err_mean_m"].get<double>());
    }
  }

 private:
  // fixed_joints_deg, configurations_deg, random_configurations.
  void ParseConfigurations(const ConfigNode& root) {
    if (const auto fixed = root.Optional("fixed_joints_deg")) {
      for (const std::string& j : fixed->Keys()) fixed_.emplace_back(j, fixed->GetDouble(j));
    }
    if (const auto configs = root.Optional("configurations_deg")) {
      for (const ConfigNode& c : configs->Items()) {
        std::vector<std::pair<std::string, double>> cfg;
        for (const std::string& j : c.Keys()) cfg.emplace_back(j, c.GetDouble(j));
        configurations_.push_back(cfg);
      }
    }
    // Seeded random configurations within joint ranges, kept when the camera sees at least
    // `min_tags` tags (the paper chose poses in which the markers were visible).
    if (const auto rnd = root.Optional("random_configurations")) {
      random_count_ = rnd->GetInt("count");
      min_tags_ = rnd->GetInt("min_tags", 1);
      max_attempts_ = rnd->GetInt("max_attempts", 50 * random_count_);
      // The paper's exp. II kept the hand "barely rotated w.r.t. the camera": a configuration is
      // kept only if the hand's axis is within this angle of the line of sight.
      max_ee_axis_to_sight_deg_ = rnd->GetDouble("max_ee_axis_to_sight_deg", 180.0);
      if (!(max_ee_axis_to_sight_deg_ > 0.0 && max_ee_axis_to_sight_deg_ <= 180.0)) {
        rnd->Child("max_ee_axis_to_sight_deg").Fail("expected an angle in (0, 180]");
      }
      const ConfigNode ranges = rnd->Child("ranges_deg");
      for (const std::string& j : ranges.Keys()) {
        const ConfigNode r = ranges.Child(j);
        const std::vector<double> lohi = r.AsDoubleList();
        if (lohi.size() != 2 || lohi[0] > lohi[1]) r.Fail("expected [low, high]");
        ranges_.push_back({j, lohi[0], lohi[1]});
      }
      if (random_count_ < 1) rnd->Child("count").Fail("must be >= 1");
    }
    if (configurations_.empty() && random_count_ == 0) {
      root.Fail("needs configurations_deg or random_configurations");
    }
  }

  // The truth simulation, its camera and tags, and the declared chain the estimators see.
  void LoadTruth() {
    rig_ = LoadTruthRig(model_path_, effects_, std::move(rig_.declared));
    for (const auto& cfg : configurations_) {
      for (const auto& [j, v] : cfg) rig_.sim->SetCommand(j, 0.0);
    }
    for (const auto& [j, v] : fixed_) rig_.sim->SetCommand(j, 0.0);
    for (const auto& r : ranges_) rig_.sim->SetCommand(r.joint, 0.0);
    if (!aim_pan_.empty()) {
      rig_.sim->SetCommand(aim_pan_, 0.0);
      rig_.sim->SetCommand(aim_tilt_, 0.0);
      rig_.sim->Frame(aim_at_);
    }
    camera_id_ = sim::CameraId(rig_.sim->model(), camera_, model_path_);
    rig_.chain->ObservedFrame(camera_);
    tags_ = render::ApplyTagTextures(rig_.sim->mutable_model());
    for (const auto& tag : tags_) {
      const std::string geom = sim::ObjectName(rig_.sim->model(), mjOBJ_GEOM, tag.geom_id);
      for (const auto& [name, frame] : rig_.chain->observed) {
        if (name == geom) tag_frames_[tag.id] = frame;
      }
    }
    if (tag_frames_.empty()) {
      throw InputError(rig_.declared.file + ": no tag geom of " + model_path_ +
                       " is among the observed frames");
    }
  }

  void MakeEstimators(const ConfigNode& root) {
    rig_.setup.cameras.push_back(
        {sim::CameraIntrinsics(rig_.sim->model(), camera_id_), rig_.chain->ObservedFrame(camera_)});
    // estimate_in: an observed frame (e.g. the camera, as in [PPOE eq. 25]) in which every
    // estimator works and is scored; by default the declared base.
    if (root.Has("estimate_in")) {
      estimate_in_ = root.GetString("estimate_in");
      rig_.setup.reference_frame = rig_.chain->ObservedFrame(estimate_in_);
    }
    for (const EstimatorSpec& spec : estimators_) instances_.push_back(rig_.MakeEstimator(spec));
    detector_instance_ = std::make_unique<render::TagDetector>(detector_);
  }

  // What the run accumulates over its configurations.
  struct RunState {
    RunState(size_t estimators, const std::filesystem::path& csv_path)
        : stats(estimators), status_counts(estimators), csv(csv_path) {
      csv << "config,estimator,tags_used,view_angle_deg,ee_axis_to_sight_deg,pos_err_m,"
             "lateral_err_m,rot_err_deg,nees\n";
    }
    std::vector<ErrorStats> stats;
    TrajectoryRecorder trajectories;
    std::vector<std::map<std::string, int>> status_counts;
    std::ofstream csv;
    int total_tags = 0;
    int configs_without_tags = 0;
    StageTimer timer;  // the pipeline's throughput: timing.pipeline_frames_per_s
  };

  // One configuration as the estimators and the scoring see it.
  struct Frame {
    render::Image image;
    render::DetectionResult det;
    estimators::JointReading joints;
    std::vector<estimators::Measurement> measurements;
    double view_angle_deg = -1.0, ee_axis_deg = 0.0;
    lie::SE3 T_w_ref;           // the frame estimates are made in (true pose)
    lie::SE3 T_base_ee;         // the truth, seen from it
    Eigen::Isometry3d T_cam_w;  // the camera's true pose
  };

  // Settles configuration c, renders and detects, reads the encoders; the truth.
  Frame Collect(size_t c, render::Renderer& renderer, RunState* state) {
    Frame f;
    {
      const auto t = state->timer.Time("simulate");
      Command(configurations_[c]);
    }
    {
      const auto t = state->timer.Time("render");
      f.image = renderer.RenderRgb(const_cast<mjData*>(rig_.sim->data()), camera_id_);
    }
    {
      const auto t = state->timer.Time("detect");
      f.det = detector_instance_->Detect(f.image);
    }
    f.joints = EncoderReading(*rig_.sim, *rig_.chain, static_cast<double>(c));
    f.measurements =
        TagMeasurements(f.det, tags_, tag_frames_, use_corners_, pixel_std_, f.joints.t);
    state->total_tags += static_cast<int>(f.measurements.size());
    state->configs_without_tags += f.measurements.empty();
    f.view_angle_deg = LargestViewAngleDeg(f.det);
    f.ee_axis_deg = EeAxisToSightDeg();
    // The truth in the declared model's base frame.
    const lie::SE3 T_w_base = rig_.chain->base_body == 0
                                  ? lie::SE3()
                                  : ToSE3(rig_.sim->BodyPose(sim::ObjectName(
                                        rig_.sim->model(), mjOBJ_BODY, rig_.chain->base_body)));
    // Estimates made in a reference frame are scored against the truth seen from that frame's
    // true pose (a sagging camera mount moves the frame, not the truth).
    f.T_w_ref = estimate_in_.empty() ? T_w_base : ToSE3(rig_.sim->Pose(estimate_in_));
    f.T_base_ee = f.T_w_ref.Inverse() * ToSE3(rig_.sim->Pose(rig_.declared.end_effector));
    f.T_cam_w = rig_.sim->Pose(camera_).inverse();
    state->trajectories.AddTruth(f.joints.t, f.T_base_ee);
    return f;
  }

  // A pose in the reference frame, seen from the camera.
  static Eigen::Isometry3d ToCamera(const Frame& f, const lie::SE3& T_base_x) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    const lie::SE3 T_w_x = f.T_w_ref * T_base_x;
    T.linear() = T_w_x.rotation();
    T.translation() = T_w_x.translation();
    return Eigen::Isometry3d(f.T_cam_w * T);
  }

  // The configurations' readings as a recorded log of static postures (--export-log): each
  // configuration a joint row at t = its index, estimated afresh as here; the tags libapriltag
  // found (with its centres when the centre is fused); the truth.
  sim::RecordedLog StartLog() const {
    if (!estimate_in_.empty()) {
      throw InputError("--export-log: estimate_in '" + estimate_in_ +
                       "': a log's replay estimates in the declared base frame");
    }
    sim::RecordedLog log = LogOfChain(rig_.declared, *rig_.chain);
    log.static_postures = true;
    AddTagCameraToLog(rig_.sim->model(), camera_, rig_.setup.cameras[0].intrinsics, tags_,
                      tag_frames_, pixel_std_, /*centres=*/!use_corners_, &log);
    return log;
  }

  // The evaluation overlay's truth: its axes and the detected tags' outlines.
  render::Image TruthOverlay(const Frame& f) const {
    render::Image overlay = f.image;
    render::DrawFrameAxes(&overlay, rig_.setup.cameras[0].intrinsics, ToCamera(f, f.T_base_ee),
                          0.06, 2);
    render::DrawText(&overlay, "truth: axes   estimates: + and 95% ellipse", {8, 18},
                     render::kWhite);
    for (const render::TagDetection& d : f.det.detections) {
      render::DrawPolyline(&overlay, {d.corners.begin(), d.corners.end()}, true, render::kYellow,
                           1);
    }
    return overlay;
  }

  // Estimator e from scratch on this configuration's readings.
  estimators::Belief Estimate(size_t e, const Frame& f, RunState* state) {
    const auto t = state->timer.Time("estimate");
    estimators::Estimator& est = *instances_[e];
    std::map<std::string, int>& counts = state->status_counts[e];
    est.Reset();
    est.Predict(f.joints.t);
    ++counts[estimators::ToString(est.Update(f.joints))];
    for (const auto& m : f.measurements) ++counts[estimators::ToString(est.Update(m))];
    return est.Estimate();
  }

  void Score(size_t c, size_t e, const Frame& f, const estimators::Belief& b, RunState* state) {
    ErrorStats& stats = state->stats[e];
    stats.Add(b.T_base_ee, b.cov, f.T_base_ee);
    state->trajectories.Add(estimators_[e].name, f.joints.t, b.T_base_ee, b.cov);
    char line[256];
    std::snprintf(line, sizeof(line), "%zu,%s,%zu,%.4f,%.4f,%.9g,%.9g,%.9g,%.9g\n", c,
                  estimators_[e].name.c_str(), f.measurements.size(), f.view_angle_deg,
                  f.ee_axis_deg, stats.last_pos(), stats.last_lateral(), stats.last_rot_deg(),
                  stats.last_nees());
    state->csv << line;
  }

  // Estimate e's position and its 95% ellipse on the overlay.
  void DrawEstimate(size_t e, const Frame& f, const estimators::Belief& b,
                    render::Image* overlay) const {
    const render::Color colors[] = {render::kMagenta, render::kCyan, render::kYellow,
                                    render::kGreen, render::kRed};
    const render::Color color = colors[e % 5];
    const PinholeCamera& cam = rig_.setup.cameras[0].intrinsics;
    const Eigen::Isometry3d T_cam_est = ToCamera(f, b.T_base_ee);
    // Right perturbation: the position part of the local covariance turns with R.
    const Mat3 R_cam_est = T_cam_est.linear();
    const Mat3 cov_cam = R_cam_est * b.cov.topLeftCorner<3, 3>() * R_cam_est.transpose();
    Eigen::Vector2d uv;
    if (cam.Project(T_cam_est.translation(), &uv)) {
      render::DrawMarker(overlay, uv, color, 5, 1);
      render::DrawPositionCovariance(overlay, cam, T_cam_est.translation(), cov_cam, 0.95, color,
                                     1);
      render::DrawText(overlay, estimators_[e].name, {8, 38.0 + 18.0 * e}, color);
    }
  }

  void WriteMetrics(const RunState& state, RunContext& ctx) const {
    Json& metrics = (*ctx.summary)["metrics"];
    metrics["configurations"] = static_cast<int>(configurations_.size());
    metrics["estimated_in"] = estimate_in_.empty() ? "base" : estimate_in_;
    // One "pose" per configuration (the timestamp is its index): evo_ape reads them as is.
    state.trajectories.Write(*ctx.out, estimate_in_.empty() ? "base" : estimate_in_);
    if (random_count_ > 0) metrics["configuration_attempts"] = attempts_;
    metrics["tags_detected_total"] = state.total_tags;
    metrics["configurations_without_tags"] = state.configs_without_tags;
    for (size_t e = 0; e < instances_.size(); ++e) {
      Json& em = (*ctx.summary)["estimators"][estimators_[e].name]["metrics"];
      state.stats[e].WriteMetrics(&em);
      Json& counts = (*ctx.summary)["estimators"][estimators_[e].name]["updates"];
      for (const auto& [status, n] : state.status_counts[e]) counts[status] = n;
      counts["covariance_repairs"] = instances_[e]->covariance_repairs();
    }
  }

  // Table I as a chart: one bar per estimator (mean lateral error, +- std), and the paper's
  // value beside it when the scenario gives it.
  void PlotLateralError(RunContext& ctx) const {
    render::Figure fig(760, 480);
    render::Axes& ax = fig.axes();
    ax.title = "Lateral end-effector error (mean +- std), " +
               std::to_string(configurations_.size()) + " configurations";
    std::string names;
    for (size_t e = 0; e < estimators_.size(); ++e) {
      names += (e ? ", " : "") + std::to_string(e) + ": " + estimators_[e].name;
    }
    ax.x_label = "estimator (" + names + ")";
    ax.y_label = "lateral error [cm]";
    ax.x_min = -0.6;
    ax.x_max = estimators_.size() - 0.4;
    ax.y_min = 0.0;
    ax.legend_position = render::LegendPosition::kTopRight;
    double top = 0.0;
    const bool with_paper = !paper_lateral_cm_.empty();
    bool paper_labelled = false;
    for (size_t e = 0; e < estimators_.size(); ++e) {
      const Json& em = (*ctx.summary)["estimators"][estimators_[e].name]["metrics"];
      if (!em.contains("lateral_err_mean_m")) continue;
      const double mean = 100.0 * em["lateral_err_mean_m"].get<double>();
      const double sd = 100.0 * em["lateral_err_std_m"].get<double>();
      render::Series& bar =
          ax.AddBars(estimators_[e].name + " (simulated)", {e - (with_paper ? 0.17 : 0.0)}, {mean},
                     with_paper ? 0.3 : 0.5);
      bar.y_err = {sd};
      bar.color = render::PaletteColor(static_cast<int>(e));
      top = std::max(top, mean + sd);
      for (const auto& [name, ms] : paper_lateral_cm_) {
        if (name != estimators_[e].name) continue;
        render::Series& p =
            ax.AddScatter(paper_labelled ? "" : "paper, Table I", {e + 0.17}, {ms[0]});
        paper_labelled = true;
        p.y_err = {ms[1]};
        p.marker = render::Marker::kDiamond;
        p.marker_size = 6;
        p.color = render::Rgb{60, 60, 60};
        top = std::max(top, ms[0] + ms[1]);
      }
    }
    ax.y_max = 1.45 * top;  // room for the legend above the highest bar
    fig.SavePng((ctx.out->FramesDir() / "lateral_error.png").string());
  }

  // How obliquely the camera sees the tags it uses: the largest angle between a detected tag's
  // normal and its line of sight (truth poses; 0 = face on, -1 = no tag). The paper's exp. II
  // "ensured that the fiducial markers ... face towards the camera"; this column shows whether a
  // scenario's configurations do.
  double LargestViewAngleDeg(const render::DetectionResult& det) const {
    double largest = -1.0;
    const Eigen::Vector3d p_w_cam = rig_.sim->Pose(camera_).translation();
    for (const render::TagDetection& d : det.detections) {
      if (tag_frames_.count(d.id) == 0) continue;
      for (const render::TagInModel& tag : tags_) {
        if (tag.id != d.id) continue;
        const Eigen::Isometry3d T_w_geom =
            rig_.sim->Pose(sim::ObjectName(rig_.sim->model(), mjOBJ_GEOM, tag.geom_id));
        const auto& c = tag.corners_geom;
        const Eigen::Vector3d n_w =
            T_w_geom.linear() * (c[1] - c[0]).cross(c[3] - c[0]).normalized();
        const Eigen::Vector3d centre_w = T_w_geom * (0.25 * (c[0] + c[1] + c[2] + c[3]));
        const double cosine = std::abs(n_w.dot((p_w_cam - centre_w).normalized()));
        largest = std::max(largest, std::acos(std::min(1.0, cosine)) * 180.0 / M_PI);
      }
    }
    return largest;
  }

  // The angle between the end effector's longitudinal (z) axis and the camera's line of sight
  // to it (truth poses): near 0 the hand points away from the camera and its lateral directions
  // (the scored ones) lie across the image, where a bearing sees them.
  double EeAxisToSightDeg() const {
    const Eigen::Isometry3d T_w_ee = rig_.sim->Pose(rig_.declared.end_effector);
    const Eigen::Vector3d sight = T_w_ee.translation() - rig_.sim->Pose(camera_).translation();
    return std::acos(std::clamp(T_w_ee.linear().col(2).dot(sight.normalized()), -1.0, 1.0)) *
           180.0 / M_PI;
  }

  struct Range {
    std::string joint;
    double lo_deg, hi_deg;
  };

  // Commands a configuration (after the fixed joints), aims the camera, settles the truth.
  void Command(const std::vector<std::pair<std::string, double>>& cfg) {
    for (const auto& [j, deg] : fixed_) rig_.sim->SetCommand(j, deg * M_PI / 180.0);
    for (const auto& [j, deg] : cfg) rig_.sim->SetCommand(j, deg * M_PI / 180.0);
    if (!aim_pan_.empty()) AimCamera(rig_.sim.get(), aim_pan_, aim_tilt_, aim_at_, camera_);
    rig_.sim->Settle();
  }

  void SampleConfigurations(render::Renderer& renderer, RunContext& ctx) {
    std::mt19937_64 rng(ctx.seed * 7919ULL + 17);
    while (static_cast<int>(configurations_.size()) < random_count_) {
      if (attempts_ >= max_attempts_) {
        throw InputError(
            "random_configurations: only " + std::to_string(configurations_.size()) + " of " +
            std::to_string(random_count_) + " configurations show " + std::to_string(min_tags_) +
            " tag(s)" +
            (max_ee_axis_to_sight_deg_ < 180.0 ? " within max_ee_axis_to_sight_deg" : "") +
            " after " + std::to_string(attempts_) + " attempts; widen ranges_deg");
      }
      ++attempts_;
      std::vector<std::pair<std::string, double>> cfg;
      for (const Range& r : ranges_) {
        std::uniform_real_distribution<double> u(r.lo_deg, r.hi_deg);
        cfg.emplace_back(r.joint, u(rng));
      }
      Command(cfg);
      if (EeAxisToSightDeg() > max_ee_axis_to_sight_deg_) continue;
      const render::Image frame =
          renderer.RenderRgb(const_cast<mjData*>(rig_.sim->data()), camera_id_);
      int seen = 0;
      for (const auto& d : detector_instance_->Detect(frame).detections) {
        seen += tag_frames_.count(d.id) > 0;
      }
      if (seen >= min_tags_) configurations_.push_back(cfg);
    }
  }

  std::string model_path_;
  sim::EffectList effects_;
  std::string camera_;
  std::string estimate_in_;  // "" = the declared base
  double pixel_std_ = 0.5;
  render::RenderMode mode_ = render::RenderMode::kFast;
  render::DetectorSettings detector_;
  std::vector<std::pair<std::string, double>> fixed_;
  std::vector<std::vector<std::pair<std::string, double>>> configurations_;
  bool save_frames_ = true;
  std::vector<std::pair<std::string, std::vector<double>>> paper_lateral_cm_;
  bool use_corners_ = false;
  int random_count_ = 0;
  int min_tags_ = 1;
  int max_attempts_ = 0;
  double max_ee_axis_to_sight_deg_ = 180.0;
  int attempts_ = 0;
  std::vector<Range> ranges_;
  std::string aim_pan_, aim_tilt_, aim_at_;
  std::vector<EstimatorSpec> estimators_;

  TruthRig rig_;
  int camera_id_ = -1;
  std::vector<render::TagInModel> tags_;
  std::map<int, kinematics::FrameId> tag_frames_;
  std::vector<std::unique_ptr<estimators::Estimator>> instances_;
  std::unique_ptr<render::TagDetector> detector_instance_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeTagFusionKind() { return std::make_unique<TagFusionKind>(); }

}  // namespace flexbench::scenarios
