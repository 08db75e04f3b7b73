// The particle-filter paper's yaw-drift result (sec. IV-E, Fig. 10): 6-axis IMUs whose yaw
// drifts (a gyro bias about the vertical that Madgwick's filter cannot correct without a
// magnetometer), fused with a unimodal Bingham observation noise, which reads the drift as a yaw
// of the arm, and with the axis-symmetric one, whose likelihood is the same for every rotation
// about the vertical ([PF eq. 27] with lambda = (l, l, 0, 0)).
//
// The truth is jsk_arm without compliance (its effective angles are its joint angles, so the
// error is the estimator's alone), moved by its servos; the IMUs start with their true
// orientation (a calibrated yaw, madgwick.init: truth) and then drift.
//
//   burn_in_s: 1.0
//
// Metrics per estimator: joint_err_max_deg (largest error of any joint after the burn-in),
// joint_err_max_deg_per_joint, joint_rmse_deg; scenario: imu_yaw_drift_final_deg (largest IMU
// yaw error at the end).
#include <cmath>

#include "render/plot.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/kinds.h"

namespace flexbench::scenarios {
namespace {

double Yaw(const Quat& q) {
  const Mat3 R = q.toRotationMatrix();
  return std::atan2(R(1, 0), R(0, 0));
}

// Yaw of the IMU's estimate relative to the truth: the rotation about the world vertical that
// the estimate carries (q_est q_true^-1 is a pure yaw when roll and pitch are right).
double YawError(const Quat& est, const Quat& truth) { return Yaw(est * truth.inverse()); }

class JskImuYawDriftKind : public ScenarioKind {
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
    const std::vector<jsk::Snapshot> snaps =
        jsk::SimulateDynamic(rig_, trajectory_, sensors, options_, ctx);
    const int nq = rig_.nq();
    std::vector<std::vector<double>> truth(nq), reference(nq);
    std::vector<double> t_axis, drift_deg;
    double drift_final = 0.0;
    for (const jsk::Snapshot& s : snaps) {
      for (int j = 0; j < nq; ++j) {
        truth[j].push_back(s.link[j]);
        reference[j].push_back(s.reference[j]);
      }
      double worst = 0.0;
      for (size_t k = 0; k < s.imus.size(); ++k) {
        const double e = jsk::Deg(YawError(s.imus[k].q_base_frame, s.imu_true[k]));
        if (std::abs(e) > std::abs(worst)) worst = e;
      }
      t_axis.push_back(s.t);
      drift_deg.push_back(worst);
      drift_final = worst;
    }

    std::vector<jsk::Trace> traces;
    Json& all = (*ctx.summary)["estimators"];
    for (const jsk::LabelledEstimator& spec : estimators_) {
      int rejected = 0;
      jsk::Trace tr = jsk::RunOnSnapshots(rig_, spec, snaps, ctx.seed, false, ctx, &rejected);
      double err_max = 0.0, sq = 0.0;
      std::vector<double> err_max_joint(nq, 0.0);
      int n = 0;
      for (size_t i = 0; i < snaps.size(); ++i) {
        if (snaps[i].t < burn_in_s_) continue;
        ++n;
        for (int j = 0; j < nq; ++j) {
          const double e = std::abs(jsk::Deg(jsk::AngleError(tr.mean[j][i], truth[j][i])));
          err_max = std::max(err_max, e);
          err_max_joint[j] = std::max(err_max_joint[j], e);
          sq += e * e;
        }
      }
      Json& m = all[spec.label]["metrics"];
      m["estimator"] = spec.name;
      m["joint_err_max_deg"] = err_max;
      m["joint_err_max_deg_per_joint"] = err_max_joint;
      m["joint_rmse_deg"] = std::sqrt(sq / (n * nq));
      m["rejected_readings"] = rejected;
      traces.push_back(std::move(tr));
    }
    Json& metrics = (*ctx.summary)["metrics"];
    metrics["snapshots"] = static_cast<int>(snaps.size());
    metrics["duration_s"] = trajectory_.Duration();
    metrics["imu_yaw_drift_final_deg"] = std::abs(drift_final);

    jsk::WriteTraces(rig_, traces, &truth, reference, ctx.out);
    for (const jsk::Trace& tr : traces) {
      jsk::PlotJointBands(rig_, "IMU yaw drift: " + tr.label, {tr}, &truth, reference,
                          (ctx.out->FramesDir() / ("fig10_" + tr.label + ".png")).string(),
                          "time [s]");
    }
    // Fig. 10 in one panel pair: each estimator's joint errors against the IMUs' yaw drift.
    render::Figure fig(1400, 800, 2, 1);
    fig.title = "Unimodal vs axis-symmetric Bingham under IMU yaw drift";
    render::Axes& ax = fig.axes(0, 0);
    ax.title = "largest joint error of each estimator";
    ax.x_label = "time [s]";
    ax.y_label = "error [deg]";
    for (size_t e = 0; e < traces.size(); ++e) {
      std::vector<double> worst(snaps.size(), 0.0);
      for (size_t i = 0; i < snaps.size(); ++i) {
        for (int j = 0; j < nq; ++j) {
          worst[i] = std::max(
              worst[i], std::abs(jsk::Deg(jsk::AngleError(traces[e].mean[j][i], truth[j][i]))));
        }
      }
      render::Series& s = ax.AddLine(traces[e].label, traces[e].t, worst);
      s.color = render::PaletteColor(static_cast<int>(e));
      jsk::StyleComparison(&s);
    }
    ax.AddHLine(1.5, "1.5 deg gate");
    jsk::FitAxes(&ax);
    render::Axes& d = fig.axes(1, 0);
    d.title = "IMU yaw drift (Madgwick estimate vs truth, the larger of the two IMUs)";
    d.x_label = "time [s]";
    d.y_label = "yaw error [deg]";
    d.AddLine("IMU yaw drift", t_axis, drift_deg);
    jsk::FitAxes(&d, 0, 0.3);
    fig.SavePng((ctx.out->FramesDir() / "fig10_yaw_drift.png").string());
  }

 private:
  jsk::Rig rig_;
  jsk::Trajectory trajectory_;
  jsk::DynamicOptions options_;
  double burn_in_s_ = 1.0;
  std::unique_ptr<ConfigNode> sensors_node_;
  std::vector<jsk::LabelledEstimator> estimators_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskImuYawDriftKind() {
  return std::make_unique<JskImuYawDriftKind>();
}

}  // namespace flexbench::scenarios
