// mismatch_matrix: every estimator against every undeclared effect. For each column
// the truth carries one effect (or none) the declared model knows nothing of; at the same random
// configurations each estimator fuses the encoders and a tracked end-effector point and is
// scored against the settled truth. Writes matrix.csv (one row per estimator and effect: errors,
// NEES, its chi-square bound, flagged) and matrix.png (heat maps of error and NEES, flagged cells
// outlined). Metric `unflagged_growth_cells`: cells whose error grew by `growth_factor` over the
// no-effect column while the mean NEES stayed inside its bound -- the mismatch went unnoticed.
// Per cell, the running-NEES test (common/error_stats.h, window 10) over the configurations
// in order gives the detection delay: the configuration at which it first fires (-1: never).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <sstream>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/stats/chi_square.h"
#include "render/plot.h"
#include "scenarios/runner/common/error_stats.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/log_export.h"
#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/common/pose.h"
#include "scenarios/runner/common/sim_readings.h"
#include "scenarios/runner/common/trajectories.h"
#include "scenarios/runner/common/truth_rig.h"
#include "scenarios/runner/kinds/kinds.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {
namespace {

class MismatchMatrixKind : public ScenarioKind {
 public:
  bool ExportsLog() const final { return true; }

  void Configure(const ConfigNode& root) override {
    rig_.declared = ReadModelAndDeclared(root, &model_path_);
    const ConfigNode effects = root.Child("effects");
    for (const std::string& name : effects.Keys()) {
      columns_.push_back(name);
      sims_.push_back(sim::Simulation::Load(model_path_, sim::ParseEffects(effects.Child(name))));
    }
    if (columns_.empty() || columns_[0] != "none") {
      effects.Fail("the first column must be 'none' (the reference the others are compared to)");
    }
    count_ = root.GetInt("configurations", 30);
    if (count_ < 2) root.Child("configurations").Fail("need at least 2");
    for (const std::string& j : root.Child("ranges_deg").Keys()) {
      const std::vector<double> r = root.Child("ranges_deg").Child(j).AsDoubleList();
      if (r.size() != 2 || !(r[0] <= r[1])) root.Child("ranges_deg").Child(j).Fail("[lo, hi]");
      ranges_.emplace_back(j, std::pair{r[0] * kDeg, r[1] * kDeg});
    }
    encoder_std_ = root.GetDouble("encoder_noise_deg", 0.05) * kDeg;
    point_std_ = root.GetDouble("point_std_m", 0.002);
    growth_ = root.GetDouble("growth_factor", 1.5);
    steps_ = root.GetInt("steps_per_configuration", 1);
    if (steps_ < 1) root.Child("steps_per_configuration").Fail("need at least 1");
    specs_ = ParseEstimators(root.Child("estimators"));
    const sim::Simulation& s0 = *sims_[0];
    rig_ = BuildDeclaredRig(s0.nominal_model(), std::move(rig_.declared));
    for (const auto& [j, r] : ranges_) rig_.chain->QIndex(j);  // names checked now
    for (const EstimatorSpec& spec : specs_) instances_.push_back(rig_.MakeEstimator(spec, 1));
  }

  // Per column (one effect in the truth): configurations settled -> readings at rest ->
  // estimates -> scores; then the matrix (CSV, heat maps, metrics).
  void Run(RunContext& ctx) override {
    const std::vector<Eigen::VectorXd> configs = DrawConfigurations(ctx.seed);
    range_ = FittedRangeCheck(rig_.declared, rig_.chain->q_joints, sims_[0]->nominal_model(),
                              rig_.chain.get());
    // Detection delay: the running-NEES test over the configurations in their order.
    std::vector<std::vector<ErrorStats>> stats(
        instances_.size(),
        std::vector<ErrorStats>(columns_.size(), ErrorStats(std::min(10, count_))));
    // --export-log: each column's readings as a log, DIR/<column>: its configurations are
    // postures (postures.csv: the estimators start afresh at each, as here), every step's
    // encoders and tracked point (positions.csv), the truth.
    std::vector<std::pair<std::string, sim::RecordedLog>> logs;
    for (size_t col = 0; col < columns_.size(); ++col) {
      if (!ctx.export_log.empty()) {
        logs.emplace_back(columns_[col], LogOfChain(rig_.declared, *rig_.chain));
        logs.back().second.joint_std = encoder_std_;
        logs.back().second.sensed_frames = {rig_.declared.end_effector};
      }
      RunColumn(col, configs, &stats, ctx, logs.empty() ? nullptr : &logs.back().second);
    }
    if (!logs.empty()) {
      WriteLogsWithDeclared(logs, rig_.declared, ctx.export_log);
      ctx.log("readings of every column written to " + ctx.export_log + "/<column>");
    }
    range_.Report(ctx);
    Report(stats, ctx);
  }

