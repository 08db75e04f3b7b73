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

#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

using jsk::Deg;

class JskSimDeflectionKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    rig_ = jsk::LoadRig(root, /*with_effects=*/false);
    options_ = jsk::ParseSyntheticOptions(root);
    trajectory_ = jsk::ParseTrajectory(root.Child("trajectory"), rig_.nq(), /*dynamic=*/false);
    burn_in_ = root.GetInt("burn_in_steps", 5);
    if (burn_in_ < 0 || burn_in_ >= trajectory_.Steps()) {
      jsk::FailAt(root, "burn_in_steps", "must be in [0, number of steps)");
    }
    estimators_ = jsk::ParseLabelledEstimators(root.Child("estimators"));
    // Build every estimator once now: bad parameters fail before any work.
    for (const auto& e : estimators_) jsk::MakeLabelled(rig_, e, 0);
  }

  void Run(RunContext& ctx) override {
    const jsk::SyntheticRun run = jsk::MakeSyntheticRun(rig_, trajectory_, options_, ctx.seed);
    const int steps = run.steps();
    const int nq = rig_.nq();
    std::vector<jsk::Trace> traces;
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < estimators_.size(); ++e) {
      const jsk::LabelledEstimator& spec = estimators_[e];
      int rejected = 0;
      const auto t0 = std::chrono::steady_clock::now();
      jsk::Trace tr = jsk::RunSynthetic(rig_, spec, run, ctx.seed, &rejected);
      (*ctx.timing)[spec.label + "_ms_per_step"] =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() /
          steps;
      ctx.progress("estimators", static_cast<int>(e + 1), static_cast<int>(estimators_.size()));
      // Metrics over the steps after the burn-in.
      double sq = 0.0, err_max = 0.0, pos_sum = 0.0, pos_max = 0.0, ess_sum = 0.0;
      std::vector<double> sq_joint(nq, 0.0);
      const int n = steps - burn_in_;
      for (int s = burn_in_; s < steps; ++s) {
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
      Json& m = all[spec.label]["metrics"];
      m["estimator"] = spec.name;
      m["joint_rmse_deg"] = std::sqrt(sq / (n * nq));
      Json per_joint = Json::array();
      for (int j = 0; j < nq; ++j) per_joint.push_back(std::sqrt(sq_joint[j] / n));
      m["joint_rmse_deg_per_joint"] = per_joint;
      m["joint_err_max_deg"] = err_max;
      m["pos_err_mean_m"] = pos_sum / n;
      m["pos_err_max_m"] = pos_max;
      if (jsk::IsParticleFilter(spec)) m["ess_mean"] = ess_sum / n;
      m["rejected_readings"] = rejected;
      traces.push_back(std::move(tr));
    }

    Json& metrics = (*ctx.summary)["metrics"];
    metrics["steps"] = steps;
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
  jsk::Rig rig_;
  jsk::SyntheticOptions options_;
  jsk::Trajectory trajectory_;
  int burn_in_ = 5;
  std::vector<jsk::LabelledEstimator> estimators_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskSimDeflectionKind() {
  return std::make_unique<JskSimDeflectionKind>();
}

}  // namespace flexbench::scenarios
