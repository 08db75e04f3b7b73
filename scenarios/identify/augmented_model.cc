#include <algorithm>
#include <cmath>

#include "scenarios/identify/run.h"
#include "sim/posture_load.h"

namespace flexbench::identify {
namespace {

// Appends `ie`, or adds it to an entry of the same name: values add up, stds by root sum of
// squares (the two fits' errors are independent).
void AddIdentifiedEffect(sim::IdentifiedEffect ie, std::vector<sim::IdentifiedEffect>* effects) {
  const auto same =
      std::find_if(effects->begin(), effects->end(),
                   [&](const sim::IdentifiedEffect& e) { return e.effect == ie.effect; });
  if (same == effects->end()) {
    effects->push_back(std::move(ie));
    return;
  }
  for (size_t k = 0; k < ie.value.size(); ++k) same->value[k] += ie.value[k];
  if (same->std.empty()) same->std.assign(ie.value.size(), 0.0);
  for (size_t k = 0; k < ie.std.size(); ++k) same->std[k] = std::hypot(same->std[k], ie.std[k]);
  same->equivalent = ie.equivalent;
}

// The fitted measurement frames' poses and marker offsets, with their covariances: a fitted
// offset adds to the declared one (the fit moved the frame the file had already moved).
void AddFittedFrames(const DataSet& d, const IdentifyResult& res, sim::DeclaredModel* out) {
  out->frames.clear();
  for (size_t f = 0; f < d.frames.size(); ++f) {
    out->frames.push_back({d.frames[f].name, res.after.T_base_frames[f], res.frame_cov[f], ""});
  }
  for (size_t k = 0; k < d.points.size(); ++k) {
    if (!d.offset_unknown[k]) continue;
    const auto same = std::find_if(out->marker_offsets.begin(), out->marker_offsets.end(),
                                   [&](const auto& m) { return m.frame == d.points[k]; });
    if (same == out->marker_offsets.end()) {
      out->marker_offsets.push_back(
          {d.points[k], res.after.marker_offsets[k], res.marker_offset_cov[k], ""});
    } else {
      same->offset_m += res.after.marker_offsets[k];
      same->cov += res.marker_offset_cov[k];
    }
  }
}

}  // namespace

// The declared model with the fit: its effects, frames and the sources scaled to what remains
// (the model file where the declared file has it).
sim::DeclaredModel AugmentedModel(const Job& job, const Report& report) {
  const IdentifyResult& res = report.result;
  sim::DeclaredModel out = *job.declared;
  ScaleSourceDirections(report.directions, report.constrained, report.source_scale, &out.sources);
  // The declared file's own effects stay (the fit acted on top of them); a refit of one of
  // them adds to it.
  for (const auto& e : res.effects) {
    const Candidate& fitted = job.em->candidates()[e.candidate];
    sim::IdentifiedEffect ie{fitted.Name(), e.value, e.std, fitted.unit, "", {}};
    // An equivalence set's name lists every member; the values are the fitted member's.
    if (e.name != ie.effect) ie.equivalent = e.members;
    AddIdentifiedEffect(std::move(ie), &out.identified_effects);
  }
  AddFittedFrames(report.cal, res, &out);
  return out;
}

// Where the fit holds: the range over the calibration and validation rows of each joint that
// moves a measured frame (the others, a mast beside the arm, were never measured), and the
// source directions those rows sized.
// `augmented`: the file being written; the loads and reach are taken on its chain (its
// fitted marker offsets move the end effector), as a run using it evaluates them.
sim::FittedUnder FittedUnder(const Job& job, const Report& report,
                             const sim::DeclaredModel& augmented) {
  const sim::DeclaredChain& chain = *job.chain;
  const mjModel* mj = job.mj;
  sim::FittedUnder f;
  const int nq = chain.model.nq();
  std::vector<char> moves(nq, 0);
  for (kinematics::FrameId p : job.em->points()) {
    for (; p > 0; p = chain.model.frame(p).parent) {
      if (chain.model.frame(p).q_index >= 0) moves[chain.model.frame(p).q_index] = 1;
    }
  }
  Eigen::VectorXd lo = Eigen::VectorXd::Constant(nq, INFINITY), hi = -lo;
  for (const DataSet* d : {&report.cal, &report.val}) {
    for (const Observation& o : d->rows) {
      lo = lo.cwiseMin(o.q);
      hi = hi.cwiseMax(o.q);
    }
  }
  // The loads and reach of the same rows (what a bending link or a compliant mount answers to).
  const sim::DeclaredChain used = sim::BuildDeclaredChain(mj, augmented, /*with_couplings=*/true);
  sim::PostureLoadEvaluator load(mj, used);
  sim::PostureLoad at;
  Eigen::VectorXd tau_lo = Eigen::VectorXd::Constant(nq, INFINITY), tau_hi = -tau_lo;
  Vec3 box_lo = Vec3::Constant(INFINITY), box_hi = -box_lo;
  for (const DataSet* d : {&report.cal, &report.val}) {
    for (const Observation& o : d->rows) {
      load.Evaluate(o.q, &at);
      tau_lo = tau_lo.cwiseMin(at.gravity_torque);
      tau_hi = tau_hi.cwiseMax(at.gravity_torque);
      box_lo = box_lo.cwiseMin(at.p_base_ee);
      box_hi = box_hi.cwiseMax(at.p_base_ee);
    }
  }
  for (int k = 0; k < nq; ++k) {
    if (!moves[k] || !(lo[k] <= hi[k])) continue;
    const int j = mj_name2id(mj, mjOBJ_JOINT, chain.q_joints[k].c_str());
    f.joint_ranges.push_back({chain.q_joints[k], lo[k], hi[k], mj->jnt_type[j] == mjJNT_SLIDE});
    f.gravity_torques.push_back({chain.q_joints[k], tau_lo[k], tau_hi[k]});
  }
  f.has_box = box_lo.x() <= box_hi.x();
  if (f.has_box) {
    f.box_min = box_lo;
    f.box_max = box_hi;
  }
  f.source_scale = report.source_scale;
  for (size_t i = 0; i < report.directions.size(); ++i) {
    (report.constrained[i] ? f.constrained_sources : f.kept_declared_sources)
        .push_back(report.directions[i].name);
  }
  return f;
}

}  // namespace flexbench::identify
