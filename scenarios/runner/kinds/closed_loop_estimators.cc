// closed_loop_estimators: the whole loop on one robot. The truth carries effects the
// declared model lacks.
//   (a) The estimators track the end effector along a trajectory (AprilTags rendered, detected
//       by libapriltag, fused with the encoders) with the declared model: error and NEES, and a
//       running-NEES mismatch test.
//   (b) A calibration routine (the closed_loop kind's keys: the truth puts its ball into
//       sockets) identifies the missing effects and writes declared_augmented.yaml (identify/).
//   (c) The same estimators track a new trajectory with the augmented model.
// Outputs loop.csv and loop.png (before/after per estimator) beside the identification's own.
//
//   tracking: {camera: mast_camera, aim: {pan: mast_pan, tilt: mast_tilt, at: ee},
//              steps: 30, ranges_deg: {j1: [-30, 30], ...}, fixed_joints_deg: {...},
//              pixel_noise_std_px: 0.5, mismatch_window: 10}
//   estimators: {fk: {}, ppoe_ekf: {}, ...}
//   + the closed_loop keys (truth, calibration, validation, point_std_m, ...).
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <random>
#include <sstream>

#include "estimators/estimator.h"
#include "estimators/stats/chi_square.h"
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
#include "scenarios/runner/common/tag_tracking.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/common/truth_rig.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/camera.h"
#include "sim/declared_chain.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

// One estimator's run along one trajectory.
struct Track {
  ErrorStats stats;  // with the running mismatch test
  std::vector<double> pos_err;
};

class ClosedLoopEstimatorsKind : public ScenarioKind {
 public:
  bool ExportsLog() const final { return true; }

  void Configure(const ConfigNode& root) override {
    identify_ = MakeClosedLoopKind();
    identify_->Configure(root);  // model, declared, truth, calibration, validation, ...
    rig_.declared = ReadModelAndDeclared(root, &model_path_);
    truth_ = sim::ParseEffects(root.Child("truth").Child("effects"));
    // The encoders of the tracking runs read with the noise of the calibration routine's.
    encoder_noise_rad_ = root.Child("truth").GetDouble("encoder_noise_deg", 0.0) * M_PI / 180.0;
    const ConfigNode t = root.Child("tracking");
    camera_ = t.GetString("camera");
    const ConfigNode aim = t.Child("aim");
    aim_pan_ = aim.GetString("pan");
    aim_tilt_ = aim.GetString("tilt");
    aim_at_ = aim.GetString("at");
    steps_ = t.GetInt("steps");
    if (steps_ < 2) t.Child("steps").Fail("must be >= 2");
    pixel_std_ = t.GetDouble("pixel_noise_std_px", 0.5);
    if (!(pixel_std_ > 0.0)) t.Child("pixel_noise_std_px").Fail("must be > 0");
    window_ = t.GetInt("mismatch_window", 10);
    if (window_ < 2 || window_ > steps_) t.Child("mismatch_window").Fail("must be in [2, steps]");
    const ConfigNode ranges = t.Child("ranges_deg");
    for (const std::string& j : ranges.Keys()) {
      const std::vector<double> lohi = ranges.Child(j).AsDoubleList();
      if (lohi.size() != 2 || !(lohi[0] <= lohi[1])) ranges.Child(j).Fail("expected [low, high]");
      ranges_.push_back({j, lohi[0], lohi[1]});
    }
    if (const auto fixed = t.Optional("fixed_joints_deg")) {
      for (const std::string& j : fixed->Keys()) fixed_.emplace_back(j, fixed->GetDouble(j));
    }
    mode_ = ParseRenderMode(root, render::RenderMode::kFast);
    detector_ = ParseDetectorSettings(root);
    specs_ = ParseEstimators(root.Child("estimators"));

    rig_ = LoadTruthRig(model_path_, truth_, std::move(rig_.declared));
    for (const Range& r : ranges_) rig_.sim->SetCommand(r.joint, 0.0);
    for (const auto& [j, v] : fixed_) rig_.sim->SetCommand(j, 0.0);
    rig_.sim->SetCommand(aim_pan_, 0.0);
    rig_.sim->SetCommand(aim_tilt_, 0.0);
    rig_.sim->Frame(aim_at_);
    camera_id_ = sim::CameraId(rig_.sim->model(), camera_, model_path_);
    AddCamera(&rig_);
    tags_ = render::ApplyTagTextures(rig_.sim->mutable_model());
    if (TagFrames(*rig_.chain).empty()) {
      throw InputError(rig_.declared.file + ": no tag geom of " + model_path_ +
                       " is among the observed frames");
    }
    Instances(rig_);  // bad estimator parameters fail now
  }

