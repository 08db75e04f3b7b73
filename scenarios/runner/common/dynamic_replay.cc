#include "scenarios/runner/common/dynamic_replay.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>

#include "estimators/error.h"
#include "estimators/format.h"
#include "scenarios/runner/common/error_stats.h"
#include "scenarios/runner/common/log_replay.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/output.h"
#include "sim/dynamic_effects.h"
#include "sim/export_model.h"

namespace flexbench::scenarios {
namespace {

namespace dyn = identify::dynamic;
namespace fs = std::filesystem;

std::string Joined(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

// Whether a dynamic effect moves the end effector at given joint readings (its standing part:
// sim/declared_effects.cc); the others change only how the arm moves.
bool MovesStandingArm(const std::string& effect) {
  const sim::DynamicRow* row = sim::FindDynamic(effect.substr(0, effect.find('@')));
  return row &&
         (row->kind == sim::DynamicKind::kLinkMode || row->kind == sim::DynamicKind::kPayloadMass);
}

// `declared` with `fitted` applied on top of it (sim::Combined): one entry that acts as both.
// A scale's std scales with the declared factor, a sum's stds add in quadrature, a delay's is
// the fit's.
void MergeInto(sim::IdentifiedEffect& declared, sim::IdentifiedEffect fitted) {
  const sim::DynamicKind kind =
      sim::FindDynamic(fitted.effect.substr(0, fitted.effect.find('@')))->kind;
  std::array<double, 2> a{}, b{};
  for (size_t k = 0; k < fitted.value.size(); ++k) a[k] = declared.value[k], b[k] = fitted.value[k];
  const std::array<double, 2> v = sim::Combined(kind, a, b);
  const bool scale = kind == sim::DynamicKind::kServoGain || kind == sim::DynamicKind::kLinkMode ||
                     kind == sim::DynamicKind::kBaseMode;
  for (size_t k = 0; k < fitted.value.size(); ++k) {
    const double s0 = declared.std.size() > k ? declared.std[k] : 0.0;
    if (scale) {
      fitted.std[k] *= std::abs(a[k]);
    } else if (kind != sim::DynamicKind::kServoDelay) {
      fitted.std[k] = std::hypot(fitted.std[k], s0);
    }
    fitted.value[k] = v[k];
  }
  declared = std::move(fitted);
}

}  // namespace

sim::DeclaredModel DynamicAugmented(const sim::DeclaredModel& declared,
                                    const dyn::DynamicReport& rep, bool heldout_values) {
  sim::DeclaredModel out = declared;
  // A static effect whose dynamic counterpart was chosen gives its place to it.
  auto& fx = out.identified_effects;
  fx.erase(std::remove_if(fx.begin(), fx.end(),
                          [&](const sim::IdentifiedEffect& e) {
                            return std::find(rep.replaced_static.begin(), rep.replaced_static.end(),
                                             e.effect) != rep.replaced_static.end();
                          }),
           fx.end());
  for (const dyn::ChosenEffect& c : rep.chosen) {
    sim::IdentifiedEffect ie;
    ie.effect = c.name;
    ie.value = heldout_values ? c.heldout_values : c.values;
    for (double s : c.std_errors) ie.std.push_back(std::isfinite(s) ? s : 0.0);
    ie.unit = Joined(c.value_names);
    ie.where = "dynamic identification";
    ie.equivalent = c.equivalent;
    // The declared file's own entry of that effect: the fit acted on top of it.
    const auto same = std::find_if(
        fx.begin(), fx.end(), [&](const sim::IdentifiedEffect& e) { return e.effect == c.name; });
    if (same == fx.end()) {
      fx.push_back(std::move(ie));
    } else {
      MergeInto(*same, std::move(ie));
    }
  }
  return out;
}

void WriteDynamicAugmented(const sim::DeclaredModel& declared, const dyn::DynamicReport& rep,
                           RunContext& ctx) {
  Json& cm = (*ctx.summary)["dynamic_identification"]["calibrated_model"];
  if (rep.chosen.empty() || rep.verdict == "unexplained") {
    cm = {{"not_written",
           rep.chosen.empty() && rep.verdict == "no_effect"
               ? "nothing to add: the declared model holds the log"
               : "no effect explains the held-out segments (verdict " + rep.verdict + ")"}};
    return;
  }
  sim::DeclaredModel out = DynamicAugmented(declared, rep, false);
  sim::ExportedModel mjcf;
  try {
    mjcf = sim::ExportMjcf(out);
  } catch (const InputError& e) {
    cm = {{"not_written", e.what()}};
    ctx.log(std::string("calibrated model not exported: ") + e.what());
    return;
  }
  const std::string header =
      "Declared model augmented by flexbench closed_loop_dynamic: the dynamic effects found in\n"
      "the log, with their fitted values and standard errors. Verdict: " +
      rep.verdict + ".";
  // Relative to the result folder, so the file loads from where it is written.
  out.model_path = fs::absolute(declared.model_path)
                       .lexically_normal()
                       .lexically_relative(fs::absolute(ctx.out->final_dir()).lexically_normal())
                       .generic_string();
  // The MJCF first: a declared file is never there without the model it names.
  WriteFileAtomic(ctx.out->File("calibrated_model.xml"), mjcf.text);
  WriteFileAtomic(ctx.out->File("declared_augmented.yaml"), sim::EmitDeclaredModel(out, header));
  cm = {{"declared", "declared_augmented.yaml"},
        {"mjcf", "calibrated_model.xml"},
        {"not_in_mjcf", mjcf.skipped}};
  ctx.log("wrote declared_augmented.yaml and calibrated_model.xml" +
          (mjcf.skipped.empty() ? std::string()
                                : " (the MJCF cannot hold: " + Joined(mjcf.skipped) + ")"));
}

void ReplayDynamicHeldOut(const sim::RecordedLog& log, const mjModel* nominal,
                          const sim::DeclaredModel& declared, const dyn::DynamicReport& rep,
                          const std::vector<EstimatorSpec>& specs, RunContext& ctx) {
  Json& m = (*ctx.summary)["metrics"];
  if (log.truth_t.empty() || log.truth_frame != declared.end_effector) {
    ctx.log("held-out replay left out: the log has no truth.tum of the end effector '" +
            declared.end_effector + "'");
    return;
  }
  if (rep.chosen.empty()) {
    ctx.log("held-out replay left out: no effect was chosen");
    return;
  }
  if (rep.folds < 2) {
    ctx.log("held-out replay left out: one fold only, nothing is held out");
    return;
  }
  std::vector<std::string> standing, moving;
  for (const dyn::ChosenEffect& c : rep.chosen) {
    (MovesStandingArm(c.name) ? standing : moving).push_back(c.name);
  }
  if (!moving.empty()) {
    ctx.log("held-out replay: " + Joined(moving) +
            " change how the arm moves, not where it stands at given joint readings: the "
            "estimators (kinematic) are as before with them");
  }
  const double from = rep.heldout_from_s, to = rep.heldout_to_s;
  const auto held_out = [&](double t) { return t >= from && t <= to; };
  const std::vector<size_t> imu_order = ImuTimeOrder(log);
  const std::vector<LogStep> steps = LogSteps(log, 0.0);
  std::vector<std::string> errors(specs.size());
  std::vector<double> mean(2, 0.0);
  for (const bool after : {false, true}) {
    LogIndex index;
    const DeclaredRig rig =
        BuildLogRig(log, nominal, after ? DynamicAugmented(declared, rep, true) : declared, &index);
    TrajectoryRecorder recorder;
    for (size_t e = 0; e < specs.size(); ++e) {
      ErrorStats stats;
      const auto est = rig.MakeEstimator(specs[e], ctx.seed);
      const auto on_step = [&](size_t s, const estimators::Belief& b) {
        if (!held_out(steps[s].t)) return;
        lie::SE3 T_true;
        if (!sim::TruthAt(log, steps[s].t, &T_true)) return;
        stats.Add(b.T_base_ee, b.cov, T_true);
        if (e == 0) recorder.AddTruth(steps[s].t, T_true);
        recorder.Add(specs[e].label, steps[s].t, b.T_base_ee, b.cov);
      };
      const int rejected = ReplayLog(log, index, steps, imu_order, *est, on_step);
      Json& j = m["heldout_replay"][specs[e].label][after ? "after" : "before"];
      if (stats.count() > 0) stats.WriteMetrics(&j);
      j["steps_scored"] = stats.count();
      j["rejected_readings"] = rejected;
      const double err = stats.count() > 0 ? j["pos_err_mean_m"].get<double>() : NAN;
      if (e == 0) mean[after] = err;
      errors[e] += (after ? " -> " : "") + ShortNum(1e3 * err);
    }
    recorder.Write(*ctx.out, "base", after ? "heldout_after" : "heldout_before");
  }
  m["heldout_replay_lowered"] = mean[1] < mean[0];
  std::string line = "held-out replay (the last fold, " + ShortNum(from) + "-" + ShortNum(to) +
                     " s; the effects fitted without it), mean position error before -> after "
                     "(mm):";
  for (size_t e = 0; e < specs.size(); ++e) {
    line += (e ? "; " : " ") + specs[e].label + " " + errors[e];
  }
  ctx.log(line);
}

}  // namespace flexbench::scenarios
