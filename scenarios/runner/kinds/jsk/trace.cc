#include "scenarios/runner/kinds/jsk/trace.h"

#include <cstdio>
#include <fstream>

#include "scenarios/runner/common/trajectories.h"

namespace flexbench::scenarios::jsk {

void Trace::Add(double time, const estimators::Belief& b, const pf::ParticleSummary* pf,
                const lie::SE3& T_true_step) {
  t.push_back(time);
  for (size_t j = 0; j < mean.size(); ++j) {
    const double m = b.q[j];
    mean[j].push_back(m);
    if (pf) {
      lower[j].push_back(pf->lower95[j]);
      upper[j].push_back(pf->upper95[j]);
    } else {
      lower[j].push_back(m - 1.96 * b.q_std[j]);
      upper[j].push_back(m + 1.96 * b.q_std[j]);
    }
  }
  const Vec3 e = b.T_base_ee.translation() - T_true_step.translation();
  T_est.push_back(b.T_base_ee);
  cov.push_back(b.cov);
  T_true.push_back(T_true_step);
  ee_err_m.push_back(e.norm());
  ee_err_z_m.push_back(e.z());
  ess.push_back(pf ? pf->ess : 0.0);
}

TracedRun::TracedRun(const Rig& rig, const EstimatorSpec& spec, std::uint64_t seed)
    : est(rig.MakeEstimator(spec, seed)) {
  est->Reset();
  trace.label = spec.label;
  trace.has_particles = est->Particles() != nullptr;
  trace.Resize(rig.nq());
}

void WriteTraces(const Rig& rig, const std::vector<Trace>& traces,
                 const std::vector<std::vector<double>>* truth,
                 const std::vector<std::vector<double>>& reference, OutputDir* out) {
  std::ofstream csv(out->File("traces.csv"));
  csv << "t,estimator,joint,truth_deg,reference_deg,mean_deg,lower95_deg,upper95_deg\n";
  char line[512];
  for (const Trace& tr : traces) {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      for (int j = 0; j < rig.nq(); ++j) {
        char truth_text[64] = "";
        if (truth) std::snprintf(truth_text, sizeof(truth_text), "%.6f", Deg((*truth)[j][i]));
        std::snprintf(line, sizeof(line), "%.4f,%s,%s,%s,%.6f,%.6f,%.6f,%.6f\n", tr.t[i],
                      tr.label.c_str(), rig.joint_names()[j].c_str(), truth_text,
                      Deg(reference[j][i]), Deg(tr.mean[j][i]), Deg(tr.lower[j][i]),
                      Deg(tr.upper[j][i]));
        csv << line;
      }
    }
  }
  std::ofstream ee(out->File("ee.csv"));
  ee << "t,estimator,ee_err_m,ee_err_z_m,ess\n";
  for (const Trace& tr : traces) {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      std::snprintf(line, sizeof(line), "%.4f,%s,%.9f,%.9f,%.3f\n", tr.t[i], tr.label.c_str(),
                    tr.ee_err_m[i], tr.ee_err_z_m[i], tr.ess[i]);
      ee << line;
    }
  }
  // TUM trajectories (a pose per step, t in seconds of the run; the synthetic kinds count steps).
  TrajectoryRecorder trajectories;
  if (!traces.empty()) {
    const Trace& first = traces.front();
    for (size_t i = 0; i < first.t.size(); ++i) trajectories.AddTruth(first.t[i], first.T_true[i]);
  }
  for (const Trace& tr : traces) {
    for (size_t i = 0; i < tr.t.size(); ++i) {
      trajectories.Add(tr.label, tr.t[i], tr.T_est[i], tr.cov[i]);
    }
  }
  trajectories.Write(*out, "base");
}

}  // namespace flexbench::scenarios::jsk
