#include "scenarios/runner/common/closed_loop/heldout_replay.h"

#include <algorithm>

#include "estimators/error.h"
#include "estimators/format.h"
#include "scenarios/runner/common/closed_loop/sources.h"
#include "scenarios/runner/common/error_stats.h"
#include "scenarios/runner/common/log_replay.h"
#include "scenarios/runner/common/trajectories.h"
#include "sim/declared_chain.h"

namespace flexbench::scenarios {

// Whether the validation log's held-out span can be replayed and scored (its truth is the end
// effector's, it has joint rows there), checked before any work: its frames must be on the
// chain, the span must hold joint rows; without truth of the end effector it is said and left.
void CheckHeldOutReplay(ClosedLoopSetup& cl) {
  const sim::RecordedLog& log = Log(cl, cl.validation);
  if (log.truth_t.empty() || log.truth_frame != cl.declared.end_effector) {
    cl.log_notes.push_back("held-out replay left out: " + log.dir + " has no truth.tum of the " +
                           "end effector '" + cl.declared.end_effector + "' to score it against");
    return;
  }
  LogEstimatorSetup(log, *cl.chain, cl.declared.end_effector);
  if (LogSteps(log, 0.0, cl.validation.from_s, cl.validation.to_s).empty()) {
    throw InputError(cl.validation.where + ": " + log.dir + " has no joint row in " +
                     Span(cl.validation) + ": no held-out span to replay");
  }
  cl.replay_held_out = true;
}

// The validation log through the replay estimators under the declared model and under the
// augmented one (shipped or not: the figures show why), from its start so that filters are
// warm, scored on the held-out span alone.
std::string ReplayHeldOut(const ClosedLoopSetup& cl, RunContext& ctx, const identify::Job& job,
                          const identify::Report& rep, Json* m) {
  const identify::IdentifyResult& res = rep.result;
  const sim::RecordedLog& log = cl.logs.at(cl.validation.path);
  const std::vector<size_t> imu_order = ImuTimeOrder(log);
  const std::vector<LogStep> steps = LogSteps(log, 0.0);
  const auto held_out = [&](double t) {
    return t >= cl.validation.from_s && t <= cl.validation.to_s;
  };
  int held_out_steps = 0;
  for (const LogStep& step : steps) held_out_steps += held_out(step.t);
  std::vector<std::string> errors(cl.replay_specs.size());
  int judge = -1;  // the first estimator that is the model alone at the readings
  const int frame = LogFrame(cl, cl.validation);
  for (const bool after : {false, true}) {
    LogIndex index;
    const DeclaredRig rig = BuildLogRig(
        log, cl.mj.get(), after ? identify::AugmentedModel(job, rep) : cl.declared, &index);
    // The tracker's points in the base frame at the frame's pose fitted with the model.
    const lie::SE3 T_base_frame =
        frame < 0 ? lie::SE3() : (after ? res.after : res.before).T_base_frames[frame];
    TrajectoryRecorder recorder;
    for (size_t e = 0; e < cl.replay_specs.size(); ++e) {
      const std::string& label = cl.replay_specs[e].label;
      ErrorStats stats;
      const auto est = rig.MakeEstimator(cl.replay_specs[e], ctx.seed);
      if (judge < 0 && !est->FusesExternalMeasurements()) judge = static_cast<int>(e);
      const auto on_step = [&](size_t s, const estimators::Belief& b) {
        if (!held_out(steps[s].t)) return;
        lie::SE3 T_true;
        if (sim::TruthAt(log, steps[s].t, &T_true)) {
          T_true = T_base_frame * T_true;
          stats.Add(b.T_base_ee, b.cov, T_true);
          if (e == 0) recorder.AddTruth(steps[s].t, T_true);
        }
        recorder.Add(label, steps[s].t, b.T_base_ee, b.cov);
      };
      const int rejected = ReplayLog(log, index, steps, imu_order, *est, on_step);
      Json& j = (*m)["heldout_replay"][label][after ? "after" : "before"];
      if (stats.count() > 0) stats.WriteMetrics(&j);
      j["steps_scored"] = stats.count();
      j["rejected_readings"] = rejected;
      errors[e] += (after ? " -> " : "") +
                   (stats.count() > 0 ? ShortNum(j["pos_err_mean_m"].get<double>()) : "-");
    }
    recorder.Write(*ctx.out, "base", after ? "heldout_after" : "heldout_before");
  }
  std::string line = "held-out replay (" + std::to_string(held_out_steps) + " steps in " +
                     Span(cl.validation) + "), mean position error before -> after (m):";
  for (size_t e = 0; e < errors.size(); ++e) {
    line += (e ? "; " : " ") + cl.replay_specs[e].label + " " + errors[e];
  }
  ctx.log(line);
  return cl.replay_specs[judge < 0 ? 0 : judge].label;
}

// The held-out truth has the last word: when the augmented model replays it worse than the
// declared one (the mean position error of `judge`, the first replay estimator that is the
// model alone at the readings (fk), else of the first, more than 10%
// above), the effects fit the rows, not the arm (a sensor's bias read as kinematics): the
// verdict is unexplained, and the augmented model is not written.
void JudgeHeldOutReplay(RunContext& ctx, const std::string& judge, Json* m, identify::Report* rep) {
  const Json& j = (*m)["heldout_replay"][judge];
  if (!j["before"].contains("pos_err_mean_m") || !j["after"].contains("pos_err_mean_m")) return;
  const double before = j["before"]["pos_err_mean_m"].get<double>();
  const double after = j["after"]["pos_err_mean_m"].get<double>();
  const bool worse = after > 1.1 * before;
  (*m)["heldout_replay_worse"] = worse;
  if (!worse || rep->verdict == "unexplained" || rep->verdict == "no_effect") return;
  rep->verdict = "unexplained";
  (*m)["verdict"] = rep->verdict;
  ctx.log(
      "verdict: unexplained; the augmented model replays the held-out truth worse than the "
      "declared one (" +
      judge + " " + ShortNum(1e3 * before) + " -> " + ShortNum(1e3 * after) +
      " mm): the effects named fit the rows, not the arm");
}

}  // namespace flexbench::scenarios
