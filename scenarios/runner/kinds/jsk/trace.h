// Per-step traces of the jsk kinds' estimators and the files written from them.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "estimators/estimator.h"
#include "estimators/pf/particle_filter.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios::jsk {

// Per-step traces of one estimator.
struct Trace {
  std::string label;
  std::vector<double> t;
  std::vector<std::vector<double>> mean, lower, upper;  // [joint][step], radians
  std::vector<double> ee_err_m;                         // |p_est - p_true| of the end effector
  std::vector<double> ee_err_z_m;                       // z component p_est - p_true
  std::vector<double> ess;
  bool has_particles = false;  // the estimator is a particle filter (ess is its, else zeros)
  // The end effector's pose per step: the estimate (mean, covariance) and the truth, for the
  // TUM trajectories.
  std::vector<lie::SE3> T_est, T_true;
  std::vector<Mat6> cov;
  void Resize(int nq) { mean.resize(nq), lower.resize(nq), upper.resize(nq); }
  // Appends one step from a belief (and the particle summary's interval when `pf` is set).
  void Add(double time, const estimators::Belief& b, const pf::ParticleSummary* pf,
           const lie::SE3& T_true);
};

// One estimator's run over a jsk kind's readings: the estimator (reset), its trace, and the
// count of updates it refused (neither accepted nor ignored).
struct TracedRun {
  TracedRun(const Rig& rig, const EstimatorSpec& spec, std::uint64_t seed);
  void Count(estimators::UpdateStatus st) {
    rejected +=
        st != estimators::UpdateStatus::kAccepted && st != estimators::UpdateStatus::kIgnored;
  }
  // Appends the estimate after the step's updates.
  void Record(double time, const lie::SE3& T_true) {
    trace.Add(time, est->Estimate(), est->Particles(), T_true);
  }
  std::unique_ptr<estimators::Estimator> est;
  Trace trace;
  int rejected = 0;
};

// "traces.csv": t, label, joint, truth, reference, mean, lower, upper (degrees), "ee.csv" and
// the TUM trajectories.
void WriteTraces(const Rig& rig, const std::vector<Trace>& traces,
                 const std::vector<std::vector<double>>* truth,
                 const std::vector<std::vector<double>>& reference, OutputDir* out);

}  // namespace flexbench::scenarios::jsk