  void Run(RunContext& ctx) override {
    render::Renderer renderer(rig_.sim->model(), mode_);
    render::TagDetector detector(detector_);
    ctx.log("(a) tracking with the declared model");
    TrajectoryRecorder before_trajectories, after_trajectories;
    // The scenario's declared model may itself be an augmented one (--set declared=...).
    FittedRangeCheck declared_range(rig_.declared, rig_.chain->q_joints, rig_.sim->nominal_model(),
                                    rig_.chain.get());
    const std::vector<Track> before =
        Follow(ctx, renderer, detector, rig_, 0, &before_trajectories, nullptr, &declared_range);
    declared_range.Report(ctx);
    before_trajectories.Write(*ctx.out, "base", "before");
    ctx.log("(b) calibration routine and identification (identify/)");
    const fs::path augmented = Identify(ctx);
    std::unique_ptr<DeclaredRig> aug_rig;
    SharedError shared;
    FittedRangeCheck range;
    if (fs::exists(augmented)) {
      aug_rig = std::make_unique<DeclaredRig>(
          BuildDeclaredRig(rig_.sim->nominal_model(), sim::LoadDeclaredModel(augmented.string())));
      AddCamera(aug_rig.get());
      shared = PerturbedChains(aug_rig->declared);
      range = FittedRangeCheck(aug_rig->declared, aug_rig->chain->q_joints,
                               rig_.sim->nominal_model(), aug_rig->chain.get());
    } else {
      ctx.log("no augmented model (see identify/summary.json): tracking again as declared");
    }
    ctx.log("(c) tracking a new trajectory with the augmented model");
    const std::vector<Track> after = Follow(ctx, renderer, detector, aug_rig ? *aug_rig : rig_, 1,
                                            &after_trajectories, &shared, &range);
    range.Report(ctx);
    after_trajectories.Write(*ctx.out, "base", "after");
    (*ctx.summary)["metrics"]["augmented_model_used"] = aug_rig != nullptr;
    Report(ctx, before, after);
  }

 private:
  struct Range {
    std::string joint;
    double lo_deg, hi_deg;
  };

  std::map<int, kinematics::FrameId> TagFrames(const sim::DeclaredChain& chain) const {
    std::map<int, kinematics::FrameId> frames;
    for (const auto& tag : tags_) {
      const std::string geom = sim::ObjectName(rig_.sim->model(), mjOBJ_GEOM, tag.geom_id);
      for (const auto& [name, frame] : chain.observed) {
        if (name == geom) frames[tag.id] = frame;
      }
    }
    return frames;
  }

  // The fitted parameters' error is the same at every step of a trajectory: the augmented
  // model with each identified parameter one standard deviation up and down. The estimates'
  // shared error G z (ErrorStats) takes G's columns from the difference of fk's poses.
  struct SharedError {
    std::vector<DeclaredRig> up, down;
  };

  SharedError PerturbedChains(const sim::DeclaredModel& aug) const {
    SharedError out;
    for (size_t e = 0; e < aug.identified_effects.size(); ++e) {
      const sim::IdentifiedEffect& effect = aug.identified_effects[e];
      for (size_t k = 0; k < effect.value.size() && k < effect.std.size(); ++k) {
        if (!(effect.std[k] > 0.0)) continue;
        for (const double sign : {1.0, -1.0}) {
          sim::DeclaredModel d = aug;
          d.identified_effects[e].value[k] += sign * effect.std[k];
          (sign > 0 ? out.up : out.down)
              .push_back(BuildDeclaredRig(rig_.sim->nominal_model(), std::move(d)));
        }
      }
    }
    return out;
  }

  // fk on `rig`: the pose the model predicts from the readings alone.
  static std::unique_ptr<estimators::Estimator> Fk(const DeclaredRig& rig) {
    return estimators::MakeEstimator("fk", rig.setup);
  }

  // G (6 x parameters): the change of fk's pose, in its tangent space, with one standard
  // deviation of each parameter (central differences over the perturbed chains' fk).
  static Mat6x SharedColumns(std::vector<std::unique_ptr<estimators::Estimator>>& fk,
                             const estimators::JointReading& joints) {
    for (auto& f : fk) {
      f->Predict(joints.t);
      f->Update(joints);
    }
    const int m = static_cast<int>(fk.size() - 1) / 2;
    const lie::SE3 T_0 = fk[0]->Estimate().T_base_ee;
    Mat6x G(6, m);
    for (int i = 0; i < m; ++i) {
      G.col(i) = 0.5 * (T_0.Between(fk[1 + i]->Estimate().T_base_ee).Log() -
                        T_0.Between(fk[1 + m + i]->Estimate().T_base_ee).Log());
    }
    return G;
  }

