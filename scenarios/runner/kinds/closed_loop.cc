// closed_loop: from measured data to the effect the declared model lacks.
// Residual of the declared model on a calibration set -> stepwise selection of candidate
// effects (scenarios/identify) -> fitted, augmented declared model -> error before and after on
// the calibration and on a separate validation set, NEES before and after, PNGs.
//
// Data sources (keys `calibration` and `validation`):
//   mukca: {dir: <recordings of one robot>, placements: [front, ...], socket_distance_m: 0.05}
//   csv: <file> (+ distances: [[group_a, group_b, metres], ...]); format in calibration_data.h
//   simulate: {placements: N, configurations_per_socket: n, seed: k}
//     the truth (`truth.effects`, the sim effect list) puts the end effector into sockets
//     `truth.socket_distance_m` apart at random placements; rows are its encoder readings.
//   simulate: {postures: N, seed: k}   (with `truth.tracker`, runner/common/simulated_tracker.h)
//     a tracker at a pose drawn about its nominal one sees the truth's markers over N random
//     settled postures; rows are the encoder readings and the markers in the tracker's frame.
//   log: {dir: <recorded log folder>, from_s: a, to_s: b, frame: tracker}   (sim/recorded_log.h)
//     a moving arm's log: its truth.tum read as a tracker's points (a measurement) at the joint
//     readings of their times, in the time span [a, b] (either end optional); in the base frame,
//     or in `frame`, one of `frames` (its pose fitted with the effects). Calibration and
//     validation on one log take spans that do not overlap: the validation is a held-out time
//     span, never interleaved rows. The held-out span is then replayed (`replay_estimators`,
//     default fk) under the declared and under the augmented model, each scored against the
//     truth.tum: metrics heldout_replay.<estimator>.before/after, trajectories under
//     trajectories/base/heldout_before and heldout_after.
//     With `streams` (any of truth, tags, imu; default all the log has) only those become rows:
//     truth.tum as points, a fixed camera's tag detections as pixels of the tags' centres, and
//     each IMU's windows at rest (`static: {min_s, gyro_max_rad_s, joint_span_rad}`,
//     identify/log_gravity.h) as gravity rows of its frame (gravity_std_rad: by default what
//     the log shows of a row's error, the windows' standard error and the encoders' rounding).
//   expected_effects: [names]   what a log's truth is known to hold (a demonstration, a test):
//     scored as for simulated truth (effect_found_correct, effects_named_up_to_equivalence).
#include <chrono>
#include <iostream>

#include "scenarios/identify/run.h"
#include "scenarios/runner/common/closed_loop/heldout_replay.h"
#include "scenarios/runner/common/closed_loop/outputs.h"
#include "scenarios/runner/common/closed_loop/setup.h"
#include "scenarios/runner/common/closed_loop/sources.h"
#include "scenarios/runner/common/closed_loop/truth.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

class ClosedLoopKind : public ScenarioKind {
 public:
  explicit ClosedLoopKind(std::unique_ptr<ClosedLoopSetup> ready = nullptr)
      : configured_(ready != nullptr),
        setup_(ready ? std::move(ready) : std::make_unique<ClosedLoopSetup>()),
        cl_(*setup_) {}

  void Configure(const ConfigNode& root) override {
    if (!configured_) ReadClosedLoopSetup(root, &cl_);
  }

  // collect (sources) -> identify::Run (outliers, selection, errors before and after, verdict,
  // NEES) -> score against the truth -> replay a held-out log span -> report.
  void Run(RunContext& ctx) override {
    using Clock = std::chrono::steady_clock;
    const Clock::time_point t0 = Clock::now();
    LogBaseEffects(cl_, ctx);
    for (const std::string& note : cl_.log_notes) ctx.log(note);
    identify::DataSet cal = LoadRows(cl_, cl_.calibration, ctx, "calibration");
    identify::DataSet val = LoadRows(cl_, cl_.validation, ctx, "validation");
    const double load_s = std::chrono::duration<double>(Clock::now() - t0).count();
    identify::Job job = MakeJob(cl_, std::move(cal), std::move(val));
    job.log = ctx.log;
    job.warn = [](const std::string& line) {
      std::cerr << "[flexbench] warning: " << line << "\n";
    };
    // The rows move into the report; the job keeps the declared side the outputs need.
    identify::Report rep = identify::Run(std::move(job));
    (*ctx.timing)["data_s"] = load_s + rep.prepare_s;
    (*ctx.timing)["identify_s"] = rep.identify_s;
    Json& m = (*ctx.summary)["metrics"];
    WriteFitMetrics(cl_, rep, &m);
    if (cl_.truth.tracker) ScoreTrackerPose(cl_, ctx, rep.cal, rep.result);
    ScoreNames(cl_, rep.result, &m);
    WriteMetrics(cl_, rep, &m);
    if (cl_.replay_held_out) {
      const std::string judge = ReplayHeldOut(cl_, ctx, job, rep, &m);
      JudgeHeldOutReplay(ctx, judge, &m, &rep);
    }
    WriteIdentification(cl_, rep, &(*ctx.summary)["identification"]);
    WriteIdentificationFiles(cl_, ctx, job, rep);
  }

 private:
  bool configured_;
  std::unique_ptr<ClosedLoopSetup> setup_;
  ClosedLoopSetup& cl_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeClosedLoopKind() { return std::make_unique<ClosedLoopKind>(); }

std::unique_ptr<ScenarioKind> MakeClosedLoopKind(std::unique_ptr<ClosedLoopSetup> setup) {
  return std::make_unique<ClosedLoopKind>(std::move(setup));
}

}  // namespace flexbench::scenarios
