// A recorded log (sim/recorded_log.h: joints, IMUs, the truth) replayed through the estimators,
// as a simulated run is: the same estimators, TUM trajectories, metrics and gates.
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
// A step: the IMU readings up to its time (in time order), Predict, the joint reading, the
// estimate. Joint angles are the declared model's joint variables (zero at its zero), matched to
// the declared joints by column name. Metrics per estimator, against truth.tum interpolated at
// the steps inside its span (when the log has one): ErrorStats' position and rotation errors,
// NEES, steps_scored, rejected_readings. Scenario metrics: steps, duration_s, and per stream
// rows, duplicates, gaps, median_dt_s, clock_offset_s; a stream without time overlap with the
// joints is warned about and counted (streams_without_overlap); an estimated IMU clock offset
// (imu_clock_offset_s, its standard error _std_s and the correlation at it), added to the IMU
// times before the estimators see them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <optional>

#include "estimators/error.h"
#include "scenarios/runner/common/clock_offset.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {
namespace {

class ReplayKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    log_ = sim::ReadRecordedLog(root.ResolvePath(root.GetString("log")));
    const std::string log_yaml = log_.dir + "/log.yaml";
    const auto declared = root.Optional("declared");
    declared_ = sim::LoadDeclaredModel(declared ? root.ResolvePath(declared->AsString())
                                                : log_.declared_path);
    model_ = sim::LoadModel(declared_.model_path);
    chain_ = std::make_unique<sim::DeclaredChain>(sim::BuildDeclaredChain(model_.get(), declared_));
    MapJoints();
    setup_.model = &chain_->model;
    setup_.effects = chain_->effects_or_null();
    setup_.end_effector = chain_->end_effector;
    for (const sim::LogImu& imu : log_.imus) {
      estimators::ImuSetup s;
      try {
        s.frame = chain_->ObservedFrame(imu.frame);
      } catch (const InputError& e) {
        throw InputError(log_yaml + ": imu.sensors." + imu.name + ".frame: " + e.what());
      }
      s.filter_beta = imu.filter_beta;
      s.has_initial = imu.has_initial;
      s.q_base_frame_initial = imu.q_base_frame_initial;
      setup_.imus.push_back(s);
    }
    if (!log_.truth_t.empty() && log_.truth_frame != declared_.end_effector) {
      throw InputError(log_yaml + ": truth.frame '" + log_.truth_frame +
                       "': the estimators estimate the declared end effector '" +
                       declared_.end_effector + "'");
    }
    step_hz_ = root.GetDouble("step_hz", 0.0);
    if (!(step_hz_ >= 0.0) || !std::isfinite(step_hz_)) {
      root.Child("step_hz").Fail("must be 0 (a step per joint row) or a rate > 0 in Hz");
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
    const std::vector<Step> steps = Steps();
    const std::vector<size_t> imu_order = ImuTimeOrder();
    TrajectoryRecorder recorder;
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < specs_.size(); ++e) {
      const bool first = e == 0;
      ErrorStats stats;
      int rejected = 0;
      const auto count = [&](estimators::UpdateStatus s) {
        rejected +=
            s != estimators::UpdateStatus::kAccepted && s != estimators::UpdateStatus::kIgnored;
      };
      const std::unique_ptr<estimators::Estimator> est = Make(specs_[e], ctx.seed);
      estimators::JointReading j;
      j.q.resize(chain_->model.nq());
      j.std = estimators::JointVector::Zero(chain_->model.nq());
      size_t next_imu = 0;
      for (size_t s = 0; s < steps.size(); ++s) {
        const Step& step = steps[s];
        for (; next_imu < imu_order.size() && log_.imu[imu_order[next_imu]].t <= step.t;
             ++next_imu) {
          count(est->Update(log_.imu[imu_order[next_imu]]));
        }
        est->Predict(step.t);
        j.t = step.t;
        for (int k = 0; k < j.q.size(); ++k) j.q[k] = log_.q(step.row)[column_[k]];
        count(est->Update(j));
        const estimators::Belief b = est->Estimate();
        lie::SE3 T_true;
        if (sim::TruthAt(log_, step.t, &T_true)) {
          stats.Add(b.T_base_ee, b.cov, T_true);
          if (first) recorder.AddTruth(step.t, T_true);
        }
        recorder.Add(specs_[e].label, step.t, b.T_base_ee, b.cov);
        if (s % 256 == 0 || s + 1 == steps.size()) {
          ctx.progress(specs_[e].label, static_cast<int>(s + 1), static_cast<int>(steps.size()));
        }
      }
      Json& m = all[specs_[e].label]["metrics"];
      if (stats.count() > 0) stats.WriteMetrics(&m);
      m["steps_scored"] = stats.count();
      m["rejected_readings"] = rejected + est->deferred_rejections();
    }
    (*ctx.summary)["metrics"]["steps"] = static_cast<int>(steps.size());
    recorder.Write(*ctx.out, "base");  // the coordinates: the declared base frame
  }

 private:
  struct Step {
    double t;
    size_t row;  // the joint row it reads
  };

  // column_[k]: the joints.csv column of declared joint k; every column a declared joint.
  void MapJoints() {
    const std::string where = log_.joint_stats.file + ":1";
    for (const std::string& j : chain_->q_joints) {
      const auto it = std::find(log_.joints.begin(), log_.joints.end(), j);
      if (it == log_.joints.end()) {
        throw InputError(where + ": no column for declared joint '" + j + "' (" + j +
                         "_rad, or _m for a slide)");
      }
      const int c = static_cast<int>(it - log_.joints.begin());
      const kinematics::PpoeModel& model = chain_->model;
      const int k = static_cast<int>(column_.size());
      const bool slide =
          model.frame(model.joint_frame(k)).joint.type == kinematics::JointType::kPrismatic;
      if (slide != static_cast<bool>(log_.joint_is_slide[c])) {
        throw InputError(where + ": column '" + j + (log_.joint_is_slide[c] ? "_m" : "_rad") +
                         "': " + declared_.file + " declares '" + j + "' " +
                         (slide ? "a slide (" + j + "_m)" : "revolute (" + j + "_rad)"));
      }
      column_.push_back(c);
    }
    for (const std::string& c : log_.joints) {
      if (std::find(chain_->q_joints.begin(), chain_->q_joints.end(), c) ==
          chain_->q_joints.end()) {
        throw InputError(where + ": column '" + c + "': " + declared_.file +
                         " declares no joint of that name");
      }
    }
  }

  std::vector<Step> Steps() const {
    std::vector<Step> steps;
    const std::vector<double>& t = log_.joint_t;
    if (step_hz_ == 0.0) {
      for (size_t r = 0; r < t.size(); ++r) steps.push_back({t[r], r});
      return steps;
    }
    // Each tick k (at t.front() + k / step_hz) takes the latest row at or before it, at that
    // row's time: row r is stepped when a tick falls in [t_r, t_r+1), or at t_r for the last
    // row. In ticks, with a thousandth of a tick of slack for times written in decimals.
    const auto first_tick_at_or_after = [&](double time) {
      return std::ceil((time - t.front()) * step_hz_ - 1e-3);
    };
    for (size_t r = 0; r < t.size(); ++r) {
      const double k = first_tick_at_or_after(t[r]);
      const bool served = r + 1 < t.size() ? k < first_tick_at_or_after(t[r + 1])
                                           : k <= (t[r] - t.front()) * step_hz_ + 1e-3;
      if (served) steps.push_back({t[r], r});
    }
    return steps;
  }

  // The IMU readings in time order (a sensor's own order where times are equal).
  std::vector<size_t> ImuTimeOrder() const {
    std::vector<size_t> order(log_.imu.size());
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(),
                     [&](size_t a, size_t b) { return log_.imu[a].t < log_.imu[b].t; });
    return order;
  }

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
    m["streams_without_overlap"] = without_overlap;
  }

  // Estimates the IMU clock offset and adds it to the IMU times.
  void AlignImuClock(const RunContext& ctx) {
    std::vector<kinematics::FrameId> frames;
    for (const estimators::ImuSetup& s : setup_.imus) frames.push_back(s.frame);
    const ClockOffset c =
        EstimateImuClockOffset(log_, chain_->model, column_, frames, offset_range_s_);
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
    return MakeEstimatorOf(e, setup_, seed);
  }

  sim::RecordedLog log_;
  sim::DeclaredModel declared_;
  sim::MjModelPtr model_;
  std::unique_ptr<sim::DeclaredChain> chain_;
  std::vector<int> column_;
  estimators::EstimatorSetup setup_;
  double step_hz_ = 0.0;
  bool estimate_offset_ = false;
  double offset_range_s_ = 0.5;
  std::vector<EstimatorSpec> specs_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeReplayKind() { return std::make_unique<ReplayKind>(); }

}  // namespace flexbench::scenarios