  // The camera the tags are seen with, on `rig`'s set-up.
  void AddCamera(DeclaredRig* rig) const {
    rig->setup.cameras.push_back(
        {sim::CameraIntrinsics(rig_.sim->model(), camera_id_), rig->chain->ObservedFrame(camera_)});
  }

  std::vector<std::unique_ptr<estimators::Estimator>> Instances(const DeclaredRig& rig) const {
    std::vector<std::unique_ptr<estimators::Estimator>> out;
    for (const EstimatorSpec& spec : specs_) out.push_back(rig.MakeEstimator(spec, seed_));
    return out;
  }

  // Trajectory `index`: each joint swings through its range, q = mid + half sin(phase + 2 pi f
  // s), s in [0, 1], phase and f (0.5..1.5 cycles) drawn from the run's seed; a new index is a
  // new trajectory.
  std::vector<std::vector<std::pair<std::string, double>>> Trajectory(std::uint64_t seed,
                                                                      int index) const {
    std::mt19937_64 rng(seed * 7919ULL + 31 + index);
    std::uniform_real_distribution<double> phase(0.0, 2.0 * M_PI), freq(0.5, 1.5);
    std::vector<std::pair<double, double>> pf;
    for (size_t j = 0; j < ranges_.size(); ++j) {
      const double p = phase(rng);
      pf.emplace_back(p, freq(rng));
    }
    std::vector<std::vector<std::pair<std::string, double>>> traj(steps_);
    for (int k = 0; k < steps_; ++k) {
      const double s = static_cast<double>(k) / (steps_ - 1);
      for (size_t j = 0; j < ranges_.size(); ++j) {
        const Range& r = ranges_[j];
        const double mid = 0.5 * (r.lo_deg + r.hi_deg), half = 0.5 * (r.hi_deg - r.lo_deg);
        traj[k].emplace_back(r.joint,
                             mid + half * std::sin(pf[j].first + 2.0 * M_PI * pf[j].second * s));
      }
    }
    return traj;
  }

  std::vector<Track> Follow(RunContext& ctx, render::Renderer& renderer,
                            render::TagDetector& detector, const DeclaredRig& rig, int index,
                            TrajectoryRecorder* trajectories, const SharedError* shared = nullptr,
                            FittedRangeCheck* range = nullptr) {
    seed_ = ctx.seed;
    auto instances = Instances(rig);
    std::vector<std::unique_ptr<estimators::Estimator>> fk;  // rig, then up, then down
    if (shared != nullptr && !shared->up.empty()) {
      fk.push_back(Fk(rig));
      for (const DeclaredRig& r : shared->up) fk.push_back(Fk(r));
      for (const DeclaredRig& r : shared->down) fk.push_back(Fk(r));
    }
    const sim::DeclaredChain& chain = *rig.chain;
    const std::map<int, kinematics::FrameId> tag_frames = TagFrames(chain);
    std::vector<Track> tracks(instances.size());
    for (Track& tr : tracks) tr.stats = ErrorStats(window_);
    const std::string stage = index == 0 ? "tracking (declared)" : "tracking (augmented)";
    int tags_seen = 0;
    const auto trajectory = Trajectory(ctx.seed, index);
    std::mt19937_64 noise_rng(ctx.seed * 104729ULL + 7 + index);
    std::normal_distribution<double> noise(0.0, 1.0);
    std::optional<sim::RecordedLog> log;
    if (index == 0 && !ctx.export_log.empty()) log = StartLog(chain, tag_frames);
    for (int k = 0; k < steps_; ++k) {
      for (const auto& [j, deg] : fixed_) rig_.sim->SetCommand(j, deg * M_PI / 180.0);
      for (const auto& [j, deg] : trajectory[k]) {
        rig_.sim->SetCommand(j, deg * M_PI / 180.0);
      }
      AimCamera(rig_.sim.get(), aim_pan_, aim_tilt_, aim_at_, camera_);
      rig_.sim->Settle();
      const render::Image frame =
          renderer.RenderRgb(const_cast<mjData*>(rig_.sim->data()), camera_id_);
      estimators::JointReading joints = EncoderReading(*rig_.sim, chain, k);
      for (int j = 0; j < joints.q.size(); ++j)
        joints.q[j] += encoder_noise_rad_ * noise(noise_rng);
      joints.std.setConstant(encoder_noise_rad_);
      if (range) range->Observe(joints.q.data(), static_cast<int>(joints.q.size()));
      const render::DetectionResult det = detector.Detect(frame);
      const auto measurements =
          TagMeasurements(det, tags_, tag_frames, false, pixel_std_, joints.t);
      tags_seen += static_cast<int>(measurements.size());
      const lie::SE3 T_w_base = chain.base_body == 0
                                    ? lie::SE3()
                                    : ToSE3(rig_.sim->BodyPose(sim::ObjectName(
                                          rig_.sim->model(), mjOBJ_BODY, chain.base_body)));
      const lie::SE3 T_base_ee =
          T_w_base.Inverse() * ToSE3(rig_.sim->Pose(rig_.declared.end_effector));
      trajectories->AddTruth(joints.t, T_base_ee);
      if (log) {
        AddStepToLog(joints, T_base_ee, &*log);
        AddDetectionsToLog(det, joints.t, 0, &*log);
      }
      const Mat6x G = fk.empty() ? Mat6x() : SharedColumns(fk, joints);
      for (size_t e = 0; e < instances.size(); ++e) {
        estimators::Estimator& est = *instances[e];
        est.Predict(joints.t);
        est.Update(joints);
        for (const auto& m : measurements) est.Update(m);
        const estimators::Belief b = est.Estimate();
        Track& tr = tracks[e];
        tr.stats.Add(b.T_base_ee, b.cov, T_base_ee, G);
        trajectories->Add(specs_[e].name, joints.t, b.T_base_ee, b.cov);
        tr.pos_err.push_back(tr.stats.last_pos());
      }
      ctx.progress(stage, k + 1, steps_);
    }
    (*ctx.summary)["metrics"][index == 0 ? "tags_before" : "tags_after"] = tags_seen;
    if (log) {
      WriteLogWithDeclared(*log, rig_.declared, ctx.export_log);
      ctx.log("readings of the declared tracking written to " + ctx.export_log);
    }
    return tracks;
  }