 private:
  std::vector<Eigen::VectorXd> DrawConfigurations(std::uint64_t seed) const {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Eigen::VectorXd> configs;
    for (int c = 0; c < count_; ++c) {
      Eigen::VectorXd q = Eigen::VectorXd::Zero(rig_.chain->model.nq());
      for (const auto& [j, r] : ranges_)
        q[rig_.chain->QIndex(j)] = r.first + (r.second - r.first) * u(rng);
      configs.push_back(q);
    }
    return configs;
  }

  // The same noise draws in every column: differences come from the effects alone.
  struct Noise {
    explicit Noise(std::uint64_t seed) : rng(seed + 7) {}
    std::mt19937_64 rng;
    std::normal_distribution<double> n{0.0, 1.0};
    double operator()() { return n(rng); }
  };

  void RunColumn(size_t col, const std::vector<Eigen::VectorXd>& configs,
                 std::vector<std::vector<ErrorStats>>* stats, RunContext& ctx,
                 sim::RecordedLog* log) {
    sim::Simulation& sim = *sims_[col];
    const sim::FrameRef ee = sims_[0]->Frame(rig_.declared.end_effector);
    TrajectoryRecorder trajectories;  // one pose per configuration (timestamp: its index)
    const std::vector<int> act = ActuatorIndices(sim);
    Noise noise(ctx.seed);
    for (int c = 0; c < count_; ++c) {
      ctx.progress("mismatch " + columns_[col], c, count_);
      Eigen::VectorXd cmd = Eigen::VectorXd::Zero(sim.num_actuated());
      for (int k = 0; k < rig_.chain->model.nq(); ++k) cmd[act[k]] = configs[c][k];
      sim.SetCommand(cmd);
      sim.Settle();
      const lie::SE3 T_true = ToSE3(sim.Pose(ee));
      // The arm rests while readings stream in (fresh noise each step); filters that need
      // several steps to converge get them, EKFs restart from each step's prior.
      for (auto& est : instances_) est->Reset();
      if (log) log->posture_starts.push_back(c * steps_);
      for (int step = 0; step < steps_; ++step) {
        FeedStep(sim, T_true, c * steps_ + step, &noise, log);
      }
      trajectories.AddTruth(c, T_true);
      for (size_t e = 0; e < instances_.size(); ++e) {
        const estimators::Belief b = instances_[e]->Estimate();
        (*stats)[e][col].Add(b.T_base_ee, b.cov, T_true);
        trajectories.Add(specs_[e].name, c, b.T_base_ee, b.cov);
      }
    }
    trajectories.Write(*ctx.out, "base", columns_[col]);
  }

  // Where each declared joint sits among the simulation's actuated joints.
  std::vector<int> ActuatorIndices(const sim::Simulation& sim) const {
    const std::vector<int> act = scenarios::ActuatorIndices(sim, *rig_.chain);
    for (size_t k = 0; k < act.size(); ++k) {
      if (act[k] < 0) {
        throw InputError(model_path_ + ": declared joint '" + rig_.chain->q_joints[k] +
                         "' is not actuated in the truth");
      }
    }
    return act;
  }

  // One step's readings (the encoders and the tracked point, with noise) into every estimator,
  // and into `log` when given.
  void FeedStep(const sim::Simulation& sim, const lie::SE3& T_true, double t, Noise* noise,
                sim::RecordedLog* log) {
    const int nq = rig_.chain->model.nq();
    estimators::JointReading joints;
    joints.t = t;
    joints.q.resize(nq);
    joints.std = estimators::JointVector::Constant(nq, encoder_std_);
    for (int k = 0; k < nq; ++k) {
      const int jid = mj_name2id(sim.model(), mjOBJ_JOINT, rig_.chain->q_joints[k].c_str());
      joints.q[k] = sim.MotorPosition(jid) - sim.JointOffset(jid) + encoder_std_ * (*noise)();
    }
    estimators::PositionReading point;
    point.t = t;
    point.frame = rig_.chain->end_effector;
    // z, y, x: the order GCC evaluated the arguments of the Vec3(n(), n(), n()) this was, so the
    // draws (and every output) stay what they were.
    const double n2 = (*noise)(), n1 = (*noise)(), n0 = (*noise)();
    point.p_base = T_true.translation() + point_std_ * Vec3(n0, n1, n2);
    point.cov = point_std_ * point_std_ * Mat3::Identity();
    if (log) {
      AddStepToLog(joints, T_true, log);
      log->positions.push_back({t, 0, point.p_base, point_std_});
    }
    range_.Observe(joints.q.data(), nq);
    for (auto& est : instances_) {
      est->Predict(t);
      est->Update(joints);
      est->Update(point);
    }
  }

