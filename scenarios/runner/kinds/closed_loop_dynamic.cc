// closed_loop_dynamic: the closed loop on a moving arm. The truth (MuJoCo physics with effects
// the declared model lacks) is driven through a multi-sine by its position servos; its encoders,
// IMUs and the commands are written as a recorded log (log/), which dynamic identification then
// reads back as a user's log: rollouts of the declared model's MJCF, candidate families,
// selection held to the held-out segments' error, verdict (scenarios/identify/dynamic/).
//
//   truth:
//     effects: {joint_friction: {Nm: {link2_pitch_joint: 0.2}}}
//     duration_s: 12
//     command_rate_hz: 500
//     commands: position      # or torque: the log holds each step's motor torques instead
//     motion: {center_deg: [...], amplitude_deg: [...], frequencies_hz: [f1, f2, f3]}
//   sensors: [...]            # encoders (link side) and IMUs, sim/sensors
//   tag_camera: {camera: external_camera, rate_hz: 30, pixel_std_px: 1}   # optional: the
//                             # rendered tags libapriltag finds, in the log
//                             (common/motion_camera.h)
//   identify: {segment_s: 0.5, folds: 3, max_effects: 3, families: [...], threads: 2,
//              streams: [encoders, imu, tags]}   # the log's streams the residual holds
//   replay_estimators: {fk: {}, ppoe_ekf: {}}   # replay the last fold (default: fk)
//   expected:                 # the truth's effects, as identification names them
//     - {name: joint_friction@link2_pitch_joint, values: [0.2]}
// or, for a recorded log (a user's robot), instead of model/truth/sensors:
//   log: path/to/log          # log.yaml with commands.csv (docs/logs.md)
//   declared: ...             # optional: the log's own declared model by default
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>