  // The declared tracking's readings as a recorded log (--export-log): the encoders with their
  // stated noise, the tags libapriltag found with its centres (the estimators fuse the centre
  // pixel), the hand's truth. Replayed, the estimators give the live run's estimates bit for bit.
  sim::RecordedLog StartLog(const sim::DeclaredChain& chain,
                            const std::map<int, kinematics::FrameId>& tag_frames) const {
    sim::RecordedLog log = LogOfChain(rig_.declared, chain);
    log.joint_std = encoder_noise_rad_;
    AddTagCameraToLog(rig_.sim->model(), camera_,
                      sim::CameraIntrinsics(rig_.sim->model(), camera_id_), tags_, tag_frames,
                      pixel_std_, /*centres=*/true, &log);
    return log;
  }

  // Runs the closed_loop kind into identify/ and returns its augmented model's path.
  fs::path Identify(RunContext& ctx) {
    const fs::path dir = ctx.out->File("identify");
    Json summary;
    summary["scenario"] = "identify";
    summary["kind"] = "closed_loop";
    summary["seed"] = ctx.seed;
    summary["metrics"] = Json::object();
    summary["estimators"] = Json::object();
    {
      OutputDir out(dir);
      RunContext sub = ctx;
      sub.out = &out;
      sub.summary = &summary;
      identify_->Run(sub);
      WriteFileAtomic(out.File("summary.json"),
                      summary.dump(2, ' ', false, Json::error_handler_t::replace) + "\n");
      out.Commit();
    }
    Json& m = (*ctx.summary)["metrics"];
    const Json& im = summary["metrics"];
    for (const char* key : {"verdict", "effects_found", "effect_found_correct", "val_err_before_m",
                            "val_err_after_m", "source_covariance_scale"}) {
      if (im.contains(key)) m["identification_" + std::string(key)] = im[key];
    }
    (*ctx.summary)["identification"] = summary["identification"];
    return dir / "declared_augmented.yaml";
  }

