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
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

class JskDirectFusionKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    rig_ = jsk::LoadRig(root, /*with_effects=*/true);
    trajectory_ = jsk::ParseTrajectory(root.Child("trajectory"), rig_.nq(), /*dynamic=*/true);
    options_ = jsk::ParseDynamicOptions(root);
    burn_in_s_ = root.GetDouble("burn_in_s", 1.0);
    if (!(burn_in_s_ >= 0.0 && burn_in_s_ < trajectory_.Duration())) {
      jsk::FailAt(root, "burn_in_s", "must be in [0, trajectory duration)");
    }
    const ConfigNode locked = root.Child("locked_waypoints");
    for (const ConfigNode& item : locked.Items()) {
      const int w = item.AsInt();
      if (w < 0 || w >= static_cast<int>(trajectory_.waypoints.size())) {
        item.Fail("no such waypoint");
      }
      locked_.push_back(w);
    }
    sensors_node_ = std::make_unique<ConfigNode>(root.Child("sensors"));
    sim::SensorSuite::Parse(*sensors_node_, *rig_.sim, 0);
    estimators_ = jsk::ParseLabelledEstimators(root.Child("estimators"));
    for (const auto& e : estimators_) jsk::MakeLabelled(rig_, e, 0);
  }

  void Run(RunContext& ctx) override {
    sim::SensorSuite sensors = sim::SensorSuite::Parse(*sensors_node_, *rig_.sim, ctx.seed);
    const std::vector<jsk::Snapshot> snaps =
        jsk::SimulateDynamic(rig_, trajectory_, sensors, options_, ctx);
    const int nq = rig_.nq();
    std::vector<std::vector<double>> reference(nq);
    std::vector<double> z_true_cm;
    for (const jsk::Snapshot& s : snaps) {
      for (int j = 0; j < nq; ++j) reference[j].push_back(s.reference[j]);
      z_true_cm.push_back(100.0 * s.T_true.translation().z());
    }
    const auto is_locked = [&](const jsk::Snapshot& s) {
      return std::find(locked_.begin(), locked_.end(), s.segment) != locked_.end();
    };

    std::vector<jsk::Trace> traces;
    Json& all = (*ctx.summary)["estimators"];
    for (const jsk::LabelledEstimator& spec : estimators_) {
      int rejected = 0;
      jsk::Trace tr = jsk::RunOnSnapshots(rig_, spec, snaps, ctx.seed, false, ctx, &rejected);
      double sum = 0.0, sum_l = 0.0, sum_f = 0.0, z_l = 0.0, z_f = 0.0;
      int n = 0, n_l = 0, n_f = 0;
      for (size_t i = 0; i < snaps.size(); ++i) {
        if (snaps[i].t < burn_in_s_) continue;
        sum += tr.ee_err_m[i];
        ++n;
        if (is_locked(snaps[i])) {
          sum_l += tr.ee_err_m[i];
          z_l += std::abs(tr.ee_err_z_m[i]);
          ++n_l;
        } else {
          sum_f += tr.ee_err_m[i];
          z_f += std::abs(tr.ee_err_z_m[i]);
          ++n_f;
        }
      }
      Json& m = all[spec.label]["metrics"];
      m["estimator"] = spec.name;
      m["pos_err_mean_m"] = sum / n;
      m["pos_err_locked_mean_m"] = n_l ? Json(sum_l / n_l) : Json();
      m["pos_err_free_mean_m"] = n_f ? Json(sum_f / n_f) : Json();
      m["ee_z_err_locked_mean_m"] = n_l ? Json(z_l / n_l) : Json();
      m["ee_z_err_free_mean_m"] = n_f ? Json(z_f / n_f) : Json();
      m["rejected_readings"] = rejected;
      traces.push_back(std::move(tr));
    }
    Json& metrics = (*ctx.summary)["metrics"];
    metrics["snapshots"] = static_cast<int>(snaps.size());
    metrics["duration_s"] = trajectory_.Duration();

    jsk::WriteTraces(rig_, traces, nullptr, reference, ctx.out);
    // Fig. 9: the gripper height estimated by each method, and the reference angles.
    render::Figure fig(1400, 1200, 3, 1);
    fig.title = "Direct fusion ('xyz', 'yxz', yaw zeroed) vs the particle filter";
    render::Axes& ax = fig.axes(0, 0);
    ax.title = "gripper height z (first phase: link2 past horizontal, 'xyz' at its gimbal lock)";
    ax.x_label = "time [s]";
    ax.y_label = "z [cm]";
    render::Series& t =
        ax.AddLine("truth", snaps.empty() ? std::vector<double>{} : traces.front().t, z_true_cm);
    t.color = render::Rgb{0, 0, 0};
    for (size_t e = 0; e < traces.size(); ++e) {
      std::vector<double> z;
      for (size_t i = 0; i < snaps.size(); ++i) {
        z.push_back(100.0 * (snaps[i].T_true.translation().z() + traces[e].ee_err_z_m[i]));
      }
      render::Series& s = ax.AddLine(traces[e].label, traces[e].t, z);
      s.color = render::PaletteColor(static_cast<int>(e));
      if (traces[e].label.find("direct_fusion") != std::string::npos) {
        s.line = render::LineStyle::kDashed;
      }
    }
    jsk::FitAxes(&ax, 5, 0.5, /*from_zero=*/false);
    render::Axes& err = fig.axes(1, 0);
    err.title = "gripper position error (all components)";
    err.x_label = "time [s]";
    err.y_label = "error [cm]";
    for (size_t e = 0; e < traces.size(); ++e) {
      std::vector<double> cm;
      for (double v : traces[e].ee_err_m) cm.push_back(100.0 * v);
      render::Series& s = err.AddLine(traces[e].label, traces[e].t, cm);
      s.color = render::PaletteColor(static_cast<int>(e));
    }
    jsk::FitAxes(&err, 5, 0.5);
    render::Axes& pose = fig.axes(2, 0);
    pose.title = "reference joint angles";
    pose.x_label = "time [s]";
    pose.y_label = "angle [deg]";
    for (int j = 0; j < nq; ++j) {
      std::vector<double> deg;
      for (double v : reference[j]) deg.push_back(jsk::Deg(v));
      pose.AddLine(rig_.joint_names()[j], traces.front().t, deg);
    }
    jsk::FitAxes(&pose, 0, 0.5);
    fig.SavePng((ctx.out->FramesDir() / "fig9_direct_fusion.png").string());
    for (const jsk::Trace& tr : traces) {
      jsk::PlotJointBands(rig_, "Direct fusion scenario: " + tr.label, {tr}, nullptr, reference,
                          (ctx.out->FramesDir() / ("fig9_" + tr.label + ".png")).string(),
                          "time [s]");
    }
  }

 private:
  jsk::Rig rig_;
  jsk::Trajectory trajectory_;
  jsk::DynamicOptions options_;
  double burn_in_s_ = 1.0;
  std::vector<int> locked_;
  std::unique_ptr<ConfigNode> sensors_node_;
  std::vector<jsk::LabelledEstimator> estimators_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskDirectFusionKind() {
  return std::make_unique<JskDirectFusionKind>();
}

}  // namespace flexbench::scenarios
