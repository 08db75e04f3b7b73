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
#include <algorithm>
#include <cmath>

#include "render/plot.h"
#include "scenarios/runner/kinds/jsk/jsk_kind.h"
#include "scenarios/runner/kinds/jsk/plots.h"
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

// The larger IMU yaw error of each snapshot, signed, in degrees.
std::vector<double> YawDriftDeg(const std::vector<jsk::Snapshot>& snaps) {
  std::vector<double> drift_deg;
  for (const jsk::Snapshot& s : snaps) {
    double worst = 0.0;
    for (size_t k = 0; k < s.imus.size(); ++k) {
      const double e = jsk::Deg(YawError(s.imus[k].q_base_frame, s.imu_true[k]));
      if (std::abs(e) > std::abs(worst)) worst = e;
    }
    drift_deg.push_back(worst);
  }
  return drift_deg;
}

// The largest joint error of a trace at every step, in degrees.
std::vector<double> WorstJointErrorDeg(const jsk::Trace& tr,
                                       const std::vector<std::vector<double>>& truth) {
  std::vector<double> worst(tr.t.size(), 0.0);
  for (size_t i = 0; i < worst.size(); ++i) {
    for (size_t j = 0; j < truth.size(); ++j) {
      worst[i] =
          std::max(worst[i], std::abs(jsk::Deg(jsk::AngleError(tr.mean[j][i], truth[j][i]))));
    }
  }
  return worst;
}

class JskImuYawDriftKind : public jsk::DynamicKind {
 public:
  void Run(RunContext& ctx) override {
    const std::vector<jsk::Snapshot> snaps = Simulate(ctx);
    const std::vector<std::vector<double>> truth = LinkAngles(snaps);
    const std::vector<std::vector<double>> reference = Reference(snaps);
    const std::vector<double> drift_deg = YawDriftDeg(snaps);
    std::vector<int> rejected;
    const std::vector<jsk::Trace> traces = Estimate(snaps, ctx, &rejected);
    Json& all = (*ctx.summary)["estimators"];
    for (size_t e = 0; e < traces.size(); ++e) {
      Score(estimators_[e], traces[e], snaps, truth, rejected[e],
            &all[estimators_[e].label]["metrics"]);
    }
    WriteRunMetrics(snaps, ctx);
    (*ctx.summary)["metrics"]["imu_yaw_drift_final_deg"] =
        drift_deg.empty() ? 0.0 : std::abs(drift_deg.back());
    jsk::WriteTraces(rig_, traces, &truth, reference, ctx.out);
    PlotEachTrace("fig10_", "IMU yaw drift: ", traces, &truth, reference, ctx);
    PlotYawDrift(snaps, traces, truth, drift_deg, ctx);
  }

 private:
  // The true link-side angles per joint, [joint][snapshot].
  std::vector<std::vector<double>> LinkAngles(const std::vector<jsk::Snapshot>& snaps) const {
    std::vector<std::vector<double>> truth(rig_.nq());
    for (const jsk::Snapshot& s : snaps) {
      for (int j = 0; j < rig_.nq(); ++j) truth[j].push_back(s.link[j]);
    }
    return truth;
  }

  // Joint errors against the true link angles after the burn-in.
  void Score(const EstimatorSpec& spec, const jsk::Trace& tr,
             const std::vector<jsk::Snapshot>& snaps, const std::vector<std::vector<double>>& truth,
             int rejected, Json* metrics) const {
    const int nq = rig_.nq();
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
    Json& m = *metrics;
    m["estimator"] = spec.name;
    m["joint_err_max_deg"] = err_max;
    m["joint_err_max_deg_per_joint"] = err_max_joint;
    m["joint_rmse_deg"] = std::sqrt(sq / (n * nq));
    m["rejected_readings"] = rejected;
  }

  // Fig. 10 in one panel pair: each estimator's joint errors against the IMUs' yaw drift.
  void PlotYawDrift(const std::vector<jsk::Snapshot>& snaps, const std::vector<jsk::Trace>& traces,
                    const std::vector<std::vector<double>>& truth,
                    const std::vector<double>& drift_deg, const RunContext& ctx) const {
    render::Figure fig(1400, 800, 2, 1);
    fig.title = "Unimodal vs axis-symmetric Bingham under IMU yaw drift";
    render::Axes& ax = fig.axes(0, 0);
    ax.title = "largest joint error of each estimator";
    ax.x_label = "time [s]";
    ax.y_label = "error [deg]";
    for (size_t e = 0; e < traces.size(); ++e) {
      render::Series& s =
          ax.AddLine(traces[e].label, traces[e].t, WorstJointErrorDeg(traces[e], truth));
      s.color = render::PaletteColor(static_cast<int>(e));
      jsk::StyleComparison(&s);
    }
    ax.AddHLine(1.5, "1.5 deg gate");
    jsk::FitAxes(&ax);
    render::Axes& d = fig.axes(1, 0);
    d.title = "IMU yaw drift (Madgwick estimate vs truth, the larger of the two IMUs)";
    d.x_label = "time [s]";
    d.y_label = "yaw error [deg]";
    std::vector<double> t_axis;
    for (const jsk::Snapshot& s : snaps) t_axis.push_back(s.t);
    d.AddLine("IMU yaw drift", t_axis, drift_deg);
    jsk::FitAxes(&d, 0, 0.3);
    fig.SavePng((ctx.out->FramesDir() / "fig10_yaw_drift.png").string());
  }
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeJskImuYawDriftKind() {
  return std::make_unique<JskImuYawDriftKind>();
}

}  // namespace flexbench::scenarios