  void Report(RunContext& ctx, const std::vector<Track>& before, const std::vector<Track>& after) {
    std::ostringstream csv;
    csv << "estimator,pos_err_before_m,pos_err_after_m,ratio,nees_before,nees_after,"
           "nees_bound_low,nees_bound_high,nees_after_bound_low,nees_after_bound_high,"
           "mismatch_first_step_before,mismatch_first_step_after\n";
    bool all_halved = true, nees_fixed = true, flag_ok = true;
    std::vector<double> x, b_mm, a_mm;
    for (size_t e = 0; e < specs_.size(); ++e) {
      Json bm = Json::object(), am = Json::object();
      before[e].stats.WriteMetrics(&bm);
      after[e].stats.WriteMetrics(&am);
      Json& em = (*ctx.summary)["estimators"][specs_[e].name]["metrics"];
      em["before"] = bm;
      em["after"] = am;
      const double pb = bm["pos_err_mean_m"].get<double>(), pa = am["pos_err_mean_m"].get<double>();
      em["pos_err_ratio"] = pa / pb;
      const auto inside = [](const Json& m) {
        return m.contains("nees_consistent") && m["nees_consistent"].get<bool>();
      };
      // NEES after inside its bounds wherever it was outside before.
      em["nees_fixed"] = inside(bm) || inside(am);
      em["mismatch_flagged_before"] = before[e].stats.mismatch().flagged();
      em["mismatch_first_step_before"] = before[e].stats.mismatch().first_step();
      em["mismatch_flagged_after"] = after[e].stats.mismatch().flagged();
      em["mismatch_first_step_after"] = after[e].stats.mismatch().first_step();
      all_halved = all_halved && pa < 0.5 * pb;
      nees_fixed = nees_fixed && em["nees_fixed"].get<bool>();
      flag_ok = flag_ok &&
                (!before[e].stats.mismatch().flagged() || !after[e].stats.mismatch().flagged());
      char line[320];
      std::snprintf(line, sizeof(line), "%s,%.9g,%.9g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%d\n",
                    specs_[e].name.c_str(), pb, pa, pa / pb, bm.value("nees_mean", 0.0),
                    am.value("nees_mean", 0.0), bm.value("nees_bound_low", 0.0),
                    bm.value("nees_bound_high", 0.0), am.value("nees_bound_low", 0.0),
                    am.value("nees_bound_high", 0.0), before[e].stats.mismatch().first_step(),
                    after[e].stats.mismatch().first_step());
      csv << line;
      x.push_back(static_cast<double>(e));
      b_mm.push_back(1e3 * pb);
      a_mm.push_back(1e3 * pa);
    }
    WriteFileAtomic(ctx.out->File("loop.csv"), csv.str());
    Json& m = (*ctx.summary)["metrics"];
    m["every_error_halved"] = all_halved;
    m["every_nees_fixed"] = nees_fixed;
    m["no_flag_after_a_flag_before"] = flag_ok;

    render::Figure fig(900, 520);
    fig.title = "Closing the loop: position error before and after identification";
    render::Axes& ax = fig.axes();
    for (const EstimatorSpec& s : specs_) ax.x_tick_labels.push_back(s.name);
    ax.x_label = "estimator";
    // A log axis: errors after the fix are some 1/50 of those before and would not show.
    ax.y_log = true;
    ax.y_label = "mean position error [mm], log scale";
    ax.x_min = -0.6;
    ax.x_max = specs_.size() - 0.4;
    std::vector<double> xb, xa;
    std::vector<std::string> lb, la;
    const auto mm3 = [](double v) {
      char b[32];
      std::snprintf(b, sizeof(b), "%.3g", v);
      return std::string(b);
    };
    double top = 0.0;
    for (size_t e = 0; e < x.size(); ++e) {
      top = std::max({top, b_mm[e], a_mm[e]});
      xb.push_back(x[e] - 0.17), xa.push_back(x[e] + 0.17);
      lb.push_back(mm3(b_mm[e])), la.push_back(mm3(a_mm[e]));
    }
    ax.AddBars("declared model (trajectory 1)", xb, b_mm, 0.3).color = render::PaletteColor(0);
    ax.series.back().point_labels = lb;
    ax.AddBars("augmented model (trajectory 2)", xa, a_mm, 0.3).color = render::PaletteColor(1);
    ax.series.back().point_labels = la;
    ax.y_max = 10.0 * top;  // a decade free for the legend
    ax.legend_position = render::LegendPosition::kTopRight;
    fig.SavePng(ctx.out->File("loop.png").string());
  }

  std::unique_ptr<ScenarioKind> identify_;
  std::string model_path_;
  sim::EffectList truth_;
  std::string camera_, aim_pan_, aim_tilt_, aim_at_;
  int steps_ = 30;
  int window_ = 10;
  double pixel_std_ = 0.5;
  double encoder_noise_rad_ = 0.0;
  std::vector<Range> ranges_;
  std::vector<std::pair<std::string, double>> fixed_;
  render::RenderMode mode_ = render::RenderMode::kFast;
  render::DetectorSettings detector_;
  std::vector<EstimatorSpec> specs_;
  std::uint64_t seed_ = 0;

  TruthRig rig_;
  int camera_id_ = -1;
  std::vector<render::TagInModel> tags_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeClosedLoopEstimatorsKind() {
  return std::make_unique<ClosedLoopEstimatorsKind>();
}

}  // namespace flexbench::scenarios
