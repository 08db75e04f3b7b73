// rover_deflection: sweep the rover arm from folded to stretched out in several directions,
// settle the truth (base-plate compliance, elastic links ...) under gravity at every
// configuration and compare it with the nominal kinematics. Writes one CSV per configuration
// (true and nominal frames), deflection.csv (one row per configuration), deflection.png
// (deflection and plate tilt against reach) and mast-camera frames with their tag detections.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>

#include "estimators/camera/pinhole.h"
#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/format.h"
#include "render/plot.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/camera.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {
namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point a) {
  return std::chrono::duration<double>(Clock::now() - a).count();
}

double RotationAngleDeg(const Mat3& a, const Mat3& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle() / kDeg;
}

struct Config {
  int index = 0;
  double direction_deg = 0.0;
  double alpha = 0.0;  // 0 folded .. 1 stretched out
  Eigen::VectorXd q;   // actuated joints, actuator order
};

struct Result {
  double reach = 0.0;
  double tilt_soft = 0.0;   // deg
  double tilt_stiff = 0.0;  // deg
  Vec3 ee_delta = Vec3::Zero();
  double ee_deflection = 0.0;
  double ee_rot_deg = 0.0;
  int iterations = 0;
  double residual = 0.0;
};

class RoverDeflectionKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    const ConfigNode model = root.Child("model");
    model_path_ = model.ResolvePath(model.AsString());
    end_effector_ = root.GetString("end_effector", "ee");
    reach_joint_ = root.GetString("reach_from_joint", "j1");
    if (const auto t = root.Optional("tilt_joints")) {
      soft_joint_ = t->GetString("soft", soft_joint_);
      stiff_joint_ = t->GetString("stiff", stiff_joint_);
    }
    if (const auto e = root.Optional("effects")) effects_ = sim::ParseEffects(*e);
    // The truth, built now: MJCF errors, unsupported effects and bad names fail before any work.
    sim_ = sim::Simulation::Load(model_path_, effects_);
    const mjModel* m = sim_->model();
    sim::SiteId(m, end_effector_, model_path_);
    sim::JointId(m, reach_joint_, model_path_);
    soft_id_ = sim::JointId(m, soft_joint_, model_path_);
    stiff_id_ = sim::JointId(m, stiff_joint_, model_path_);
    if (const auto f = root.Optional("frames")) {
      for (const ConfigNode& item : f->Items()) {
        frames_.push_back(item.AsString());
        try {
          sim_->Frame(frames_.back());
        } catch (const InputError& e) {
          item.Fail(e.what());
        }
      }
    }
    if (std::find(frames_.begin(), frames_.end(), end_effector_) == frames_.end()) {
      frames_.insert(frames_.begin(), end_effector_);
    }

    const ConfigNode sweep = root.Child("sweep");
    direction_joint_ = sweep.GetString("direction_joint", "j1");
    ActuatedIndex(sweep, direction_joint_);
    const ConfigNode dirs = sweep.Child("directions_deg");
    directions_ = dirs.AsDoubleList();
    if (directions_.empty()) dirs.Fail("needs at least one direction");
    const ConfigNode steps = sweep.Child("steps");
    steps_ = steps.AsInt();
    if (steps_ < 2) steps.Fail("needs at least 2 steps (folded and stretched out)");
    folded_ = ReadPose(sweep.Child("folded_deg"));
    stretched_ = ReadPose(sweep.Child("outstretched_deg"));
    if (const auto fixed = sweep.Optional("fixed_deg")) fixed_ = ReadPose(*fixed);

    if (const auto cam = root.Optional("camera")) {
      camera_ = cam->GetString("name");
      camera_id_ = sim::CameraId(m, camera_, model_path_);
      pan_index_ = ActuatedIndex(*cam, cam->GetString("pan_joint"));
      tilt_index_ = ActuatedIndex(*cam, cam->GetString("tilt_joint"));
      aim_body_ = cam->GetString("aim_body");
      sim::BodyId(m, aim_body_, model_path_);
    }
    if (const auto r = root.Optional("render")) {
      if (camera_.empty()) r->Fail("rendering needs a camera section");
      if (const auto mode = r->Optional("mode")) {
        mode_ = render::ParseRenderMode(mode->AsString(), mode->WhereKey());
      }
      const int n = static_cast<int>(directions_.size()) * steps_;
      for (const ConfigNode& item : r->Child("configurations").Items()) {
        const int c = item.AsInt();
        if (c < 0 || c >= n) item.Fail("configuration index outside 0.." + std::to_string(n - 1));
        render_configs_.insert(c);
      }
      overview_ = r->GetString("overview_camera", "");
      if (!overview_.empty()) overview_id_ = sim::CameraId(m, overview_, model_path_);
    }
    // Sensors are validated now (seed 0) and built again with the run's seed.
    sensors_node_ = root.Optional("sensors");
    if (sensors_node_) sim::SensorSuite::Parse(*sensors_node_, *sim_, 0);
  }

  void Run(RunContext& ctx) override {
    sim::Simulation& sim = *sim_;
    sim::SensorSuite sensors;
    if (sensors_node_) sensors = sim::SensorSuite::Parse(*sensors_node_, sim, ctx.seed);
    const std::vector<Config> configs = MakeConfigs();
    const sim::FrameRef ee = sim.Frame(end_effector_);
    const int reach_joint = sim::JointId(sim.model(), reach_joint_);

    std::vector<Result> results;
    double settle_s = 0.0;
    for (const Config& c : configs) {
      sim.SetCommand(c.q);
      const auto t0 = Clock::now();
      const sim::SettleReport rep = sim.Settle();
      settle_s += Seconds(t0);
      Result r;
      r.iterations = rep.iterations;
      r.residual = rep.residual;
      r.tilt_soft = sim.JointPosition(soft_id_) / kDeg;
      r.tilt_stiff = sim.JointPosition(stiff_id_) / kDeg;
      const Eigen::Isometry3d T_true = sim.Pose(ee);
      const Eigen::Isometry3d T_nom = sim.NominalPose(ee, c.q);
      r.ee_delta = T_true.translation() - T_nom.translation();
      r.ee_deflection = r.ee_delta.norm();
      r.ee_rot_deg = RotationAngleDeg(T_true.linear(), T_nom.linear());
      // Reach: horizontal distance of the nominal end effector from the reach joint's axis.
      const Eigen::Isometry3d T_axis = sim.NominalPose(
          sim::FrameRef{sim::FrameType::kBody, sim.model()->jnt_bodyid[reach_joint], ""}, c.q);
      const Vec3 d = T_nom.translation() - T_axis.translation();
      r.reach = std::hypot(d.x(), d.y());
      results.push_back(r);
      std::vector<double> passive;
      for (const sim::JointEntry& j : sim.catalog().joints) {
        if (j.role != sim::JointRole::kActuated) passive.push_back(sim.JointPosition(j.id) / kDeg);
      }
      passive_angles_.push_back(passive);

      WriteConfigCsv(ctx, sim, c);
      if (!sensors.empty()) {
        std::vector<sim::SensorReading> readings;
        sensors.SampleAll(sim, static_cast<double>(c.index), &readings);
        std::ofstream out(ctx.out->File(ConfigName(c.index) + "_sensors.csv"));
        sim::WriteReadingsCsvHeader(out);
        for (const auto& reading : readings) sim::WriteReadingCsv(out, reading);
        sensor_readings_ += static_cast<int>(readings.size());
      }
      if (render_configs_.count(c.index)) RenderFrames(ctx, sim, c);
      ctx.progress("configurations", c.index + 1, static_cast<int>(configs.size()));
    }
    (*ctx.timing)["settle_s"] = settle_s;
    (*ctx.timing)["settle_per_configuration_ms"] = 1e3 * settle_s / configs.size();

    WriteSummaryCsv(ctx, configs, results);
    WritePlot(ctx, configs, results);
    FillMetrics(ctx, configs, results);
  }

 private:
  int ActuatedIndex(const ConfigNode& where, const std::string& joint) const {
    const auto& names = sim_->actuated_joints();
    const auto it = std::find(names.begin(), names.end(), joint);
    if (it == names.end()) where.Fail(model_path_ + " has no actuated joint named '" + joint + "'");
    return static_cast<int>(it - names.begin());
  }

  std::map<int, double> ReadPose(const ConfigNode& node) const {
    std::map<int, double> pose;
    for (const std::string& joint : node.Keys()) {
      pose[ActuatedIndex(node, joint)] = node.GetDouble(joint) * kDeg;
    }
    return pose;
  }

  std::vector<Config> MakeConfigs() const {
    std::vector<Config> configs;
    const int dir_index = ActuatedIndexNoThrow(direction_joint_);
    for (double dir : directions_) {
      for (int k = 0; k < steps_; ++k) {
        Config c;
        c.index = static_cast<int>(configs.size());
        c.direction_deg = dir;
        c.alpha = static_cast<double>(k) / (steps_ - 1);
        c.q = Eigen::VectorXd::Zero(sim_->num_actuated());
        for (const auto& [i, v] : fixed_) c.q[i] = v;
        for (const auto& [i, v] : folded_) c.q[i] = v;
        for (const auto& [i, v] : stretched_) {
          const double a = folded_.count(i) ? folded_.at(i) : c.q[i];
          c.q[i] = a + c.alpha * (v - a);
        }
        c.q[dir_index] = dir * kDeg;
        if (!camera_.empty()) AimCamera(&c.q);
        configs.push_back(c);
      }
    }
    return configs;
  }

  int ActuatedIndexNoThrow(const std::string& joint) const {
    const auto& names = sim_->actuated_joints();
    return static_cast<int>(std::find(names.begin(), names.end(), joint) - names.begin());
  }

  // Pan and tilt so that the aim body's +x points at the nominal end effector (pan about z,
  // tilt about y: positive tilt looks down).
  void AimCamera(Eigen::VectorXd* q) const {
    (*q)[pan_index_] = 0.0;
    (*q)[tilt_index_] = 0.0;
    const Vec3 target = sim_->NominalPose(end_effector_, *q).translation();
    const Vec3 eye = sim_->NominalPose(aim_body_, *q).translation();
    const Vec3 d = target - eye;
    (*q)[pan_index_] = std::atan2(d.y(), d.x());
    (*q)[tilt_index_] = std::atan2(-d.z(), std::hypot(d.x(), d.y()));
  }

  static std::string ConfigName(int index) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "configs/config_%02d", index);
    return buf;
  }

  void WriteConfigCsv(RunContext& ctx, sim::Simulation& sim, const Config& c) const {
    std::ofstream out(ctx.out->File(ConfigName(c.index) + ".csv"));
    out << "frame,true_x_m,true_y_m,true_z_m,nominal_x_m,nominal_y_m,nominal_z_m,dx_m,dy_m,dz_m,"
           "dpos_m,drot_deg\n";
    char line[512];
    for (const std::string& name : frames_) {
      const sim::FrameRef f = sim.Frame(name);
      const Eigen::Isometry3d T = sim.Pose(f);
      const Eigen::Isometry3d N = sim.NominalPose(f, c.q);
      const Vec3 d = T.translation() - N.translation();
      std::snprintf(line, sizeof(line),
                    "%s,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.6f\n", name.c_str(),
                    T.translation().x(), T.translation().y(), T.translation().z(),
                    N.translation().x(), N.translation().y(), N.translation().z(), d.x(), d.y(),
                    d.z(), d.norm(), RotationAngleDeg(T.linear(), N.linear()));
      out << line;
    }
  }

  void WriteSummaryCsv(RunContext& ctx, const std::vector<Config>& configs,
                       const std::vector<Result>& results) const {
    std::ofstream out(ctx.out->File("deflection.csv"));
    out << "config,direction_deg,alpha,reach_m";
    for (const std::string& j : sim_->actuated_joints()) out << "," << j << "_deg";
    const sim::ModelCatalog& cat = sim_->catalog();
    std::vector<int> passive;
    for (const sim::JointEntry& j : cat.joints) {
      if (j.role != sim::JointRole::kActuated) passive.push_back(j.id);
    }
    for (int j : passive) out << "," << cat.Joint(j).name << "_deg";
    out << ",ee_dx_m,ee_dy_m,ee_dz_m,ee_deflection_m,ee_rot_err_deg,settle_iterations,"
           "settle_residual_Nm\n";
    // Passive joint angles were recorded at each configuration (passive_angles_).
    for (size_t i = 0; i < configs.size(); ++i) {
      const Config& c = configs[i];
      const Result& r = results[i];
      out << c.index << "," << Fmt("%.3f", c.direction_deg) << "," << Fmt("%.6f", c.alpha) << ","
          << Fmt("%.9f", r.reach);
      for (int k = 0; k < c.q.size(); ++k) out << "," << Fmt("%.6f", c.q[k] / kDeg);
      for (size_t k = 0; k < passive.size(); ++k) {
        out << "," << Fmt("%.9f", passive_angles_.at(i).at(k));
      }
      out << "," << Fmt("%.9f", r.ee_delta.x()) << "," << Fmt("%.9f", r.ee_delta.y()) << ","
          << Fmt("%.9f", r.ee_delta.z()) << "," << Fmt("%.9f", r.ee_deflection) << ","
          << Fmt("%.6f", r.ee_rot_deg) << "," << r.iterations << "," << Fmt("%.3e", r.residual)
          << "\n";
    }
  }

  void WritePlot(RunContext& ctx, const std::vector<Config>& configs,
                 const std::vector<Result>& results) const {
    render::Figure fig(1100, 460, 1, 2);
    fig.title = "rover_arm: truth against nominal kinematics, folded to stretched out";
    render::Axes& a = fig.axes(0, 0);
    a.title = "End-effector deflection";
    a.x_label = "reach [m]";
    a.y_label = "|p_true - p_nominal| [cm]";
    a.y_min = 0.0;
    render::Axes& b = fig.axes(0, 1);
    b.title = "Base-plate tilt (solid: soft pitch, dashed: stiff roll)";
    b.x_label = "reach [m]";
    b.y_label = "tilt [deg]";
    b.y_min = 0.0;
    const render::Marker markers[] = {render::Marker::kCircle, render::Marker::kSquare,
                                      render::Marker::kTriangle, render::Marker::kDiamond};
    for (size_t d = 0; d < directions_.size(); ++d) {
      std::vector<double> reach, defl, soft, stiff;
      for (size_t i = 0; i < configs.size(); ++i) {
        if (static_cast<int>(i) / steps_ != static_cast<int>(d)) continue;
        reach.push_back(results[i].reach);
        defl.push_back(100.0 * results[i].ee_deflection);
        soft.push_back(std::abs(results[i].tilt_soft));
        stiff.push_back(std::abs(results[i].tilt_stiff));
      }
      const std::string label = direction_joint_ + " = " + Fmt("%g", directions_[d]) + " deg";
      const render::Rgb color = render::PaletteColor(static_cast<int>(d));
      render::Series& s = a.AddLine(label, reach, defl);
      s.color = color;
      s.marker = markers[d % 4];
      render::Series& s1 = b.AddLine(label, reach, soft);
      s1.color = color;
      s1.marker = markers[d % 4];
      render::Series& s2 = b.AddLine("", reach, stiff);
      s2.color = color;
      s2.line = render::LineStyle::kDashed;
      s2.marker = markers[d % 4];
      s2.marker_size = 3;
    }
    a.AddHLine(1.0, "gate 1 cm");
    a.AddHLine(3.0, "gate 3 cm");
    fig.SavePng(ctx.out->File("deflection.png").string());
  }

  void RenderFrames(RunContext& ctx, sim::Simulation& sim, const Config& c) {
    if (!renderer_) {
      tags_ = render::ApplyTagTextures(sim.mutable_model());
      renderer_ = std::make_unique<render::Renderer>(sim.model(), mode_);
      detector_ = std::make_unique<render::TagDetector>(render::DetectorSettings{});
      ctx.log("GL_RENDERER: " + renderer_->gl_renderer());
    }
    mjData* d = const_cast<mjData*>(sim.data());
    char name[64];
    std::snprintf(name, sizeof(name), "mast_config_%02d.png", c.index);
    const render::Image frame = renderer_->RenderRgb(d, camera_id_);
    render::WritePng(frame, (ctx.out->FramesDir() / name).string());
    if (overview_id_ >= 0) {
      std::snprintf(name, sizeof(name), "overview_config_%02d.png", c.index);
      render::WritePng(renderer_->RenderRgb(d, overview_id_),
                       (ctx.out->FramesDir() / name).string());
    }
    // Detections against the true corners projected through the true camera.
    const render::DetectionResult det = detector_->Detect(frame);
    const PinholeCamera cam = sim::CameraIntrinsics(sim.model(), camera_id_);
    const Eigen::Isometry3d T_cam_w = sim::WorldFromOptical(d, camera_id_).inverse();
    int found = 0;
    for (const render::TagDetection& t : det.detections) {
      for (const render::TagInModel& tag : tags_) {
        if (tag.id != t.id) continue;
        ++found;
        const auto corners = render::TagCornersWorld(d, tag);
        for (int k = 0; k < 4; ++k) {
          Eigen::Vector2d uv;
          if (!cam.Project(T_cam_w * corners[k], &uv)) continue;
          corner_sq_ += (t.corners[k] - uv).squaredNorm();
          ++corner_n_;
        }
      }
    }
    tags_detected_.push_back(found);
  }

  void FillMetrics(RunContext& ctx, const std::vector<Config>& configs,
                   const std::vector<Result>& results) const {
    double soft_max = 0, stiff_max = 0, defl_max = 0, rot_max = 0, reach_max = 0;
    double soft_folded = 0, soft_out = 0, defl_folded = 0, defl_out_sum = 0, residual_max = 0;
    int n_out = 0, it_max = 0;
    for (size_t i = 0; i < configs.size(); ++i) {
      const Result& r = results[i];
      soft_max = std::max(soft_max, std::abs(r.tilt_soft));
      stiff_max = std::max(stiff_max, std::abs(r.tilt_stiff));
      defl_max = std::max(defl_max, r.ee_deflection);
      rot_max = std::max(rot_max, r.ee_rot_deg);
      reach_max = std::max(reach_max, r.reach);
      residual_max = std::max(residual_max, r.residual);
      it_max = std::max(it_max, r.iterations);
      if (configs[i].alpha == 0.0) {
        soft_folded = std::max(soft_folded, std::abs(r.tilt_soft));
        defl_folded = std::max(defl_folded, r.ee_deflection);
      }
      if (configs[i].alpha == 1.0) {
        soft_out = std::max(soft_out, std::abs(r.tilt_soft));
        defl_out_sum += r.ee_deflection;
        ++n_out;
      }
    }
    Json& m = (*ctx.summary)["metrics"];
    m["configurations"] = static_cast<int>(configs.size());
    m["effects"] = sim_->effect_names();
    m["tilt_soft_deg_max"] = soft_max;
    m["tilt_stiff_deg_max"] = stiff_max;
    m["tilt_soft_folded_deg_max"] = soft_folded;
    m["tilt_soft_outstretched_deg_max"] = soft_out;
    m["ee_deflection_max_m"] = defl_max;
    m["ee_deflection_folded_max_m"] = defl_folded;
    m["ee_deflection_outstretched_mean_m"] = n_out ? defl_out_sum / n_out : 0.0;
    m["ee_rot_err_max_deg"] = rot_max;
    m["reach_max_m"] = reach_max;
    m["settle_iterations_max"] = it_max;
    m["settle_residual_max_Nm"] = residual_max;
    if (sensor_readings_ > 0) m["sensor_readings"] = sensor_readings_;
    if (!tags_detected_.empty()) {
      m["frames_rendered"] = static_cast<int>(tags_detected_.size());
      m["tags_detected_min"] = *std::min_element(tags_detected_.begin(), tags_detected_.end());
      m["tag_corner_rmse_px"] = corner_n_ ? Json(std::sqrt(corner_sq_ / corner_n_)) : Json();
    }
  }

  std::string model_path_;
  std::string end_effector_;
  std::string reach_joint_;
  std::string soft_joint_ = "plate_pitch";
  std::string stiff_joint_ = "plate_roll";
  int soft_id_ = -1;
  int stiff_id_ = -1;
  std::vector<std::string> frames_;
  sim::EffectList effects_;
  std::unique_ptr<sim::Simulation> sim_;
  std::string direction_joint_;
  std::vector<double> directions_;
  int steps_ = 0;
  std::map<int, double> folded_, stretched_, fixed_;
  std::string camera_;
  int camera_id_ = -1;
  int pan_index_ = -1;
  int tilt_index_ = -1;
  std::string aim_body_;
  render::RenderMode mode_ = render::RenderMode::kQuality;
  std::set<int> render_configs_;
  std::string overview_;
  int overview_id_ = -1;
  std::optional<ConfigNode> sensors_node_;
  std::vector<std::vector<double>> passive_angles_;
  int sensor_readings_ = 0;
  std::vector<render::TagInModel> tags_;
  std::unique_ptr<render::Renderer> renderer_;
  std::unique_ptr<render::TagDetector> detector_;
  std::vector<int> tags_detected_;
  double corner_sq_ = 0.0;
  int corner_n_ = 0;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeRoverDeflectionKind() {
  return std::make_unique<RoverDeflectionKind>();
}

}  // namespace flexbench::scenarios
