// A recorded log (sim/recorded_log.h: joints, IMUs, tag detections, the truth) replayed through the
// estimators, as a simulated run is: the same estimators, TUM trajectories, metrics and gates.
//
//   kind: replay
//   log: logs/jsk_arm          # the log folder (relative to this file); its log.yaml names the
//                              # declared model
//   declared: my_arm.declared.yaml   # optional: another declared model (an augmented one)
//   step_hz: 0                 # 0: an estimator step at each joints.csv row; else a step at
//                              # the latest row at or before each tick of this rate, at its time
//   estimators: {fk: {}, pf_encoders_imu: {particles: 2048}}
//   imu_clock_offset: estimate     # optional: the IMU stream's clock offset against the joints,
//   clock_offset_range_s: 0.5      # from the data (common/clock_offset.h), within +-range
//
// A step (common/log_replay.h): the IMU readings up to its time (in time order), Predict, the
// joint reading, the tag detections up to its time, the estimate. Joint angles are the declared
// model's joint variables (zero at its zero), matched to the declared joints by column name.
// Metrics per estimator, against truth.tum interpolated at the steps inside its span (when the log
// has one): ErrorStats' position and rotation errors, NEES, steps_scored, rejected_readings.
// Scenario metrics: steps, duration_s, and per stream rows, duplicates, gaps, median_dt_s,
// clock_offset_s; a stream without time overlap with the joints is warned about and counted
// (streams_without_overlap); an estimated IMU clock offset (imu_clock_offset_s, its standard error
// _std_s and the correlation at it), added to the IMU times before the estimators see them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>

