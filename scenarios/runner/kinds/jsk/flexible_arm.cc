// The particle-filter paper's real-robot experiment (sec. IV-C, Fig. 8) on a flexible MuJoCo
// arm: jsk_arm with its real compliance (elastic servo gears, bending links) moved slowly by its
// servos through postures from vertical to horizontal. The filter's rigid model with effective
// joint angles [PF eq. 22] now holds only approximately: a link that bends at mid-length is not a
// rotated rigid link. The paper scored the gripper position against AR markers; here the truth
// is MuJoCo's grasp point.
//
//   burn_in_s: 1.0        # seconds left out of the metrics (the flat prior of [PF eq. 29])
//
// Metrics per estimator: pos_err_mean_m, pos_err_max_m, pos_err_hold_mean_m (per waypoint, at
// rest), and for particle filters ess_mean. Scenario: gripper_deflection_max_m (truth vs the
// rigid model at the commanded angles).
#include <algorithm>
#include <cmath>

#include "estimators/kinematics/forward_kinematics.h"
#include "render/plot.h"
#include "scenarios/runner/common/stage_timer.h"
#include "scenarios/runner/kinds/jsk/jsk_kind.h"
#include "scenarios/runner/kinds/jsk/plots.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

class JskFlexibleArmKind : public jsk::DynamicKind {
 public:
  void Run(RunContext& ctx) override {
    StageTimer timer;  // the pipeline's throughput: timing.pipeline_steps_per_s
    const std::vector<jsk::Snapshot> snaps = [&] {
      const auto t = timer.Time("simulate");
      return Simulate(ctx);
    }();
    const std::vector<std::vector<double>> reference = Reference(snaps);
    std::vector<int> rejected;
    const std::vector<jsk::Trace> traces = Estimate(snaps, ctx, &rejected, &timer);
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < traces.size(); ++e) {
      Score(estimators_[e], traces[e], snaps, rejected[e], &all[estimators_[e].label]["metrics"]);
    }
    timer.Write(ctx.timing, "step", static_cast<int>(snaps.size()));
    WriteRunMetrics(snaps, ctx);
    (*ctx.summary)["metrics"]["gripper_deflection_max_m"] = GripperDeflectionMax(snaps);
    jsk::WriteTraces(rig_, traces, nullptr, reference, ctx.out);
    PlotEachTrace("fig8_", "Flexible jsk_arm: ", traces, nullptr, reference, ctx);
    PlotGripperError(traces, reference, ctx);
  }

 private:
  // How far the real arm is from its rigid model at the commanded angles.
  double GripperDeflectionMax(const std::vector<jsk::Snapshot>& snaps) const {
    kinematics::PpoeData data(rig_.chain->model);
    double deflection_max = 0.0;
    for (const jsk::Snapshot& s : snaps) {
      kinematics::ForwardKinematics(rig_.chain->model, data, s.reference);
      const double deflection =
          (data.T_base_frame[rig_.chain->end_effector].translation() - s.T_true.translation())
              .norm();
      deflection_max = std::max(deflection_max, deflection);
    }
    return deflection_max;
  }

  // The gripper error after the burn-in: mean, max, mean per waypoint at rest.
  void Score(const EstimatorSpec& spec, const jsk::Trace& tr,
             const std::vector<jsk::Snapshot>& snaps, int rejected, Json* metrics) const {
    const int waypoints = static_cast<int>(trajectory_.waypoints.size());
    double sum = 0.0, max = 0.0, ess = 0.0;
    int n = 0;
    std::vector<double> hold_sum(waypoints, 0.0);
    std::vector<int> hold_n(waypoints, 0);
    for (size_t i = 0; i < snaps.size(); ++i) {
      if (snaps[i].t < burn_in_s_) continue;
      sum += tr.ee_err_m[i];
      max = std::max(max, tr.ee_err_m[i]);
      ess += tr.ess[i];
      ++n;
      if (AtRest(snaps[i].t)) {
        hold_sum[snaps[i].segment] += tr.ee_err_m[i];
        ++hold_n[snaps[i].segment];
      }
    }
    Json& m = *metrics;
    m["estimator"] = spec.name;
    m["pos_err_mean_m"] = sum / n;
    m["pos_err_max_m"] = max;
    Json hold = Json::array();
    for (int w = 0; w < waypoints; ++w) {
      hold.push_back(hold_n[w] ? Json(hold_sum[w] / hold_n[w]) : Json());
    }
    m["pos_err_hold_mean_m"] = hold;
    if (tr.has_particles) m["ess_mean"] = ess / n;
    m["rejected_readings"] = rejected;
  }

  // Fig. 8's middle row: the gripper error of every estimator, with the postures below.
  void PlotGripperError(const std::vector<jsk::Trace>& traces,
                        const std::vector<std::vector<double>>& reference,
                        const RunContext& ctx) const {
    render::Figure fig(1400, 800, 2, 1);
    fig.title = "Gripper position error on the flexible arm (truth: MuJoCo's grasp point)";
    render::Axes& ax = fig.axes(0, 0);
    ax.x_label = "time [s]";
    ax.y_label = "gripper error [cm]";
    ax.legend_position = render::LegendPosition::kTopLeft;
    for (size_t e = 0; e < traces.size(); ++e) {
      render::Series& s = ax.AddLine(traces[e].label, traces[e].t, jsk::ToCm(traces[e].ee_err_m));
      s.color = render::PaletteColor(static_cast<int>(e));
      jsk::StyleComparison(&s);
    }
    jsk::FitAxes(&ax);
    render::Axes& pose = fig.axes(1, 0);
    pose.x_label = "time [s]";
    pose.y_label = "reference angle [deg]";
    pose.title = "postures (vertical at 0 deg, horizontal at 90 deg)";
    for (int j = 0; j < rig_.nq(); ++j) {
      pose.AddLine(rig_.joint_names()[j], traces.front().t, jsk::ToDeg(reference[j]));
    }
    jsk::FitAxes(&pose, 0, 0.5);
    fig.SavePng((ctx.out->FramesDir() / "fig8_gripper_error.png").string());
  }

  // Whether t falls in a hold at a waypoint (at rest), not in a motion.
  bool AtRest(double t) const {
    if (t <= trajectory_.hold_s) return true;
    const double period = trajectory_.segment_s + trajectory_.hold_s;
    const double r = std::fmod(t - trajectory_.hold_s, period);
    return r >= trajectory_.segment_s;
  }
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskFlexibleArmKind() {
  return std::make_unique<JskFlexibleArmKind>();
}

}  // namespace flexbench::scenarios