  // The matrix: one CSV row and one heat-map cell per estimator and effect.
  struct Matrix {
    std::ostringstream csv;
    render::Heatmap err_map, nees_map;
    int unflagged = 0, grown = 0;
  };

  void Report(const std::vector<std::vector<ErrorStats>>& stats, RunContext& ctx) const {
    Matrix mx;
    mx.csv << "estimator,effect,pos_err_mean_m,rot_err_mean_deg,nees_mean,nees_dof,"
              "nees_bound_high,flagged,error_grew,detection_delay_configurations\n";
    mx.err_map.title = "end-effector position error [mm]";
    mx.nees_map.title = "mean NEES / its 97.5% bound";
    mx.err_map.col_labels = mx.nees_map.col_labels = columns_;
    for (size_t e = 0; e < instances_.size(); ++e) {
      for (render::Heatmap* map : {&mx.err_map, &mx.nees_map}) {
        map->row_labels.push_back(specs_[e].name);
        map->value.emplace_back();
        map->text.emplace_back();
        map->marked.emplace_back();
      }
      Json ref;
      stats[e][0].WriteMetrics(&ref);
      for (size_t col = 0; col < columns_.size(); ++col) {
        AddCell(e, col, stats[e][col], ref["pos_err_mean_m"].get<double>(), &mx, ctx);
      }
    }
    mx.err_map.note = "outlined: error grew > " + Fmt("%.3g", growth_) + "x the 'none' column";
    mx.nees_map.note = "outlined: NEES above its bound (mismatch flagged)";
    WriteFileAtomic(ctx.out->File("matrix.csv"), mx.csv.str());
    render::SaveHeatmapsPng({mx.err_map, mx.nees_map}, 1400,
                            160 + 60 * static_cast<int>(instances_.size()),
                            ctx.out->File("matrix.png").string());
    Json& m = (*ctx.summary)["metrics"];
    m["effects"] = columns_;
    m["configurations"] = count_;
    m["cells_with_error_growth"] = mx.grown;
    m["unflagged_growth_cells"] = mx.unflagged;
  }

  // Estimator e under effect col: its metrics, CSV row and cells; `ref_pos` is its error with
  // no effect.
  void AddCell(size_t e, size_t col, const ErrorStats& stats, double ref_pos, Matrix* mx,
               RunContext& ctx) const {
    Json m;
    stats.WriteMetrics(&m);
    m["detection_delay_configurations"] = stats.mismatch().first_step();
    (*ctx.summary)["estimators"][specs_[e].name]["metrics"][columns_[col]] = m;
    const double pos = m["pos_err_mean_m"].get<double>();
    const double nees = m["nees_mean"].get<double>();
    const double high =
        m.contains("nees_bound_high") ? m["nees_bound_high"].get<double>() : std::nan("");
    const bool flagged = nees > high;
    const bool grew = col > 0 && pos > growth_ * ref_pos;
    mx->grown += grew;
    mx->unflagged += grew && !flagged;
    mx->csv << specs_[e].name << "," << columns_[col] << "," << Fmt("%.6g", pos) << ","
            << Fmt("%.6g", m["rot_err_mean_deg"].get<double>()) << "," << Fmt("%.6g", nees) << ","
            << m.value("nees_dof", 0.0) << "," << Fmt("%.6g", high) << "," << flagged << "," << grew
            << "," << stats.mismatch().first_step() << "\n";
    mx->err_map.value.back().push_back(1e3 * pos);
    mx->err_map.text.back().push_back(Fmt("%.2f", 1e3 * pos));
    mx->err_map.marked.back().push_back(grew);
    mx->nees_map.value.back().push_back(nees / high);
    mx->nees_map.text.back().push_back(Fmt("%.3g", nees / high));
    mx->nees_map.marked.back().push_back(flagged);
  }

  std::string model_path_;
  std::vector<std::string> columns_;
  std::vector<std::unique_ptr<sim::Simulation>> sims_;
  int count_ = 30;
  std::vector<std::pair<std::string, std::pair<double, double>>> ranges_;
  double encoder_std_ = 0.0, point_std_ = 0.002, growth_ = 1.5;
  int steps_ = 1;
  std::vector<EstimatorSpec> specs_;
  DeclaredRig rig_;         // on the first column's truth's nominal model (all columns share it)
  FittedRangeCheck range_;  // the declared model used beyond where it was fitted (Run)
  std::vector<std::unique_ptr<estimators::Estimator>> instances_;
};

}  // namespace

std::unique_ptr<ScenarioKind> MakeMismatchMatrixKind() {
  return std::make_unique<MismatchMatrixKind>();
}

}  // namespace flexbench::scenarios
