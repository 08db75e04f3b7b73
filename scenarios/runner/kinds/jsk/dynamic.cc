#include "scenarios/runner/kinds/jsk/dynamic.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "estimators/error.h"
#include "estimators/imu/imu_orientations.h"
#include "render/image.h"
#include "scenarios/runner/common/log_export.h"
#include "scenarios/runner/common/pose.h"
#include "scenarios/runner/common/render_config.h"
#include "scenarios/runner/common/tag_tracking.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios::jsk {

namespace {

bool SameDetection(const render::DetectorSettings& a, const render::DetectorSettings& b) {
  return a.family == b.family && a.decimate == b.decimate && a.sigma == b.sigma &&
         a.refine_edges == b.refine_edges && a.min_edge_px == b.min_edge_px &&
         a.max_view_angle_deg == b.max_view_angle_deg && a.border_margin_px == b.border_margin_px &&
         a.pixel_noise_std == b.pixel_noise_std;
}

}  // namespace

DynamicOptions ParseDynamicOptions(const ConfigNode& root, Rig& rig) {
  DynamicOptions o;
  if (const auto c = root.Optional("tag_camera")) {
    TagCamera tc;
    tc.camera = c->GetString("camera");
    tc.pixel_std_px = c->GetDouble("pixel_std_px", tc.pixel_std_px);
    tc.export_images = c->GetBool("export_images", false);
    if (!(tc.pixel_std_px > 0.0 && tc.pixel_std_px <= 100.0)) {
      c->Child("pixel_std_px").Fail("must be > 0 and at most 100");
    }
    tc.mode = ParseRenderMode(root, tc.mode);
    tc.detector = ParseDetectorSettings(root);
    // A log's frames are detected with the replay's own settings (defaults unless its scenario
    // says otherwise): frames exported under others would replay to other detections.
    if (tc.export_images && !SameDetection(tc.detector, render::DetectorSettings{})) {
      c->Child("export_images")
          .Fail("needs the detector's default settings (a replay detects the frames with its own)");
    }
    tc.cam_id = sim::CameraId(rig.sim->model(), tc.camera, rig.declared.model_path);
    try {
      rig.setup.cameras.push_back({sim::CameraIntrinsics(rig.sim->model(), tc.cam_id),
                                   rig.chain->ObservedFrame(tc.camera)});
    } catch (const InputError& e) {
      c->Child("camera").Fail(e.what());
    }
    tc.tags = render::ApplyTagTextures(rig.sim->mutable_model());
    for (const render::TagInModel& tag : tc.tags) {
      const std::string geom = sim::ObjectName(rig.sim->model(), mjOBJ_GEOM, tag.geom_id);
      for (const auto& [name, frame] : rig.chain->observed) {
        if (name == geom) tc.tag_frames[tag.id] = frame;
      }
    }
    if (tc.tag_frames.empty()) c->Fail("no tag of the model is on an observed frame");
    o.tag_camera = std::move(tc);
  }
  o.filter_rate_hz = root.GetDouble("filter_rate_hz", o.filter_rate_hz);
  if (!(o.filter_rate_hz > 0.0)) root.Child("filter_rate_hz").Fail("must be > 0");
  if (const auto m = root.Optional("madgwick")) {
    o.madgwick_beta = m->GetDouble("beta", o.madgwick_beta);
    if (!(o.madgwick_beta > 0.0)) m->Child("beta").Fail("must be > 0");
    const std::string init = m->GetString("init", "accel");
    if (init != "accel" && init != "truth") m->Child("init").Fail("expected 'accel' or 'truth'");
    o.madgwick_init_truth = init == "truth";
  }
  return o;
}

