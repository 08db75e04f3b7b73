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
//   converged_rmse_deg: 0.159   # optional: the N = 65,536 RMSE, a line in the N panel
//
// Metrics (means over seeds; '.' in numbers spelled 'p'): <variant>.particles.<N>.joint_rmse_deg
// / joint_err_max_deg / ess_mean and <variant>.kappa_v.<k>.{...}; every run also under
// estimators.<variant>_n<N>_s<seed> and estimators.<variant>_kv<k>_s<seed>. Files: sweep.csv (one
// row per run) and traces.csv (per step of each run: worst joint error, ESS).
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "estimators/format.h"
#include "render/plot.h"
#include "scenarios/runner/common/log_export.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/kinds/jsk/jsk_kind.h"
#include "scenarios/runner/kinds/jsk/plots.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

// A number as a metric key or label: "%g" with '.' spelled 'p' (metric paths are dotted).
std::string KeyNum(double v) {
  std::string s = ShortNum(v);
  for (char& c : s) {
    if (c == '.') c = 'p';
  }
  return s;
}

struct RunMetrics {
  double rmse_deg = 0.0, err_max_deg = 0.0, ess_mean = 0.0;
};

// A variant's means over the seeds along one swept parameter, for the figure.
struct Curve {
  std::vector<double> x, rmse, max, ess;
};

// One filter setting: a variant with N particles and concentration kappa_v, from one of the two
// sweeps (particles at base_kappa_v, or kappa_v at base_particles).
struct Setting {
  size_t variant = 0;
  bool particles_sweep = true;
  double value = 0.0;  // the swept parameter's value
  double n = 0.0, k = 0.0;
  const char* sweep() const { return particles_sweep ? "particles" : "kappa_v"; }
};

// What the sweep writes, accumulated over its runs.
struct SweepOutput {
  // sweep.csv: one row per run; traces.csv: per step of every run, the worst joint error and
  // the ESS (where a filter degenerates shows up as ESS collapsing before the error grows).
  std::string sweep_csv =
      "variant,sweep,particles,kappa_v,seed,joint_rmse_deg,joint_err_max_deg,ess_mean,rejected\n";
  std::string traces_csv = "label,step,t_s,joint_err_max_deg,ess\n";
  // TUM trajectories, a folder per seed's run: its truth and every setting's estimate.
  std::vector<TrajectoryRecorder> trajectories;
  std::vector<Curve> n_curves, k_curves;
  int done = 0, total = 0;
};

class JskParticleSweepKind : public jsk::SyntheticKind {
 public:
  bool ExportsLog() const final { return true; }

  void Configure(const ConfigNode& root) override {
    ConfigureSynthetic(root);
    base_.name = root.GetString("estimator");
    base_.label = base_.name;
    base_.where = root.Child("estimator").WhereKey();
    ParseVariants(root.Child("variants"));
    particles_ = root.Child("particles").AsDoubleList();
    kappas_ = root.Child("kappa_v").AsDoubleList();
    base_n_ = root.GetDouble("base_particles", 2048);
    base_kappa_ = root.GetDouble("base_kappa_v", 5.0);
    converged_rmse_deg_ = root.GetDouble("converged_rmse_deg", 0.0);
    if (!(converged_rmse_deg_ >= 0.0) || !std::isfinite(converged_rmse_deg_)) {
      root.Child("converged_rmse_deg").Fail("must be a finite number >= 0");
    }
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
    const std::vector<jsk::SyntheticRun> runs = MakeRuns(ctx);
    if (!ctx.export_log.empty()) {  // each synthetic run's readings, DIR/seed_<its seed>
      std::vector<std::pair<std::string, sim::RecordedLog>> logs;
      for (int s = 0; s < seeds_; ++s) {
        logs.emplace_back("seed_" + std::to_string(ctx.seed + 1000 * s),
                          jsk::SyntheticLog(rig_, runs[s], options_));
      }
      WriteLogsWithDeclared(logs, rig_.declared, ctx.export_log);
    }
    SweepOutput out = StartOutput(runs);
    for (const Setting& setting : Settings()) {
      const RunMetrics mean = RunSetting(setting, runs, ctx, &out, &all);
      Json& m = metrics[variants_[setting.variant].first][setting.sweep()][KeyNum(setting.value)];
      m["joint_rmse_deg"] = mean.rmse_deg;
      m["joint_err_max_deg"] = mean.err_max_deg;
      m["ess_mean"] = mean.ess_mean;
      Curve& c =
          setting.particles_sweep ? out.n_curves[setting.variant] : out.k_curves[setting.variant];
      c.x.push_back(setting.particles_sweep ? std::log2(setting.value) : std::log10(setting.value));
      c.rmse.push_back(mean.rmse_deg);
      c.max.push_back(mean.err_max_deg);
      c.ess.push_back(mean.ess_mean);
    }
    WriteFileAtomic(ctx.out->File("sweep.csv"), out.sweep_csv);
    WriteFileAtomic(ctx.out->File("traces.csv"), out.traces_csv);
    for (int s = 0; s < seeds_; ++s)
      out.trajectories[s].Write(*ctx.out, "base", "seed_" + std::to_string(s));
    metrics["seeds"] = seeds_;
    metrics["base_particles"] = base_n_;
    metrics["base_kappa_v"] = base_kappa_;
    PlotSweep(out, ctx);
  }

