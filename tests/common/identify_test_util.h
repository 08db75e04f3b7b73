// Helpers of the identification suites (tracker frames, gravity tilt, coupled joints): the first
// stage of the candidate library, and a tracker's view of a MuJoCo truth.
#pragma once

#include <algorithm>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"
#include "scenarios/identify/effect_model.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/measurement_frames.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {

// A model of models/ (`which`: "rover_arm" for models/rover_arm.declared.yaml), its declared
// chain and the candidate effects on it.
struct ModelRig {
  sim::MjModelPtr m;
  sim::DeclaredChain chain;
  std::unique_ptr<identify::EffectModel> em;
};

inline std::unique_ptr<ModelRig> LoadModelRig(const std::string& which) {
  auto r = std::make_unique<ModelRig>();
  const sim::DeclaredModel d =
      sim::LoadDeclaredModel(SourceDir() + "/models/" + which + ".declared.yaml");
  r->m = sim::LoadModel(d.model_path);
  r->chain = sim::BuildDeclaredChain(r->m.get(), d);
  r->em = std::make_unique<identify::EffectModel>(r->m.get(), r->chain, r->chain.end_effector);
  return r;
}

// The library's first stage: named families (not needs-evidence, not complete geometry),
// minus the families in `banned`.
inline std::vector<int> NamedCandidates(const identify::EffectModel& em,
                                        const std::vector<std::string>& banned = {}) {
  std::vector<int> c;
  for (size_t i = 0; i < em.candidates().size(); ++i) {
    const identify::Candidate& cand = em.candidates()[i];
    if (cand.needs_evidence || cand.generic_geometry) continue;
    if (std::find(banned.begin(), banned.end(), identify::ToString(cand.type)) != banned.end()) {
      continue;
    }
    c.push_back(static_cast<int>(i));
  }
  return c;
}

// The fitted effects for a test's messages, "a + b" ("-" for none).
inline std::string EffectNames(const identify::IdentifyResult& r) {
  std::string s;
  for (const identify::FittedEffect& e : r.effects) s += (s.empty() ? "" : " + ") + e.name;
  return s.empty() ? "-" : s;
}

// `rows` configurations of rig's truth (rig.sim, a sim::Simulation with a site "ee"; rig.chain,
// its declared chain): commands uniform in +-1 rad, settled under gravity, the marker d_marker
// off the site seen by a tracker at T_base_tracker (frame 0 of the data set) with noise_std per
// axis.
template <class Rig>
identify::DataSet TrackerData(Rig& rig, const lie::SE3& T_base_tracker, int rows, double noise_std,
                              std::mt19937_64& rng, const Vec3& d_marker = Vec3::Zero()) {
  identify::DataSet d;
  d.sets = {"s"};
  identify::MeasurementFrame tracker;
  tracker.name = "tracker";
  tracker.where = "test.yaml:1";
  d.frames = {tracker};
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> n(0.0, noise_std);
  const auto& names = rig.sim->actuated_joints();
  const lie::SE3 T_tracker_base = T_base_tracker.Inverse();
  for (int r = 0; r < rows; ++r) {
    Eigen::VectorXd cmd = Eigen::VectorXd::Zero(rig.sim->num_actuated());
    identify::Observation o;
    o.q.resize(rig.chain.model.nq());
    for (int k = 0; k < o.q.size(); ++k) {
      const int a = std::find(names.begin(), names.end(), rig.chain.q_joints[k]) - names.begin();
      cmd[a] = o.q[k] = 1.0 * u(rng);
    }
    rig.sim->SetCommand(cmd);
    rig.sim->Settle();
    const Vec3 p_base(rig.sim->Pose("ee") * d_marker);  // the marker, d_marker off the site
    o.frame = 0;
    o.p_frame = T_tracker_base * p_base + Vec3(n(rng), n(rng), n(rng));
    d.rows.push_back(o);
  }
  return d;
}

}  // namespace flexbench::testing