#include "estimators/format.h"
#include "render/plot.h"
#include "scenarios/identify/dynamic/select.h"
#include "scenarios/runner/common/dynamic_replay.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/log_images.h"
#include "scenarios/runner/common/motion_camera.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/declared_model.h"
#include "sim/motion_log.h"
#include "sim/recorded_log.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {
namespace {

namespace dyn = identify::dynamic;

struct Expected {
  std::string name;
  std::vector<double> values;
};

class ClosedLoopDynamicKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    if (root.Has("log")) {
      // A recorded log (a user's): its readings are the data; no truth is simulated.
      for (const char* key : {"truth", "sensors", "model", "tag_camera"}) {
        if (root.Has(key)) root.Child(key).Fail("a log is given: nothing is simulated");
      }
      log_dir_ = root.ResolvePath(root.GetString("log"));
      declared_path_ = root.Has("declared") ? root.ResolvePath(root.GetString("declared"))
                                            : sim::ReadRecordedLog(log_dir_).declared_path;
      declared_ = sim::LoadDeclaredModel(declared_path_);
    } else {
      ConfigureTruth(root);
    }
    if (const auto id = root.Optional("identify")) ReadIdentify(*id);
    replay_specs_ =
        root.Has("replay_estimators")
            ? ParseEstimators(root.Child("replay_estimators"), EstimatorLabels::kAllowed)
            : std::vector<EstimatorSpec>{{"fk", {}, "fk", ""}};
    if (const auto ex = root.Optional("expected")) {
      for (const ConfigNode& e : ex->Items()) {
        Expected x;
        x.name = e.GetString("name");
        if (e.Has("values")) x.values = e.Child("values").AsDoubleList();
        expected_.push_back(x);
      }
    }
  }

  void ConfigureTruth(const ConfigNode& root) {
    model_path_ = root.ResolvePath(root.GetString("model"));
    declared_path_ = root.ResolvePath(root.GetString("declared"));
    declared_ = sim::LoadDeclaredModel(declared_path_);
    const ConfigNode truth = root.Child("truth");
    sim::EffectList effects;
    if (const auto e = truth.Optional("effects")) effects = sim::ParseEffects(*e);
    truth_ = sim::Simulation::Load(model_path_, effects);
    duration_s_ = truth.GetDouble("duration_s", 12.0);
    if (!(duration_s_ >= 2.0 && duration_s_ <= 600.0)) {
      truth.Child("duration_s").Fail("must be in [2, 600] s");
    }
    command_rate_hz_ = truth.GetDouble("command_rate_hz", 500.0);
    if (!(command_rate_hz_ > 0.0 && command_rate_hz_ <= 1.0 / truth_->timestep() + 1e-9)) {
      truth.Child("command_rate_hz").Fail("must be > 0 and at most the model's step rate");
    }
    ReadMotion(truth.Child("motion"));
    const std::string commands = truth.GetString("commands", "position");
    if (commands != "position" && commands != "torque") {
      truth.Child("commands").Fail("position (the servos' targets) or torque (the motors')");
    }
    torque_commands_ = commands == "torque";
    sensors_node_ = std::make_unique<ConfigNode>(root.Child("sensors"));
    sim::SensorSuite::Parse(*sensors_node_, *truth_, 0);  // checked now; Run seeds its own
    ReadSensorNoise(*sensors_node_);
    if (const auto c = root.Optional("tag_camera")) {
      MotionCameraSpec spec = ParseMotionCamera(*c, root);
      try {
        camera_ =
            std::make_unique<MotionTagCamera>(*truth_, std::move(spec), declared_.observed_frames);
      } catch (const InputError& e) {
        c->Child("camera").Fail(e.what());
      }
    }
  }

  void Run(RunContext& ctx) override {
    std::string log_dir = log_dir_;
    if (log_dir.empty()) {
      log_dir = ctx.out->File("log").string();
      sim::SensorSuite sensors = sim::SensorSuite::Parse(*sensors_node_, *truth_, ctx.seed);
      sim::RecordedLog log = Simulate(ctx.seed, sensors);
      if (camera_) {
        const int frames = camera_->AddTo(&log);
        ctx.log("tag camera: " + std::to_string(log.tag_rows.size()) + " detections in " +
                std::to_string(frames) + " rendered frames (" + std::to_string(camera_->others()) +
                " of tags on no observed frame left out)");
      }
      sim::WriteRecordedLog(log, log_dir);
      ctx.log("wrote the truth's log (" + ShortNum(duration_s_) + " s) to log/");
    }
    sim::RecordedLog log = sim::ReadRecordedLog(log_dir);
    if (log.tag_rows.empty() && !log.images.empty()) {
      // A log's camera frames: their tags through libapriltag, as tags.csv would give them.
      DetectLogImages(render::DetectorSettings{}, &log);
      ctx.log("detected " + std::to_string(log.tag_rows.size()) + " tags in " +
              std::to_string(log.images.size()) + " frames of the log's images/");
    }
    // The declared file's own dynamic effects stay; the candidates act on top of them.
    std::vector<dyn::DynamicTerm> declared_terms;
    for (const sim::DeclaredDynamic& e : sim::DynamicEntries(declared_.identified_effects)) {
      declared_terms.push_back({e.row->kind, e.location, {e.values[0], e.values[1]}});
    }
    dyn::RolloutModel model(sim::LoadModel(declared_.model_path), declared_.model_path,
                            declared_terms);
    const dyn::MotionData data = dyn::ReadMotionData(log, model.nominal(), motion_options_);
    std::vector<dyn::Candidate> candidates = dyn::AllCandidates(model.nominal(), families_);
    if (data.torque) {
      // The servo is not in the loop of a torque log: its gain and delay act on nothing.
      const auto servo = [](const dyn::Candidate& c) {
        return c.kind == sim::DynamicKind::kServoGain || c.kind == sim::DynamicKind::kServoDelay;
      };
      candidates.erase(std::remove_if(candidates.begin(), candidates.end(), servo),
                       candidates.end());
      ctx.log("torque commands: the servo's gain and delay are not candidates (no servo acts)");
    }
    dyn::DynamicProblem problem(model, data, std::move(candidates), threads_);
    // The static identification's effects, where the declared file has them, as the start.
    const std::vector<sim::StaticCounterpart> warm =
        sim::DynamicCounterparts(model.nominal().model(), model.nominal().catalog(), declared_);
    const dyn::DynamicReport rep = dyn::IdentifyDynamics(problem, options_, warm);
    for (const std::string& line : rep.log) ctx.log(line);
    WriteSummary(rep, ctx);
    WriteFigures(problem, rep, ctx);
    WriteDynamicAugmented(declared_, rep, ctx);
    const sim::MjModelPtr nominal = sim::LoadModel(declared_.model_path);
    ReplayDynamicHeldOut(log, nominal.get(), declared_, rep, replay_specs_, ctx);
  }

 private:
  void ReadMotion(const ConfigNode& m) {
    const int n = truth_->num_actuated();
    const auto list = [&](const char* key, double scale) {
      std::vector<double> v = m.Child(key).AsDoubleList();
      if (static_cast<int>(v.size()) != n) {
        m.Child(key).Fail("expected " + std::to_string(n) + " values (the actuated joints)");
      }
      for (double& x : v) x *= scale;
      return v;
    };
    motion_.center = list("center_deg", M_PI / 180.0);
    motion_.amplitude = list("amplitude_deg", M_PI / 180.0);
    motion_.frequencies = m.Child("frequencies_hz").AsDoubleList();
    if (motion_.frequencies.empty()) m.Child("frequencies_hz").Fail("give at least one");
    for (double f : motion_.frequencies) {
      if (!(f > 0.0 && f < 50.0)) m.Child("frequencies_hz").Fail("each in (0, 50) Hz");
    }
  }

  // The noise the sensors are configured with: what the log states as its readings' noise.
  void ReadSensorNoise(const ConfigNode& list) {
    for (const ConfigNode& s : list.Items()) {
      const std::string kind = s.GetString("kind");
      if (kind == "encoder") std_q_ = s.GetDouble("noise_std_deg", 0.0) * M_PI / 180.0;
      if (kind == "imu") {
        std_gyro_ = s.GetDouble("gyro_noise_std_rad_s", 0.0);
        std_accel_ = s.GetDouble("accel_noise_std_m_s2", 0.0);
      }
    }
  }

  void ReadIdentify(const ConfigNode& id) {
    const auto positive = [&](const char* key, double fallback, double lo, double hi) {
      const double v = id.GetDouble(key, fallback);
      if (!(v >= lo && v <= hi)) {
        id.Child(key).Fail("must be in [" + ShortNum(lo) + ", " + ShortNum(hi) + "]");
      }
      return v;
    };
    motion_options_.segment_s = positive("segment_s", motion_options_.segment_s, 1e-6, 60.0);
    motion_options_.folds = static_cast<int>(positive("folds", motion_options_.folds, 2, 20));
    motion_options_.velocity_window_s =
        positive("velocity_window_s", motion_options_.velocity_window_s, 1e-4, 1.0);
    motion_options_.velocity_degree =
        static_cast<int>(positive("velocity_degree", motion_options_.velocity_degree, 1, 3));
    options_.max_effects = static_cast<int>(positive("max_effects", options_.max_effects, 0, 20));
    options_.cv_min_gain = positive("cv_min_gain", options_.cv_min_gain, 0.0, 0.9);
    options_.iterations = static_cast<int>(positive("iterations", options_.iterations, 1, 100));
    options_.joint_iterations =
        static_cast<int>(positive("joint_iterations", options_.joint_iterations, 0, 100));
    threads_ = static_cast<int>(positive("threads", threads_, 1, 64));
    if (id.Has("families")) {
      for (const ConfigNode& item : id.Child("families").Items()) {
        const std::string f = item.AsString();
        families_.push_back(f);
        const sim::DynamicRow* row = sim::FindDynamic(f);
        if (!row || !row->fitted) id.Child("families").Fail("'" + f + "' is no fitted family");
      }
    }
    if (id.Has("streams")) {
      // The encoders drive every segment's start: always in.
      motion_options_.use_imus = motion_options_.use_tags = false;
      for (const ConfigNode& item : id.Child("streams").Items()) {
        const std::string s = item.AsString();
        if (s == "imu") {
          motion_options_.use_imus = true;
        } else if (s == "tags") {
          motion_options_.use_tags = true;
        } else if (s != "encoders") {
          id.Child("streams").Fail("'" + s + "': expected encoders, imu or tags");
        }
      }
    }
  }

  sim::RecordedLog Simulate(std::uint64_t seed, sim::SensorSuite& sensors) {
    sim::MultiSine motion = motion_;
    motion.DrawPhases(seed, "closed_loop_dynamic/phases", truth_->num_actuated());
    sim::MotionLogOptions o;
    o.duration_s = duration_s_;
    o.command_rate_hz = command_rate_hz_;
    o.encoder_std = std_q_;
    o.gyro_std = std_gyro_;
    o.accel_std = std_accel_;
    o.declared_path = std::filesystem::absolute(declared_path_).lexically_normal().string();
    o.torque_commands = torque_commands_;
    o.truth_frame = declared_.end_effector;
    o.base_body = declared_.base;
    if (camera_) o.after_poll = [this](const sim::Simulation& s) { camera_->AfterPoll(s); };
    return sim::SimulateMotionLog(*truth_, sensors, motion, o);
  }

  void WriteSummary(const dyn::DynamicReport& rep, RunContext& ctx) const {
    Json& m = (*ctx.summary)["metrics"];
    m["verdict"] = rep.verdict;
    m["segments"] = rep.segments;
    m["diverged_segments"] = rep.diverged_declared;
    m["heldout_before"] = rep.heldout_before;
    m["heldout_after"] = rep.heldout_after;
    m["heldout_ratio"] = rep.heldout_after / rep.heldout_before;
    m["rollouts"] = rep.rollouts;
    m["selection_capped"] = !rep.capped.empty();
    // Per stream, the residual's RMS with the chosen effects over without (gates read it).
    for (const dyn::StreamError& st : rep.streams) {
      if (st.rms_before > 0.0) m["stream_rms_ratio"][st.stream] = st.rms_after / st.rms_before;
    }
    Json chosen = Json::array();
    bool named = !expected_.empty();
    bool within = true;
    std::vector<bool> found(expected_.size(), false);
    for (const dyn::ChosenEffect& c : rep.chosen) {
      Json e;
      e["name"] = c.name;
      for (size_t k = 0; k < c.values.size(); ++k) {
        e["values"][c.value_names[k]] = c.values[k];
        e["std_errors"][c.value_names[k]] = c.std_errors[k];
      }
      e["equivalent"] = c.equivalent;
      chosen.push_back(e);
      bool matched = false;
      for (size_t x = 0; x < expected_.size(); ++x) {
        const bool same = c.name == expected_[x].name ||
                          std::find(c.equivalent.begin(), c.equivalent.end(), expected_[x].name) !=
                              c.equivalent.end();
        if (!same) continue;
        matched = found[x] = true;
        if (c.name != expected_[x].name) continue;
        for (size_t k = 0; k < expected_[x].values.size() && k < c.values.size(); ++k) {
          within &= std::abs(c.values[k] - expected_[x].values[k]) <= 3.0 * c.std_errors[k];
        }
      }
      named &= matched;
    }
    for (bool f : found) named &= f;
    m["effects_named"] = named;
    m["params_within_3sigma"] = within;
    m["explained"] = rep.verdict == "explained";
    Json streams = Json::array();
    for (const dyn::StreamError& s : rep.streams) {
      Json e;
      e["stream"] = s.stream;
      e["unit"] = s.unit;
      e["noise"] = s.noise;
      e["noise_from_log"] = s.noise_from_log;
      e["entries"] = s.entries;
      e["rms_before"] = s.rms_before;
      e["rms_after"] = s.rms_after;
      streams.push_back(e);
    }
    Json& d = (*ctx.summary)["dynamic_identification"];
    d["chosen"] = chosen;
    d["streams"] = streams;
    d["log"] = rep.log;
    if (!rep.first_divergence.empty()) d["first_divergence"] = rep.first_divergence;
  }

  // The declared model's residual spectrum against the fit's, for the channel whose residual the
  // fit lowered most, and an encoder's residual in time, before and after; spectra.csv holds
  // every channel's.
  void WriteFigures(const dyn::DynamicProblem& p, const dyn::DynamicReport& rep,
                    RunContext& ctx) const {
    const dyn::MotionDiagnostics before = dyn::Diagnose(p, rep.declared_state.prediction);
    const auto& after = rep.diagnostics.spectra;
    std::ofstream csv(ctx.out->File("spectra.csv"));
    csv << "channel,frequency_hz,psd_before,psd_after\n";
    int best = -1;
    double best_drop = 0.0;
    for (size_t c = 0; c < before.spectra.size() && c < after.size(); ++c) {
      const dyn::Spectrum& b = before.spectra[c].spectrum;
      const dyn::Spectrum& a = after[c].spectrum;
      double sb = 0.0, sa = 0.0;
      for (size_t k = 0; k < b.psd.size() && k < a.psd.size(); ++k) {
        csv << before.spectra[c].channel << "," << ExactNum(b.frequency_hz[k]) << ","
            << ExactNum(b.psd[k]) << "," << ExactNum(a.psd[k]) << "\n";
        sb += b.psd[k];
        sa += a.psd[k];
      }
      if (before.spectra[c].channel.rfind("encoder", 0) != 0 && sb - sa > best_drop) {
        best_drop = sb - sa;
        best = static_cast<int>(c);
      }
    }
    render::Figure fig(1000, 800, 2, 1);
    if (best >= 0) {
      render::Axes& ax = fig.axes(0, 0);
      ax.title = "residual spectrum: " + before.spectra[best].channel;
      ax.x_label = "frequency [Hz]";
      ax.y_label = "PSD [noise std^2 / Hz]";
      ax.y_log = true;
      ax.x_min = 0.0;
      ax.x_max = before.spectra[best].spectrum.rate_hz / 2;
      ax.legend_position = render::LegendPosition::kTopRight;
      ax.AddLine("declared model", before.spectra[best].spectrum.frequency_hz,
                 before.spectra[best].spectrum.psd);
      ax.AddLine("with the chosen effects", after[best].spectrum.frequency_hz,
                 after[best].spectrum.psd);
    }
    const dyn::ResidualLayout& L = p.layout();
    int joint = 0;
    double worst = -1.0;
    for (int j = 0; j < static_cast<int>(p.data().joints.size()); ++j) {
      double e = 0.0;
      for (int k = 0; k < L.size(); ++k) {
        if (L.stream[k] == 0 && L.channel[k] == j) {
          e += std::pow(rep.declared_state.prediction.error[k], 2);
        }
      }
      if (e > worst) worst = e, joint = j;
    }
    std::vector<double> t, eb, ea;
    for (int k = 0; k < L.size(); ++k) {
      if (L.stream[k] != 0 || L.channel[k] != joint || L.t[k] > p.data().t.front() + 4.0) continue;
      t.push_back(L.t[k]);
      eb.push_back(1e3 * rep.declared_state.prediction.error[k]);
      ea.push_back(1e3 * rep.final_state.prediction.error[k]);
    }
    render::Axes& ax = fig.axes(1, 0);
    ax.title = "encoder " + p.data().joints[joint] + ": prediction - reading, first 4 s";
    ax.x_label = "time [s]";
    if (!t.empty()) {
      ax.x_min = t.front();
      ax.x_max = t.back();
    }
    ax.y_label = "residual [mrad]";
    ax.AddLine("declared model", t, eb);
    ax.AddLine("with the chosen effects", t, ea);
    fig.SavePng(ctx.out->File("dynamic_residual.png").string());
  }

  std::string model_path_, declared_path_;
  std::string log_dir_;  // a recorded log to identify from; empty: the truth's, simulated
  sim::DeclaredModel declared_;
  std::unique_ptr<sim::Simulation> truth_;
  double duration_s_ = 12.0, command_rate_hz_ = 500.0;
  bool torque_commands_ = false;  // the log's commands: the motors' torques
  sim::MultiSine motion_;
  std::unique_ptr<ConfigNode> sensors_node_;
  std::unique_ptr<MotionTagCamera> camera_;  // tag_camera: the truth's rendered tags
  double std_q_ = 0.0, std_gyro_ = 0.0, std_accel_ = 0.0;
  dyn::MotionOptions motion_options_;
  dyn::DynamicIdentifyOptions options_;
  std::vector<std::string> families_;
  int threads_ = 2;
  std::vector<Expected> expected_;
  std::vector<EstimatorSpec> replay_specs_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeClosedLoopDynamicKind() {
  return std::make_unique<ClosedLoopDynamicKind>();
}

}  // namespace flexbench::scenarios
