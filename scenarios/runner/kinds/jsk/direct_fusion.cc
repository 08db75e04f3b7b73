// The particle-filter paper's direct-fusion baseline (sec. IV-D, Fig. 9): joint angles read off
// the Madgwick orientations of the two IMUs by Euler decomposition with the yaw zeroed, in the
// orders 'xyz' and 'yxz', against the particle filter. The flexible jsk_arm first holds link2
// tilted past the horizontal, where 'xyz' is at or beyond its gimbal lock (the paper's T < 0:
// the yaw leaks into the x angle and the fusion collapses), then moves to ordinary postures (the
// paper's T > 0, where both orders and the filter agree).
//
//   locked_waypoints: [0, 1]   # waypoints (held or approached) that form the first phase
//   burn_in_s: 1.0
//
// Metrics per estimator: pos_err_mean_m, pos_err_locked_mean_m, pos_err_free_mean_m (the two
// phases), ee_z_err_locked_mean_m / ee_z_err_free_mean_m (|z error|, the paper's plotted
// component).
#include <algorithm>
#include <cmath>

#include "render/plot.h"
#include "scenarios/runner/kinds/jsk/jsk_kind.h"
#include "scenarios/runner/kinds/jsk/plots.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

class JskDirectFusionKind : public jsk::DynamicKind {
 public:
  void Run(RunContext& ctx) override {
    const std::vector<jsk::Snapshot> snaps = Simulate(ctx);
    const std::vector<std::vector<double>> reference = Reference(snaps);
    std::vector<int> rejected;
    const std::vector<jsk::Trace> traces = Estimate(snaps, ctx, &rejected);
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < traces.size(); ++e) {
      Score(estimators_[e], traces[e], snaps, rejected[e], &all[estimators_[e].label]["metrics"]);
    }
    WriteRunMetrics(snaps, ctx);
    jsk::WriteTraces(rig_, traces, nullptr, reference, ctx.out);
    PlotFusion(snaps, traces, reference, ctx);
    PlotEachTrace("fig9_", "Direct fusion scenario: ", traces, nullptr, reference, ctx);
  }

 private:
  void ConfigureKind(const ConfigNode& root) override {
    const ConfigNode locked = root.Child("locked_waypoints");
    for (const ConfigNode& item : locked.Items()) {
      const int w = item.AsInt();
      if (w < 0 || w >= static_cast<int>(trajectory_.waypoints.size())) {
        item.Fail("no such waypoint");
      }
      locked_.push_back(w);
    }
  }

  bool IsLocked(const jsk::Snapshot& s) const {
    return std::find(locked_.begin(), locked_.end(), s.segment) != locked_.end();
  }

  // The gripper error after the burn-in, over both phases and in each.
  void Score(const EstimatorSpec& spec, const jsk::Trace& tr,
             const std::vector<jsk::Snapshot>& snaps, int rejected, Json* metrics) const {
    double sum = 0.0, sum_l = 0.0, sum_f = 0.0, z_l = 0.0, z_f = 0.0;
    int n = 0, n_l = 0, n_f = 0;
    for (size_t i = 0; i < snaps.size(); ++i) {
      if (snaps[i].t < burn_in_s_) continue;
      sum += tr.ee_err_m[i];
      ++n;
      if (IsLocked(snaps[i])) {
        sum_l += tr.ee_err_m[i];
        z_l += std::abs(tr.ee_err_z_m[i]);
        ++n_l;
      } else {
        sum_f += tr.ee_err_m[i];
        z_f += std::abs(tr.ee_err_z_m[i]);
        ++n_f;
      }
    }
    Json& m = *metrics;
    m["estimator"] = spec.name;
    m["pos_err_mean_m"] = sum / n;
    m["pos_err_locked_mean_m"] = n_l ? Json(sum_l / n_l) : Json();
    m["pos_err_free_mean_m"] = n_f ? Json(sum_f / n_f) : Json();
    m["ee_z_err_locked_mean_m"] = n_l ? Json(z_l / n_l) : Json();
    m["ee_z_err_free_mean_m"] = n_f ? Json(z_f / n_f) : Json();
    m["rejected_readings"] = rejected;
  }

  // Fig. 9: the gripper height estimated by each method, and the reference angles.
  void PlotFusion(const std::vector<jsk::Snapshot>& snaps, const std::vector<jsk::Trace>& traces,
                  const std::vector<std::vector<double>>& reference, const RunContext& ctx) const {
    render::Figure fig(1400, 1200, 3, 1);
    fig.title = "Direct fusion ('xyz', 'yxz', yaw zeroed) vs the particle filter";
    HeightPanel(snaps, traces, &fig.axes(0, 0));
    render::Axes& err = fig.axes(1, 0);
    err.title = "gripper position error (all components)";
    err.x_label = "time [s]";
    err.y_label = "error [cm]";
    for (size_t e = 0; e < traces.size(); ++e) {
      render::Series& s = err.AddLine(traces[e].label, traces[e].t, jsk::ToCm(traces[e].ee_err_m));
      s.color = render::PaletteColor(static_cast<int>(e));
    }
    jsk::FitAxes(&err, 5, 0.5);
    render::Axes& pose = fig.axes(2, 0);
    pose.title = "reference joint angles";
    pose.x_label = "time [s]";
    pose.y_label = "angle [deg]";
    for (int j = 0; j < rig_.nq(); ++j) {
      pose.AddLine(rig_.joint_names()[j], traces.front().t, jsk::ToDeg(reference[j]));
    }
    jsk::FitAxes(&pose, 0, 0.5);
    fig.SavePng((ctx.out->FramesDir() / "fig9_direct_fusion.png").string());
  }

  // The gripper height of the truth and of each estimate.
  static void HeightPanel(const std::vector<jsk::Snapshot>& snaps,
                          const std::vector<jsk::Trace>& traces, render::Axes* ax) {
    ax->title = "gripper height z (first phase: link2 past horizontal, 'xyz' at its gimbal lock)";
    ax->x_label = "time [s]";
    ax->y_label = "z [cm]";
    std::vector<double> z_true_cm;
    for (const jsk::Snapshot& s : snaps) z_true_cm.push_back(100.0 * s.T_true.translation().z());
    render::Series& t =
        ax->AddLine("truth", snaps.empty() ? std::vector<double>{} : traces.front().t, z_true_cm);
    t.color = render::Rgb{0, 0, 0};
    for (size_t e = 0; e < traces.size(); ++e) {
      std::vector<double> z;
      for (size_t i = 0; i < snaps.size(); ++i) {
        z.push_back(100.0 * (snaps[i].T_true.translation().z() + traces[e].ee_err_z_m[i]));
      }
      render::Series& s = ax->AddLine(traces[e].label, traces[e].t, z);
      s.color = render::PaletteColor(static_cast<int>(e));
      if (traces[e].label.find("direct_fusion") != std::string::npos) {
        s.line = render::LineStyle::kDashed;
      }
    }
    jsk::FitAxes(ax, 5, 0.5, /*from_zero=*/false);
  }

  std::vector<int> locked_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskDirectFusionKind() {
  return std::make_unique<JskDirectFusionKind>();
}

}  // namespace flexbench::scenarios
