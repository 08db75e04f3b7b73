// The particle-filter paper's hyperparameter study (sec. V-A): the synthetic deflection run of
// sec. IV-B (jsk_sim_deflection) repeated for several numbers of particles N and system-noise
// concentrations kappa_v, each over a few seeds, to show where the filter degenerates (the paper:
// N >= 256 is needed; small kappa_v is noisy, large kappa_v lets the particles degenerate).
//
//   estimator: pf_all                   # the filter under study
//   variants:                           # label: fixed parameters (Table I otherwise)
//     bootstrap: {}
//     conjugate: {conjugate_proposal: 1}
//   particles: [64, 128, 256, 512, 1024, 2048]   # at base_kappa_v
//   kappa_v: [0.5, 1, 2, 5, 20, 100, 1000]       # at base_particles
//   base_particles: 2048
//   base_kappa_v: 5
//   seeds: 3
//   burn_in_steps: 5
//
// Metrics (means over seeds; '.' in numbers spelled 'p'): <variant>.particles.<N>.joint_rmse_deg
// / joint_err_max_deg / ess_mean and <variant>.kappa_v.<k>.{...}; every run also under
// estimators.<variant>_n<N>_s<seed> and estimators.<variant>_kv<k>_s<seed>. Files: sweep.csv (one
// row per run) and traces.csv (per step of each run: worst joint error, ESS).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "render/plot.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

// A number as a metric key or label: "%g" with '.' spelled 'p' (metric paths are dotted).
std::string Num(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%g", v);
  std::string s = b;
  for (char& c : s) {
    if (c == '.') c = 'p';
  }
  return s;
}

struct RunMetrics {
  double rmse_deg = 0.0, err_max_deg = 0.0, ess_mean = 0.0;
};

class JskParticleSweepKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    rig_ = jsk::LoadRig(root, /*with_effects=*/false);
    options_ = jsk::ParseSyntheticOptions(root);
    trajectory_ = jsk::ParseTrajectory(root.Child("trajectory"), rig_.nq(), /*dynamic=*/false);
    burn_in_ = root.GetInt("burn_in_steps", 5);
    if (burn_in_ < 0 || burn_in_ >= trajectory_.Steps()) {
      jsk::FailAt(root, "burn_in_steps", "must be in [0, number of steps)");
    }
    base_.name = root.GetString("estimator");
    base_.label = base_.name;
    base_.where = root.Child("estimator").WhereKey();
    const ConfigNode variants = root.Child("variants");
    for (const std::string& label : variants.Keys()) {
      const ConfigNode v = variants.Child(label);
      std::map<std::string, std::vector<double>> values;
      if (v.IsMap()) {
        for (const std::string& key : v.Keys()) {
          const ConfigNode x = v.Child(key);
          if (key == "particles" || key == "kappa_v") x.Fail("swept here; not a variant parameter");
          values[key] = x.IsSequence() ? x.AsDoubleList() : std::vector<double>{x.AsDouble()};
        }
      } else if (!(v.IsScalar() && v.AsString().empty())) {
        v.Fail("expected a mapping of parameters ({} for none)");
      }
      variants_.emplace_back(label, values);
    }
    if (variants_.empty()) variants.Fail("need at least one variant");
    particles_ = root.Child("particles").AsDoubleList();
    kappas_ = root.Child("kappa_v").AsDoubleList();
    base_n_ = root.GetDouble("base_particles", 2048);
    base_kappa_ = root.GetDouble("base_kappa_v", 5.0);
    seeds_ = root.GetInt("seeds", 3);
    if (seeds_ < 1) root.Child("seeds").Fail("must be >= 1");
    // Validate every configuration before any work.
    for (size_t v = 0; v < variants_.size(); ++v) {
      for (double n : particles_) Make(v, n, base_kappa_, "check");
      for (double k : kappas_) Make(v, base_n_, k, "check");
    }
  }

  void Run(RunContext& ctx) override {
    Json& metrics = (*ctx.summary)["metrics"];
    Json& all = (*ctx.summary)["estimators"];
    const int total =
        static_cast<int>((particles_.size() + kappas_.size()) * seeds_ * variants_.size());
    int done = 0;
    // One synthetic run per seed, shared by every configuration.
    std::vector<jsk::SyntheticRun> runs;
    for (int s = 0; s < seeds_; ++s) {
      runs.push_back(jsk::MakeSyntheticRun(rig_, trajectory_, options_, ctx.seed + 1000 * s));
    }
    struct Curve {
      std::vector<double> x, rmse, max, ess;
    };
    std::vector<Curve> n_curves(variants_.size()), k_curves(variants_.size());
    // TUM trajectories, a folder per seed's run: its truth and every setting's estimate.
    std::vector<TrajectoryRecorder> trajectories(seeds_);
    for (int s = 0; s < seeds_; ++s) {
      for (int step = 0; step < runs[s].steps(); ++step) {
        trajectories[s].AddTruth(step, runs[s].T_true[step]);
      }
    }
    // sweep.csv: one row per run; traces.csv: per step of every run, the worst joint error and
    // the ESS (where a filter degenerates shows up as ESS collapsing before the error grows).
    std::string sweep_csv =
        "variant,sweep,particles,kappa_v,seed,joint_rmse_deg,joint_err_max_deg,ess_mean,rejected\n";
    std::string traces_csv = "label,step,t_s,joint_err_max_deg,ess\n";
    char line[256];
    for (size_t var = 0; var < variants_.size(); ++var) {
      const std::string& vlabel = variants_[var].first;
      for (int pass = 0; pass < 2; ++pass) {
        const std::vector<double>& values = pass == 0 ? particles_ : kappas_;
        for (double v : values) {
          const double n = pass == 0 ? v : base_n_;
          const double k = pass == 0 ? base_kappa_ : v;
          RunMetrics mean;
          for (int s = 0; s < seeds_; ++s) {
            const std::uint64_t seed = ctx.seed + 1000 * s;
            const std::string label =
                vlabel + (pass == 0 ? "_n" + Num(n) : "_kv" + Num(k)) + "_s" + std::to_string(s);
            int rejected = 0;
            const jsk::Trace tr =
                jsk::RunSynthetic(rig_, Make(var, n, k, label), runs[s], seed, &rejected);
            const RunMetrics r = Score(tr, runs[s]);
            for (size_t i = 0; i < tr.t.size(); ++i) {
              trajectories[s].Add(label, tr.t[i], tr.T_est[i], tr.cov[i]);
            }
            std::snprintf(line, sizeof(line), "%s,%s,%d,%.9g,%d,%.9g,%.9g,%.9g,%d\n",
                          vlabel.c_str(), pass == 0 ? "particles" : "kappa_v", static_cast<int>(n),
                          k, s, r.rmse_deg, r.err_max_deg, r.ess_mean, rejected);
            sweep_csv += line;
            for (int step = 0; step < runs[s].steps(); ++step) {
              double worst = 0.0;
              for (int j = 0; j < rig_.nq(); ++j) {
                worst = std::max(
                    worst,
                    std::abs(jsk::Deg(jsk::AngleError(tr.mean[j][step], runs[s].truth[j][step]))));
              }
              std::snprintf(line, sizeof(line), "%s,%d,%.9g,%.9g,%.9g\n", label.c_str(), step,
                            tr.t[step], worst, tr.ess[step]);
              traces_csv += line;
            }
            Json& m = all[label]["metrics"];
            m["joint_rmse_deg"] = r.rmse_deg;
            m["joint_err_max_deg"] = r.err_max_deg;
            m["ess_mean"] = r.ess_mean;
            mean.rmse_deg += r.rmse_deg / seeds_;
            mean.err_max_deg += r.err_max_deg / seeds_;
            mean.ess_mean += r.ess_mean / seeds_;
            ctx.progress("sweep", ++done, total);
          }
          Json& out = metrics[vlabel][pass == 0 ? "particles" : "kappa_v"][Num(v)];
          out["joint_rmse_deg"] = mean.rmse_deg;
          out["joint_err_max_deg"] = mean.err_max_deg;
          out["ess_mean"] = mean.ess_mean;
          Curve& c = pass == 0 ? n_curves[var] : k_curves[var];
          c.x.push_back(pass == 0 ? std::log2(v) : std::log10(v));
          c.rmse.push_back(mean.rmse_deg);
          c.max.push_back(mean.err_max_deg);
          c.ess.push_back(mean.ess_mean);
        }
      }
    }
    WriteFileAtomic(ctx.out->File("sweep.csv"), sweep_csv);
    WriteFileAtomic(ctx.out->File("traces.csv"), traces_csv);
    for (int s = 0; s < seeds_; ++s)
      trajectories[s].Write(*ctx.out, "base", "seed_" + std::to_string(s));
    metrics["seeds"] = seeds_;
    metrics["base_particles"] = base_n_;
    metrics["base_kappa_v"] = base_kappa_;

    render::Figure fig(1500, 900, 2, 2);
    fig.title = "Hyperparameters (sec. V-A): " + base_.name + ", mean over " +
                std::to_string(seeds_) + " seeds (solid: RMSE, dashed: max error)";
    const auto panel = [&](int r, int c, const std::string& title, const std::string& x_label,
                           const std::string& y_label, const std::vector<Curve>& curves, bool ess) {
      render::Axes& ax = fig.axes(r, c);
      ax.title = title;
      ax.x_label = x_label;
      ax.y_label = y_label;
      ax.legend_position = render::LegendPosition::kTopRight;
      for (size_t v = 0; v < curves.size(); ++v) {
        const render::Rgb color = render::PaletteColor(static_cast<int>(v));
        const std::string& label = variants_[v].first;
        std::vector<double> log_ess;
        for (double e : curves[v].ess) log_ess.push_back(std::log10(std::max(e, 1.0)));
        render::Series& a =
            ax.AddLine(ess ? label : label + " RMSE", curves[v].x, ess ? log_ess : curves[v].rmse);
        a.marker = render::Marker::kCircle;
        a.color = color;
        if (!ess) {
          render::Series& b = ax.AddLine(label + " max", curves[v].x, curves[v].max);
          b.marker = render::Marker::kSquare;
          b.line = render::LineStyle::kDashed;
          b.color = color;
        }
      }
      jsk::FitAxes(&ax, 0, 0.45);
      ax.x_min = *ax.x_min - 0.3;
      ax.x_max = *ax.x_max + 0.3;
    };
    panel(0, 0, "joint error vs number of particles (kappa_v = " + Num(base_kappa_) + ")", "log2 N",
          "error [deg]", n_curves, false);
    panel(0, 1, "mean effective sample size vs N", "log2 N", "log10 ESS", n_curves, true);
    panel(1, 0, "joint error vs system noise (N = " + Num(base_n_) + ")", "log10 kappa_v",
          "error [deg]", k_curves, false);
    panel(1, 1, "mean effective sample size vs kappa_v", "log10 kappa_v", "log10 ESS", k_curves,
          true);
    fig.axes(0, 0).AddVLine(8.0, "N = 256");
    fig.SavePng((ctx.out->FramesDir() / "sweep.png").string());
  }

 private:
  jsk::LabelledEstimator Make(size_t variant, double n, double k, const std::string& label) const {
    jsk::LabelledEstimator e = base_;
    e.label = label;
    std::map<std::string, std::vector<double>> values = variants_[variant].second;
    values["particles"] = {n};
    values["kappa_v"] = {k};
    e.params = estimators::Params(values, "sweep " + label);
    if (label == "check") jsk::MakeLabelled(rig_, e, 0);
    return e;
  }

  RunMetrics Score(const jsk::Trace& tr, const jsk::SyntheticRun& run) const {
    RunMetrics r;
    double sq = 0.0;
    const int nq = rig_.nq();
    const int n = run.steps() - burn_in_;
    for (int s = burn_in_; s < run.steps(); ++s) {
      for (int j = 0; j < nq; ++j) {
        const double e = jsk::Deg(jsk::AngleError(tr.mean[j][s], run.truth[j][s]));
        sq += e * e;
        r.err_max_deg = std::max(r.err_max_deg, std::abs(e));
      }
      r.ess_mean += tr.ess[s] / n;
    }
    r.rmse_deg = std::sqrt(sq / (n * nq));
    return r;
  }

  jsk::Rig rig_;
  jsk::SyntheticOptions options_;
  jsk::Trajectory trajectory_;
  int burn_in_ = 5;
  jsk::LabelledEstimator base_;
  std::vector<std::pair<std::string, std::map<std::string, std::vector<double>>>> variants_;
  std::vector<double> particles_, kappas_;
  double base_n_ = 2048, base_kappa_ = 5.0;
  int seeds_ = 3;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskParticleSweepKind() {
  return std::make_unique<JskParticleSweepKind>();
}

}  // namespace flexbench::scenarios