 private:
  void ParseVariants(const ConfigNode& variants) {
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
  }

  // Collect: one synthetic run per seed, shared by every setting.
  std::vector<jsk::SyntheticRun> MakeRuns(const RunContext& ctx) const {
    std::vector<jsk::SyntheticRun> runs;
    for (int s = 0; s < seeds_; ++s) {
      runs.push_back(jsk::MakeSyntheticRun(rig_, trajectory_, options_, ctx.seed + 1000 * s));
    }
    std::vector<estimators::JointReading> joints;
    for (const jsk::SyntheticRun& r : runs)
      joints.insert(joints.end(), r.joints.begin(), r.joints.end());
    jsk::CheckFittedRange(rig_, joints, ctx);
    return runs;
  }

  SweepOutput StartOutput(const std::vector<jsk::SyntheticRun>& runs) const {
    SweepOutput out;
    out.n_curves.resize(variants_.size());
    out.k_curves.resize(variants_.size());
    out.total = static_cast<int>((particles_.size() + kappas_.size()) * seeds_ * variants_.size());
    out.trajectories.resize(seeds_);
    for (int s = 0; s < seeds_; ++s) {
      for (int step = 0; step < runs[s].steps(); ++step) {
        out.trajectories[s].AddTruth(step, runs[s].T_true[step]);
      }
    }
    return out;
  }

  // Every setting in the sweep's order: per variant the particles, then the kappa_v values.
  std::vector<Setting> Settings() const {
    std::vector<Setting> settings;
    for (size_t var = 0; var < variants_.size(); ++var) {
      for (double v : particles_) settings.push_back({var, true, v, v, base_kappa_});
      for (double v : kappas_) settings.push_back({var, false, v, base_n_, v});
    }
    return settings;
  }

  // Estimate and score one setting on every seed's run; returns the means over the seeds.
  RunMetrics RunSetting(const Setting& setting, const std::vector<jsk::SyntheticRun>& runs,
                        const RunContext& ctx, SweepOutput* out, Json* all) const {
    const std::string& vlabel = variants_[setting.variant].first;
    RunMetrics mean;
    for (int s = 0; s < seeds_; ++s) {
      const std::uint64_t seed = ctx.seed + 1000 * s;
      const std::string label =
          vlabel +
          (setting.particles_sweep ? "_n" + KeyNum(setting.n) : "_kv" + KeyNum(setting.k)) + "_s" +
          std::to_string(s);
      int rejected = 0;
      const jsk::Trace tr = jsk::RunSynthetic(
          rig_, Make(setting.variant, setting.n, setting.k, label), runs[s], seed, &rejected);
      const RunMetrics r = Score(tr, runs[s]);
      Record(setting, s, label, tr, runs[s], r, rejected, out);
      Json& m = (*all)[label]["metrics"];
      m["joint_rmse_deg"] = r.rmse_deg;
      m["joint_err_max_deg"] = r.err_max_deg;
      m["ess_mean"] = r.ess_mean;
      mean.rmse_deg += r.rmse_deg / seeds_;
      mean.err_max_deg += r.err_max_deg / seeds_;
      mean.ess_mean += r.ess_mean / seeds_;
      ctx.progress("sweep", ++out->done, out->total);
    }
    return mean;
  }