#include "estimators/error.h"
#include "scenarios/runner/common/clock_offset.h"
#include "scenarios/runner/common/error_stats.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/log_images.h"
#include "scenarios/runner/common/log_replay.h"
#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/common/render_config.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {
namespace {

using estimators::Belief;

class ReplayKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    log_ = sim::ReadRecordedLog(root.ResolvePath(root.GetString("log")));
    other_tags_ = DetectLogImages(ParseDetectorSettings(root), &log_);
    const auto declared = root.Optional("declared");
    sim::DeclaredModel d = sim::LoadDeclaredModel(declared ? root.ResolvePath(declared->AsString())
                                                           : log_.declared_path);
    model_ = sim::LoadModel(d.model_path);
    rig_ = BuildLogRig(log_, model_.get(), std::move(d), &index_);
    step_hz_ = root.GetDouble("step_hz", 0.0);
    if (!(step_hz_ >= 0.0) || !std::isfinite(step_hz_)) {
      root.Child("step_hz").Fail("must be 0 (a step per joint row) or a rate > 0 in Hz");
    }
    if (step_hz_ > 0.0 && (log_.static_postures || !log_.posture_starts.empty())) {
      root.Child("step_hz").Fail(
          "a log of postures (static_postures, postures.csv) is replayed a joint row a step");
    }
    if (const auto c = root.Optional("imu_clock_offset")) {
      if (c->AsString() != "estimate") c->Fail("expected 'estimate' (or leave it out)");
      if (log_.imu.empty()) c->Fail("the log has no IMU readings");
      estimate_offset_ = true;
      offset_range_s_ = root.GetDouble("clock_offset_range_s", 0.5);
      if (!(offset_range_s_ > 0.0 && offset_range_s_ <= 60.0)) {
        root.Child("clock_offset_range_s").Fail("must be > 0 and at most 60 (seconds)");
      }
    }
    specs_ = ParseEstimators(root.Child("estimators"), EstimatorLabels::kAllowed);
    for (const EstimatorSpec& e : specs_) Make(e, 0);  // bad parameters fail before any work
  }

  void Run(RunContext& ctx) override {
    WriteStreamMetrics(ctx);
    if (estimate_offset_) AlignImuClock(ctx);
    const std::vector<LogStep> steps = LogSteps(log_, step_hz_);
    const std::vector<size_t> imu_order = ImuTimeOrder(log_);
    TrajectoryRecorder recorder;
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < specs_.size(); ++e) {
      const bool first = e == 0;
      const std::string& label = specs_[e].label;
      ErrorStats stats;
      const std::unique_ptr<estimators::Estimator> est = Make(specs_[e], ctx.seed);
      const int rejected =
          ReplayLog(log_, index_, steps, imu_order, *est, [&](size_t s, const Belief& b) {
            const double t = steps[s].t;
            lie::SE3 T_true;
            if (sim::TruthAt(log_, t, &T_true)) {
              stats.Add(b.T_base_ee, b.cov, T_true);
              if (first) recorder.AddTruth(t, T_true);
            }
            recorder.Add(label, t, b.T_base_ee, b.cov);
            if (s % 256 == 0 || s + 1 == steps.size()) {
              ctx.progress(label, static_cast<int>(s + 1), static_cast<int>(steps.size()));
            }
          });
      Json& m = all[label]["metrics"];
      if (stats.count() > 0) stats.WriteMetrics(&m);
      m["steps_scored"] = stats.count();
      m["rejected_readings"] = rejected;
    }
    FittedRangeCheck range(rig_.declared, log_.joints, model_.get(), rig_.chain.get());
    const int columns = static_cast<int>(log_.joints.size());
    for (size_t r = 0; r < log_.joint_t.size(); ++r) {
      range.Observe(log_.joint_q.data() + r * columns, columns);
    }
    range.Report(ctx);
    (*ctx.summary)["metrics"]["steps"] = static_cast<int>(steps.size());
    // The coordinates: the declared base frame, or the frame the log's estimates are in.
    recorder.Write(*ctx.out, log_.estimate_in.empty() ? "base" : log_.estimate_in);
  }

 private:
  void WriteStreamMetrics(const RunContext& ctx) const {
    Json& m = (*ctx.summary)["metrics"];
    m["duration_s"] = log_.joint_stats.t_last - log_.joint_stats.t_first;
    int without_overlap = 0;
    const auto stream = [&](const char* name, const sim::StreamStats& s) {
      if (s.file.empty()) return;
      Json& j = m["streams"][name];
      j["rows"] = s.rows;
      j["duplicates"] = s.duplicates;
      j["gaps"] = s.gaps;
      j["median_dt_s"] = s.median_dt_s;
      j["clock_offset_s"] = s.clock_offset_s;
      if (s.rows > 0 &&
          (s.t_last < log_.joint_stats.t_first || s.t_first > log_.joint_stats.t_last)) {
        ++without_overlap;
        ctx.log(std::string("warning: ") + s.file + " has no time in common with the joints");
      }
    };
    stream("joints", log_.joint_stats);
    stream("imu", log_.imu_stats);
    stream("truth", log_.truth_stats);
    stream("tags", log_.tag_stats);
    stream("contacts", log_.contact_stats);
    stream("orientations", log_.orientation_stats);
    stream("positions", log_.position_stats);
    if (!log_.images.empty()) {
      m["streams"]["images"]["rows"] = log_.image_stats.rows;
      m["streams"]["images"]["tags_not_in_the_log"] = other_tags_;
    }
    m["streams_without_overlap"] = without_overlap;
  }

  // Estimates the IMU clock offset and adds it to the IMU times.
  void AlignImuClock(const RunContext& ctx) {
    std::vector<kinematics::FrameId> frames;
    for (const estimators::ImuSetup& s : rig_.setup.imus) frames.push_back(s.frame);
    const ClockOffset c =
        EstimateImuClockOffset(log_, rig_.chain->model, index_.column, frames, offset_range_s_);
    for (estimators::ImuReading& z : log_.imu) z.t += c.offset_s;
    Json& m = (*ctx.summary)["metrics"];
    m["imu_clock_offset_s"] = c.offset_s;
    if (std::isfinite(c.std_s)) m["imu_clock_offset_std_s"] = c.std_s;
    m["imu_clock_offset_correlation"] = c.correlation;
    char line[160];
    std::snprintf(line, sizeof(line),
                  "IMU clock offset estimated: %+.4f s +- %.4f s over %d stretches (correlation "
                  "%.3f), added to the IMU times",
                  c.offset_s, c.std_s, c.segments, c.correlation);
    ctx.log(line);
  }

  std::unique_ptr<estimators::Estimator> Make(const EstimatorSpec& e, std::uint64_t seed) const {
    return rig_.MakeEstimator(e, seed);
  }

  sim::RecordedLog log_;
  sim::MjModelPtr model_;
  DeclaredRig rig_;  // the declared model with the log's sensors
  LogIndex index_;
  int other_tags_ = 0;  // detections in the log's images of tags it does not name
  double step_hz_ = 0.0;
  bool estimate_offset_ = false;
  double offset_range_s_ = 0.5;
  std::vector<EstimatorSpec> specs_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeReplayKind() { return std::make_unique<ReplayKind>(); }

}  // namespace flexbench::scenarios