namespace {

// The IMU readings of every snapshot through the filters the estimators run, for the snapshots'
// own orientations (diagnostics: the yaw drift).
void FilterOrientations(const Rig& rig, std::vector<Snapshot>* snaps) {
  imu::ImuOrientations filters(rig.setup.imus);
  for (Snapshot& s : *snaps) {
    for (const estimators::ImuReading& z : s.imu_raw) filters.Feed(z);
    for (int k = 0; k < filters.size(); ++k) {
      estimators::OrientationReading o = filters.Take(k);
      o.t = s.t;
      s.imus.push_back(o);
    }
  }
}

// The tag camera rendered and run through libapriltag at the simulation's current state.
class TagEyes {
 public:
  TagEyes(const sim::Simulation& sim, const TagCamera& tc)
      : tc_(tc), renderer_(sim.model(), tc.mode), detector_(tc.detector) {}
  // `png`: the frame, encoded, when the run exports its frames.
  std::vector<estimators::TagCorners> Detect(const sim::Simulation& sim, double t,
                                             std::string* png) {
    renderer_.RenderRgbInto(const_cast<mjData*>(sim.data()), tc_.cam_id, &image_);
    if (tc_.export_images) *png = render::EncodePng(image_);
    std::vector<estimators::TagCorners> out;
    for (const estimators::Measurement& m :
         TagMeasurements(detector_.Detect(image_), tc_.tags, tc_.tag_frames, /*corners=*/true,
                         tc_.pixel_std_px, t)) {
      out.push_back(std::get<estimators::TagCorners>(m));
    }
    return out;
  }

 private:
  const TagCamera& tc_;
  render::Renderer renderer_;
  render::TagDetector detector_;
  render::Image image_;
};

}  // namespace

std::vector<Snapshot> SimulateDynamic(Rig& rig, const Trajectory& trajectory,
                                      sim::SensorSuite& sensors, const DynamicOptions& options,
                                      const RunContext& ctx) {
  sim::Simulation& sim = *rig.sim;
  const int nq = rig.nq();
  for (estimators::ImuSetup& imu : rig.setup.imus) {
    imu.filter_beta = options.madgwick_beta;
    imu.has_initial = false;
  }
  std::vector<char> started(rig.imu_sites.size(), 0);
  sim.SetCommand(rig.ToActuators(trajectory.AtTime(0.0)));
  sim.Settle();
  const double t0 = sim.time();
  const double dt = sim.timestep();
  const double period = 1.0 / options.filter_rate_hz;
  const double duration = trajectory.Duration();
  Eigen::VectorXd encoders = Eigen::VectorXd::Constant(nq, std::nan(""));
  std::vector<Snapshot> snaps;
  std::vector<sim::SensorReading> readings;
  std::vector<estimators::ImuReading> imu_raw;
  int next_tick = 1;  // the first snapshot after one filter period
  std::optional<TagEyes> eyes;
  if (options.tag_camera) eyes.emplace(sim, *options.tag_camera);
  const int total_ticks = static_cast<int>(std::floor(duration / period + 1e-9));
  while (sim.time() - t0 < duration - 1e-9) {
    const double t_next = sim.time() - t0 + dt;
    sim.SetCommand(rig.ToActuators(trajectory.AtTime(t_next)));
    sim.Step(1);
    readings.clear();
    sensors.Poll(sim, &readings);
    for (const sim::SensorReading& r : readings) {
      if (const auto* imu = std::get_if<sim::ImuReading>(&r)) {
        const auto it = std::find(rig.imu_sites.begin(), rig.imu_sites.end(), imu->site);
        if (it == rig.imu_sites.end()) continue;
        const size_t k = it - rig.imu_sites.begin();
        if (!started[k] && options.madgwick_init_truth) {
          rig.setup.imus[k].has_initial = true;
          rig.setup.imus[k].q_base_frame_initial = Quat(sim.SitePose(imu->site).linear());
        }
        started[k] = 1;
        imu_raw.push_back(*imu);
        imu_raw.back().imu = static_cast<int>(k);
      } else if (const auto* enc = std::get_if<sim::EncoderReading>(&r)) {
        for (int k = 0; k < nq; ++k) {
          if (rig.chain->q_joints[k] == enc->joint)
            encoders[k] = enc->position - rig.chain->q_qpos0[k];
        }
      }
    }
    const double t = sim.time() - t0;
    if (t + 1e-9 < next_tick * period) continue;
    ++next_tick;
    if (!encoders.allFinite() || std::count(started.begin(), started.end(), 0) > 0) {
      throw InputError(
          "jsk scenario: the sensors must include an encoder for every declared "
          "joint and every IMU, sampled at least at the filter rate");
    }
    Snapshot s;
    s.t = t;
    s.reference = trajectory.AtTime(t, &s.segment);
    s.link = rig.LinkAngles();
    s.joints.t = t;
    s.joints.q = encoders;
    s.joints.std = estimators::JointVector::Zero(nq);
    s.imu_raw.swap(imu_raw);
    for (size_t k = 0; k < rig.imu_frames.size(); ++k) {
      s.imu_true.push_back(Quat(sim.SitePose(rig.imu_sites[k]).linear()));
    }
    const std::string ee = rig.declared.end_effector;
    s.T_true = ToSE3(sim.Pose(ee));
    if (eyes) s.tags = eyes->Detect(sim, t, &s.png);
    snaps.push_back(std::move(s));
    ctx.progress("simulation", static_cast<int>(snaps.size()), total_ticks);
  }
  FilterOrientations(rig, &snaps);
  return snaps;
}

