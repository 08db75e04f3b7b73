// The particle-filter paper's simulation study (sec. IV-B, Fig. 6): the body deflection is
// simulated by offsetting the reference angles, theta_eff = theta_ref + k g(theta_ref) [PF eq. 31],
// with g the generalised gravity torque of the rigid nominal jsk_arm (MuJoCo's qfrc_bias at zero
// velocity, sim::Simulation::GravityTorque), so the paper's assumption [PF eq. 22] holds exactly.
// The virtual sensors read the rigid model at theta_eff: IMU orientations of the IMU frames, the
// grasp point's position, and the encoders give theta_ref. Every estimator sees the same
// readings; the truth is theta_eff.
//
//   deflection_k: 0.033          # rad per Nm [PF eq. 31]
//   noise: {reference_deg: 0, orientation_deg: 0, position_m: 0}   # optional sensor noise
//   burn_in_steps: 5             # steps left out of the metrics (the prior of [PF eq. 29] is flat)
//
// Metrics per estimator: joint_rmse_deg (effective angles), joint_rmse_deg_per_joint,
// joint_err_max_deg, pos_err_mean_m / pos_err_max_m of the grasp point, ess_mean; scenario:
// deflection_max_deg.
#include <chrono>
#include <cmath>
#include <cstdio>

#include "scenarios/runner/common/log_export.h"
#include "scenarios/runner/kinds/jsk/jsk_kind.h"
#include "scenarios/runner/kinds/jsk/plots.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

using jsk::Deg;

class JskSimDeflectionKind : public jsk::SyntheticKind {
 public:
  bool ExportsLog() const final { return true; }

  void Configure(const ConfigNode& root) override {
    ConfigureSynthetic(root);
    estimators_ = jsk::ParseAndCheckEstimators(root, rig_);
  }

  void Run(RunContext& ctx) override {
    const jsk::SyntheticRun run = jsk::MakeSyntheticRun(rig_, trajectory_, options_, ctx.seed);
    jsk::CheckFittedRange(rig_, run.joints, ctx);
    if (!ctx.export_log.empty()) {
      WriteLogWithDeclared(jsk::SyntheticLog(rig_, run, options_), rig_.declared, ctx.export_log);
    }
    std::vector<int> rejected;
    const std::vector<jsk::Trace> traces = Estimate(run, ctx, &rejected);
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < traces.size(); ++e) {
      Score(estimators_[e], traces[e], run, rejected[e], &all[estimators_[e].label]["metrics"]);
    }
    Json& metrics = (*ctx.summary)["metrics"];
    metrics["steps"] = run.steps();
    metrics["burn_in_steps"] = burn_in_;
    metrics["deflection_k"] = options_.k;
    metrics["deflection_max_deg"] = Deg(run.deflection_max);
    jsk::WriteTraces(rig_, traces, &run.truth, run.reference, ctx.out);
    char k_text[32];
    std::snprintf(k_text, sizeof(k_text), "%g", options_.k);
    for (const jsk::Trace& tr : traces) {
      jsk::PlotJointBands(
          rig_, std::string("Simulated deflection ([PF eq. 31], k = ") + k_text + "): " + tr.label,
          {tr}, &run.truth, run.reference,
          (ctx.out->FramesDir() / ("fig6_" + tr.label + ".png")).string(), "filter step");
    }
  }

 private:
  // Every estimator over the same run, timed per step.
  std::vector<jsk::Trace> Estimate(const jsk::SyntheticRun& run, const RunContext& ctx,
                                   std::vector<int>* rejected) const {
    std::vector<jsk::Trace> traces;
    rejected->assign(estimators_.size(), 0);
    for (size_t e = 0; e < estimators_.size(); ++e) {
      const EstimatorSpec& spec = estimators_[e];
      const auto t0 = std::chrono::steady_clock::now();
      traces.push_back(jsk::RunSynthetic(rig_, spec, run, ctx.seed, &(*rejected)[e]));
      (*ctx.timing)[spec.label + "_ms_per_step"] =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() /
          run.steps();
      ctx.progress("estimators", static_cast<int>(e + 1), static_cast<int>(estimators_.size()));
    }
    return traces;
  }

  // Metrics over the steps after the burn-in.
  void Score(const EstimatorSpec& spec, const jsk::Trace& tr, const jsk::SyntheticRun& run,
             int rejected, Json* metrics) const {
    const int nq = rig_.nq();
    double sq = 0.0, err_max = 0.0, pos_sum = 0.0, pos_max = 0.0, ess_sum = 0.0;
    std::vector<double> sq_joint(nq, 0.0);
    const int n = run.steps() - burn_in_;
    for (int s = burn_in_; s < run.steps(); ++s) {
      for (int j = 0; j < nq; ++j) {
        const double err = Deg(jsk::AngleError(tr.mean[j][s], run.truth[j][s]));
        sq += err * err;
        sq_joint[j] += err * err;
        err_max = std::max(err_max, std::abs(err));
      }
      pos_sum += tr.ee_err_m[s];
      pos_max = std::max(pos_max, tr.ee_err_m[s]);
      ess_sum += tr.ess[s];
    }
    Json& m = *metrics;
    m["estimator"] = spec.name;
    m["joint_rmse_deg"] = std::sqrt(sq / (n * nq));
    Json per_joint = Json::array();
    for (int j = 0; j < nq; ++j) per_joint.push_back(std::sqrt(sq_joint[j] / n));
    m["joint_rmse_deg_per_joint"] = per_joint;
    m["joint_err_max_deg"] = err_max;
    m["pos_err_mean_m"] = pos_sum / n;
    m["pos_err_max_m"] = pos_max;
    if (tr.has_particles) m["ess_mean"] = ess_sum / n;
    m["rejected_readings"] = rejected;
  }

  std::vector<EstimatorSpec> estimators_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskSimDeflectionKind() {
  return std::make_unique<JskSimDeflectionKind>();
}

}  // namespace flexbench::scenarios
