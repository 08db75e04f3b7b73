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
#include <cmath>

#include "estimators/kinematics/forward_kinematics.h"
#include "render/plot.h"
#include "scenarios/runner/common/stage_timer.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

class JskFlexibleArmKind : public ScenarioKind {
 public:
  void Configure(const ConfigNode& root) override {
    rig_ = jsk::LoadRig(root, /*with_effects=*/true);
    trajectory_ = jsk::ParseTrajectory(root.Child("trajectory"), rig_.nq(), /*dynamic=*/true);
    options_ = jsk::ParseDynamicOptions(root);
    burn_in_s_ = root.GetDouble("burn_in_s", 1.0);
    if (!(burn_in_s_ >= 0.0 && burn_in_s_ < trajectory_.Duration())) {
      jsk::FailAt(root, "burn_in_s", "must be in [0, trajectory duration)");
    }
    sensors_node_ = std::make_unique<ConfigNode>(root.Child("sensors"));
    sim::SensorSuite::Parse(*sensors_node_, *rig_.sim, 0);
    estimators_ = jsk::ParseLabelledEstimators(root.Child("estimators"));
    for (const auto& e : estimators_) jsk::MakeLabelled(rig_, e, 0);
  }

  void Run(RunContext& ctx) override {
    sim::SensorSuite sensors = sim::SensorSuite::Parse(*sensors_node_, *rig_.sim, ctx.seed);
    StageTimer timer;  // the pipeline's throughput: timing.pipeline_steps_per_s
    const std::vector<jsk::Snapshot> snaps = [&] {
      const auto t = timer.Time("simulate");
      return jsk::SimulateDynamic(rig_, trajectory_, sensors, options_, ctx);
    }();
    const int nq = rig_.nq();
    const int waypoints = static_cast<int>(trajectory_.waypoints.size());

    // How far the real arm is from its rigid model at the commanded angles.
    kinematics::PpoeData data(rig_.chain->model);
    std::vector<double> deflection(snaps.size());
    double deflection_max = 0.0;
    std::vector<std::vector<double>> reference(nq);
    for (size_t i = 0; i < snaps.size(); ++i) {
      kinematics::ForwardKinematics(rig_.chain->model, data, snaps[i].reference);
      deflection[i] = (data.T_base_frame[rig_.chain->end_effector].translation() -
                       snaps[i].T_true.translation())
                          .norm();
      deflection_max = std::max(deflection_max, deflection[i]);
      for (int j = 0; j < nq; ++j) reference[j].push_back(snaps[i].reference[j]);
    }

    std::vector<jsk::Trace> traces;
    Json& all = (*ctx.summary)["estimators"];
    for (const jsk::LabelledEstimator& spec : estimators_) {
      int rejected = 0;
      jsk::Trace tr = [&] {
        const auto t = timer.Time(spec.label);
        return jsk::RunOnSnapshots(rig_, spec, snaps, ctx.seed, false, ctx, &rejected);
      }();
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
      Json& m = all[spec.label]["metrics"];
      m["estimator"] = spec.name;
      m["pos_err_mean_m"] = sum / n;
      m["pos_err_max_m"] = max;
      Json hold = Json::array();
      for (int w = 0; w < waypoints; ++w) {
        hold.push_back(hold_n[w] ? Json(hold_sum[w] / hold_n[w]) : Json());
      }
      m["pos_err_hold_mean_m"] = hold;
      if (jsk::IsParticleFilter(spec)) m["ess_mean"] = ess / n;
      m["rejected_readings"] = rejected;
      traces.push_back(std::move(tr));
    }

    timer.Write(ctx.timing, "step", static_cast<int>(snaps.size()));
    Json& metrics = (*ctx.summary)["metrics"];
    metrics["snapshots"] = static_cast<int>(snaps.size());
    metrics["duration_s"] = trajectory_.Duration();
    metrics["gripper_deflection_max_m"] = deflection_max;
    jsk::WriteTraces(rig_, traces, nullptr, reference, ctx.out);
    for (const jsk::Trace& tr : traces) {
      jsk::PlotJointBands(rig_, "Flexible jsk_arm: " + tr.label, {tr}, nullptr, reference,
                          (ctx.out->FramesDir() / ("fig8_" + tr.label + ".png")).string(),
                          "time [s]");
    }
    // Fig. 8's middle row: the gripper error of every estimator, with the postures below.
    render::Figure fig(1400, 800, 2, 1);
    fig.title = "Gripper position error on the flexible arm (truth: MuJoCo's grasp point)";
    render::Axes& ax = fig.axes(0, 0);
    ax.x_label = "time [s]";
    ax.y_label = "gripper error [cm]";
    ax.legend_position = render::LegendPosition::kTopLeft;
    for (size_t e = 0; e < traces.size(); ++e) {
      std::vector<double> cm;
      for (double v : traces[e].ee_err_m) cm.push_back(100.0 * v);
      render::Series& s = ax.AddLine(traces[e].label, traces[e].t, cm);
      s.color = render::PaletteColor(static_cast<int>(e));
      jsk::StyleComparison(&s);
    }
    jsk::FitAxes(&ax);
    render::Axes& pose = fig.axes(1, 0);
    pose.x_label = "time [s]";
    pose.y_label = "reference angle [deg]";
    pose.title = "postures (vertical at 0 deg, horizontal at 90 deg)";
    for (int j = 0; j < nq; ++j) {
      std::vector<double> deg;
      for (double v : reference[j]) deg.push_back(jsk::Deg(v));
      pose.AddLine(rig_.joint_names()[j], traces.front().t, deg);
    }
    jsk::FitAxes(&pose, 0, 0.5);
    fig.SavePng((ctx.out->FramesDir() / "fig8_gripper_error.png").string());
  }

 private:
  // Whether t falls in a hold at a waypoint (at rest), not in a motion.
  bool AtRest(double t) const {
    if (t <= trajectory_.hold_s) return true;
    const double period = trajectory_.segment_s + trajectory_.hold_s;
    const double r = std::fmod(t - trajectory_.hold_s, period);
    return r >= trajectory_.segment_s;
  }

  jsk::Rig rig_;
  jsk::Trajectory trajectory_;
  jsk::DynamicOptions options_;
  double burn_in_s_ = 1.0;
  std::unique_ptr<ConfigNode> sensors_node_;
  std::vector<jsk::LabelledEstimator> estimators_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskFlexibleArmKind() {
  return std::make_unique<JskFlexibleArmKind>();
}

}  // namespace flexbench::scenarios