namespace {

// The tag camera, its tags on observed frames and the snapshots' detections, in the log format.
void AddTags(const Rig& rig, const TagCamera& tc, const std::vector<Snapshot>& snaps,
             sim::RecordedLog* log, std::vector<std::pair<std::string, std::string>>* files) {
  AddTagCameraToLog(rig.sim->model(), tc.camera, rig.setup.cameras[0].intrinsics, tc.tags,
                    tc.tag_frames, tc.pixel_std_px, /*centres=*/false, log);
  for (const Snapshot& s : snaps) {
    if (tc.export_images) {
      // The frame's time in whole nanoseconds, not after s.t: read back, its detections come
      // at or before the snapshot's step, as the live run feeds them.
      auto t_ns = static_cast<long long>(std::floor(s.t * 1e9));
      while (1e-9 * static_cast<double>(t_ns) > s.t) --t_ns;
      const std::string name = "images/" + tc.camera + "/" + std::to_string(t_ns) + ".png";
      if (s.png.empty()) throw InputError("--export-log: a frame could not be encoded as PNG");
      log->images.push_back({s.t, 0, name});
      files->emplace_back(name, s.png);
      continue;
    }
    for (const estimators::TagCorners& z : s.tags) {
      sim::LogTagRow row;
      row.t = z.t;
      row.camera = 0;
      row.tag = sim::TagIndex(*log, z.tag_id);
      for (int k = 0; k < 4; ++k) row.uv[k] = z.uv[k];
      log->tag_rows.push_back(row);
    }
  }
}

}  // namespace

void ExportLog(const Rig& rig, const DynamicOptions& options, const std::vector<Snapshot>& snaps,
               const std::string& dir) {
  sim::RecordedLog log = LogOfChain(rig.declared, *rig.chain);
  for (const Snapshot& s : snaps) {
    AddStepToLog(s.joints, s.T_true, &log);
    log.imu.insert(log.imu.end(), s.imu_raw.begin(), s.imu_raw.end());
  }
  for (size_t k = 0; k < rig.imu_sites.size(); ++k) {
    sim::LogImu imu;
    imu.name = imu.frame = rig.imu_sites[k];
    imu.has_initial = rig.setup.imus[k].has_initial;
    imu.q_base_frame_initial = rig.setup.imus[k].q_base_frame_initial;
    imu.filter_beta = rig.setup.imus[k].filter_beta;
    log.imus.push_back(imu);
  }
  std::vector<std::pair<std::string, std::string>> files;
  if (options.tag_camera) AddTags(rig, *options.tag_camera, snaps, &log, &files);
  WriteLogWithDeclared(log, rig.declared, dir, files);
}

Trace RunOnSnapshots(const Rig& rig, const EstimatorSpec& spec, const std::vector<Snapshot>& snaps,
                     std::uint64_t seed, bool with_position, const RunContext& ctx, int* rejected) {
  TracedRun r(rig, spec, seed);
  for (size_t i = 0; i < snaps.size(); ++i) {
    const Snapshot& s = snaps[i];
    for (const estimators::ImuReading& z : s.imu_raw) r.Count(r.est->Update(z));
    r.est->Predict(s.t);
    r.Count(r.est->Update(s.joints));
    if (with_position) {
      estimators::PositionReading p;
      p.t = s.t;
      p.frame = rig.chain->end_effector;
      p.p_base = s.T_true.translation();
      r.Count(r.est->Update(p));
    }
    for (const estimators::TagCorners& z : s.tags) r.Count(r.est->Update(z));
    r.Record(s.t, s.T_true);
    ctx.progress(spec.label, static_cast<int>(i + 1), static_cast<int>(snaps.size()));
  }
  *rejected = r.rejected + r.est->deferred_rejections();
  return std::move(r.trace);
}

}  // namespace flexbench::scenarios::jsk