  // One run's trajectory, its sweep.csv row and its traces.csv rows.
  void Record(const Setting& setting, int s, const std::string& label, const jsk::Trace& tr,
              const jsk::SyntheticRun& run, const RunMetrics& r, int rejected,
              SweepOutput* out) const {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      out->trajectories[s].Add(label, tr.t[i], tr.T_est[i], tr.cov[i]);
    }
    char line[256];
    std::snprintf(line, sizeof(line), "%s,%s,%d,%.9g,%d,%.9g,%.9g,%.9g,%d\n",
                  variants_[setting.variant].first.c_str(), setting.sweep(),
                  static_cast<int>(setting.n), setting.k, s, r.rmse_deg, r.err_max_deg, r.ess_mean,
                  rejected);
    out->sweep_csv += line;
    for (int step = 0; step < run.steps(); ++step) {
      double worst = 0.0;
      for (int j = 0; j < rig_.nq(); ++j) {
        worst = std::max(worst,
                         std::abs(jsk::Deg(jsk::AngleError(tr.mean[j][step], run.truth[j][step]))));
      }
      std::snprintf(line, sizeof(line), "%s,%d,%.9g,%.9g,%.9g\n", label.c_str(), step, tr.t[step],
                    worst, tr.ess[step]);
      out->traces_csv += line;
    }
  }

  void PlotSweep(const SweepOutput& out, const RunContext& ctx) const {
    render::Figure fig(1500, 900, 2, 2);
    fig.title = "Hyperparameters (sec. V-A): " + base_.name + ", mean over " +
                std::to_string(seeds_) + " seeds (solid: RMSE, dashed: max error)";
    Panel(&fig.axes(0, 0),
          "joint error vs number of particles (kappa_v = " + KeyNum(base_kappa_) + ")", "log2 N",
          "error [deg]", out.n_curves, false);
    Panel(&fig.axes(0, 1), "mean effective sample size vs N", "log2 N", "log10 ESS", out.n_curves,
          true);
    Panel(&fig.axes(1, 0), "joint error vs system noise (N = " + KeyNum(base_n_) + ")",
          "log10 kappa_v", "error [deg]", out.k_curves, false);
    Panel(&fig.axes(1, 1), "mean effective sample size vs kappa_v", "log10 kappa_v", "log10 ESS",
          out.k_curves, true);
    fig.axes(0, 0).AddVLine(8.0, "N = 256");
    if (converged_rmse_deg_ > 0.0) fig.axes(0, 0).AddHLine(converged_rmse_deg_, "converged RMSE");
    fig.SavePng((ctx.out->FramesDir() / "sweep.png").string());
  }

  // Every variant's curve: RMSE and max error, or the ESS (log10) when `ess`.
  void Panel(render::Axes* ax, const std::string& title, const std::string& x_label,
             const std::string& y_label, const std::vector<Curve>& curves, bool ess) const {
    ax->title = title;
    ax->x_label = x_label;
    ax->y_label = y_label;
    ax->legend_position = render::LegendPosition::kTopRight;
    for (size_t v = 0; v < curves.size(); ++v) {
      const render::Rgb color = render::PaletteColor(static_cast<int>(v));
      const std::string& label = variants_[v].first;
      std::vector<double> log_ess;
      for (double e : curves[v].ess) log_ess.push_back(std::log10(std::max(e, 1.0)));
      render::Series& a =
          ax->AddLine(ess ? label : label + " RMSE", curves[v].x, ess ? log_ess : curves[v].rmse);
      a.marker = render::Marker::kCircle;
      a.color = color;
      if (!ess) {
        render::Series& b = ax->AddLine(label + " max", curves[v].x, curves[v].max);
        b.marker = render::Marker::kSquare;
        b.line = render::LineStyle::kDashed;
        b.color = color;
      }
    }
    jsk::FitAxes(ax, 0, 0.45);
    ax->x_min = *ax->x_min - 0.3;
    ax->x_max = *ax->x_max + 0.3;
    if (!ess) {
      // Errors on a log scale: the proposals and the converged line are decades apart. Room
      // above the curves for the legend.
      double lo = converged_rmse_deg_ > 0.0 ? converged_rmse_deg_ : 1e300, hi = 0.0;
      for (const Curve& c : curves) {
        for (double v : c.rmse) lo = v > 0.0 ? std::min(lo, v) : lo;
        for (double v : c.max) hi = std::max(hi, v);
      }
      if (hi > 0.0 && lo < hi) {
        ax->y_log = true;
        ax->y_min = lo / 2.0;
        ax->y_max = hi * 30.0;
      }
    }
  }

  EstimatorSpec Make(size_t variant, double n, double k, const std::string& label) const {
    EstimatorSpec e = base_;
    e.label = label;
    std::map<std::string, std::vector<double>> values = variants_[variant].second;
    values["particles"] = {n};
    values["kappa_v"] = {k};
    e.params = estimators::Params(values, "sweep " + label);
    if (label == "check") rig_.MakeEstimator(e);
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

  EstimatorSpec base_;
  std::vector<std::pair<std::string, std::map<std::string, std::vector<double>>>> variants_;
  std::vector<double> particles_, kappas_;
  double base_n_ = 2048, base_kappa_ = 5.0;
  double converged_rmse_deg_ = 0.0;  // 0: no line
  int seeds_ = 3;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskParticleSweepKind() {
  return std::make_unique<JskParticleSweepKind>();
}

}  // namespace flexbench::scenarios
