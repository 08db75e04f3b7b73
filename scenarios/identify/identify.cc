#include "scenarios/identify/identify.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <limits>
#include <memory>

#include "estimators/error.h"
#include "estimators/stats/chi_square.h"
#include "scenarios/identify/cross_validation.h"
#include "scenarios/identify/diagnostics.h"
#include "scenarios/identify/equivalence.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/identify/parallel.h"
#include "scenarios/identify/problem.h"
#include "scenarios/identify/selection.h"

namespace flexbench::identify {
namespace {

// Candidates by stage: physically named ones first, those that need evidence, those chosen after
// the named ones, complete geometry.
std::vector<int> Pool(const EffectModel& em, const std::vector<int>& candidates, bool evidence,
                      bool generic, bool after_named = false) {
  std::vector<int> out;
  for (int c : candidates) {
    const Candidate& cand = em.candidates()[c];
    if (cand.needs_evidence == evidence && cand.generic_geometry == generic &&
        cand.after_named == after_named) {
      out.push_back(c);
    }
  }
  return out;
}

// The parameter of x's k-th alpha entry, named for messages.
std::string AlphaName(const EffectModel& em, const Fit& fit, int k) {
  for (size_t e = 0; e < fit.active.size(); ++e) {
    const int m = fit.basis[e].cols();
    if (k < m) {
      return em.candidates()[fit.active[e]].Name() +
             (fit.basis[e].cols() > 1 || fit.basis[e].rows() > 1 ? "[" + std::to_string(k) + "]"
                                                                 : "");
    }
    k -= m;
  }
  const int num_group_params = 3 * static_cast<int>(fit.group_points.size());
  const int num_frame_params = 6 * static_cast<int>(fit.T_base_frames.size());
  if (k >= num_group_params + num_frame_params) {
    return "marker offset [" + std::to_string(k - num_group_params - num_frame_params) + "]";
  }
  if (k >= num_group_params) {
    return "frame pose " + std::to_string((k - num_group_params) / 6) + "[" +
           std::to_string((k - num_group_params) % 6) + "]";
  }
  return "group point " + std::to_string(k / 3);
}

// The normalised information's pseudo-inverse (directions below singular_tol dropped), the
// fit's condition number, and what the data leave undetermined when it is near singular.
struct Information {
  Eigen::VectorXd d;     // column scaling: info = diag(1/d) In diag(1/d)
  Eigen::MatrixXd pinv;  // of In
};

Information InvertInformation(const EffectModel& em, const Fit& cur, const Eigen::MatrixXd& info,
                              const IdentifyOptions& opt, IdentifyResult* res) {
  Information out;
  out.d = info.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd In = out.d.asDiagonal() * info * out.d.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(In);
  const Eigen::VectorXd& lam = eig.eigenvalues();
  const double lmax = lam.maxCoeff();
  res->condition_number = lam[0] > 0 ? std::sqrt(lmax / lam[0]) : HUGE_VAL;
  out.pinv = Eigen::MatrixXd::Zero(In.rows(), In.cols());
  for (int i = 0; i < lam.size(); ++i) {
    if (lam[i] > opt.singular_tol * lmax) {
      out.pinv += eig.eigenvectors().col(i) * eig.eigenvectors().col(i).transpose() / lam[i];
    }
  }
  if (lam[0] > opt.singular_tol * lmax) return out;
  res->near_singular = true;
  const Eigen::VectorXd v = eig.eigenvectors().col(0);
  std::vector<int> idx(v.size());
  for (int i = 0; i < v.size(); ++i) idx[i] = i;
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return std::abs(v[a]) > std::abs(v[b]); });
  std::string combo;
  for (int i = 0; i < std::min<int>(3, v.size()); ++i) {
    if (std::abs(v[idx[i]]) < 0.1) break;
    combo +=
        Fmt("%s%+.2f %s", combo.empty() ? "" : " ", v[idx[i]], AlphaName(em, cur, idx[i]).c_str());
  }
  res->undetermined = combo;
  res->steps.push_back(
      Fmt("near singular: the data does not determine %s (eigenvalue ratio "
          "%.2g); its standard deviations cover only the determined part",
          combo.c_str(), lam[0] / lmax));
  return out;
}

// The fitted parameters' covariance and correlation (theta through the effects' bases).
void ThetaCovariance(const Problem& pr, const Fit& cur, const Information& inf,
                     IdentifyResult* res) {
  const int nt = static_cast<int>(cur.theta.size());
  const int dof = std::max(1, pr.num_residuals() - pr.num_params());
  const Eigen::MatrixXd cov_x =
      (cur.rss / dof) * inf.d.asDiagonal() * inf.pinv * inf.d.asDiagonal();
  // Alpha -> theta through the bases.
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(nt, pr.num_alpha());
  for (size_t e = 0, r = 0, c = 0; e < cur.active.size(); ++e) {
    B.block(r, c, cur.basis[e].rows(), cur.basis[e].cols()) = cur.basis[e];
    r += cur.basis[e].rows();
    c += cur.basis[e].cols();
  }
  const int na = pr.num_alpha();
  res->theta_cov = B * cov_x.topLeftCorner(na, na) * B.transpose();
  const Eigen::VectorXd sd = res->theta_cov.diagonal().cwiseMax(0).cwiseSqrt();
  res->theta_corr = res->theta_cov;
  for (int i = 0; i < nt; ++i) {
    for (int j = 0; j < nt; ++j) {
      res->theta_corr(i, j) = sd[i] * sd[j] > 0 ? res->theta_cov(i, j) / (sd[i] * sd[j]) : 0.0;
    }
  }
}

// How much the effects' corrections overlap once the group points are projected out: |sum|^2
// over the sum of |each|^2 (1: independent). From the stacked columns [J_groups d_1 .. d_k]
// (each effect's correction d_e = J_e alpha_e), so in row blocks from their triangular factor.
double EffectOverlap(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                     const IdentifyOptions& opt, const Problem& pr, const Fit& cur) {
  Fit groups_only = cur;
  groups_only.active.clear();
  groups_only.basis.clear();
  groups_only.theta.resize(0);
  const Problem pg(em, data, loads, groups_only.active, groups_only.basis, opt);
  const Eigen::VectorXd xg = StateOf(pg, groups_only);
  const Eigen::VectorXd x = StateOf(pr, cur);
  const int ng = pg.num_params();
  const int k = static_cast<int>(cur.active.size());
  const Eigen::MatrixXd C = StackedColumns(pg, [&](const Problem& block) {
    std::unique_ptr<Problem> rows;  // cur's problem on the block's rows
    if (&block != &pg) {
      rows = std::make_unique<Problem>(em, data, loads, cur.active, cur.basis, opt, block.rows());
    }
    const Eigen::MatrixXd J = (rows ? *rows : pr).Jacobian(x);
    Eigen::MatrixXd out(J.rows(), ng + k);
    out.leftCols(ng) = block.Jacobian(xg);
    for (int e = 0, a = 0; e < k; ++e) {
      const int m = static_cast<int>(cur.basis[e].cols());
      out.col(ng + e) = J.middleCols(a, m) * x.segment(a, m);
      a += m;
    }
    return out;
  });
  const Projector proj(C.leftCols(ng));
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(C.rows());
  double parts = 0.0;
  for (int e = 0; e < k; ++e) {
    const Eigen::VectorXd d = proj.Apply(C.col(ng + e));
    sum += d;
    parts += d.squaredNorm();
  }
  return parts > 0 ? sum.squaredNorm() / parts : 1.0;
}

// Each effect's values, stds (or its equivalence set's) and share of the RSS gain.
void FittedEffects(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                   const IdentifyOptions& opt, const Fit& cur, IdentifyResult* res) {
  const Eigen::VectorXd sd = res->theta_cov.diagonal().cwiseMax(0).cwiseSqrt();
  // Each effect's removal refitted on its own, side by side.
  const int n = static_cast<int>(cur.active.size());
  const int threads = TaskThreads(n, static_cast<int>(data.rows.size()), opt.threads);
  const IdentifyOptions task_opt = TaskOptions(opt, threads);
  std::vector<double> gain(n);
  ForEachTask(n, threads, [&](int e) {
    gain[e] = std::max(0.0, FitWithout(em, data, loads, cur, e, task_opt).rss - cur.rss);
  });
  double total = 0.0;
  int off = 0;
  for (size_t e = 0; e < cur.active.size(); ++e) {
    const int c = cur.active[e];
    const int np = em.candidates()[c].num_params;
    total += gain[e];
    FittedEffect fe;
    fe.candidate = c;
    fe.name = em.candidates()[c].Name();
    for (int k = 0; k < np; ++k) {
      fe.value.push_back(cur.theta[off + k]);
      fe.std.push_back(sd[off + k]);
    }
    for (const EquivalenceSet& s : res->equivalence) {
      if (s.effect != static_cast<int>(e)) continue;
      fe.name = s.name;
      fe.members.clear();
      for (const EquivalentMember& m : s.members) fe.members.push_back(m.name);
      fe.value = s.members[0].value;
      fe.unobservable = s.members[0].unobservable;
    }
    off += np;
    res->effects.push_back(fe);
  }
  for (size_t e = 0; e < res->effects.size(); ++e) {
    res->effects[e].share = total > 0 ? gain[e] / total : 0.0;
  }
}

// Covariance of the fitted parameters (pseudo-inverse of the normalised information; a near
// singular direction is reported, never hidden behind a clamped variance), correlations,
// condition number and each effect's share of the removed sum of squares.
void Report(const EffectModel& em, const DataSet& data, const RowLoads& loads,
            const IdentifyOptions& opt, IdentifyResult* res) {
  const Fit& cur = res->after;
  if (cur.theta.size() == 0) return;
  const Problem pr(em, data, loads, cur.active, cur.basis, opt);
  Eigen::MatrixXd info;
  NormalEquations(pr, StateOf(pr, cur), nullptr, &info, nullptr);
  const Information inf = InvertInformation(em, cur, info, opt, res);
  ThetaCovariance(pr, cur, inf, res);
  res->overlap = EffectOverlap(em, data, loads, opt, pr, cur);
  FittedEffects(em, data, loads, opt, cur, res);
}

// Diagnostics of `cur`'s residual; when they point at candidates that need evidence, those join
// the selection.
Fit FollowFinding(const SelectionContext& ctx, const std::vector<int>& candidates, Fit cur,
                  double* cv, IdentifyResult* res) {
  res->first_finding = FindResidualStructure(ctx.em, ctx.data, ctx.loads, cur, ctx.opt);
  res->steps.push_back(std::string("diagnostics: ") + res->first_finding.message +
                       (res->first_finding.significant ? " (significant)" : ""));
  const std::vector<int> unlocked = CandidatesFor(ctx.em, res->first_finding, candidates);
  if (unlocked.empty()) return cur;
  std::string names;
  for (int c : unlocked) {
    res->unlocked.push_back(ctx.em.candidates()[c].Name());
    names += (names.empty() ? "" : ", ") + res->unlocked.back();
  }
  res->steps.push_back("diagnostics let in: " + names);
  std::vector<int> pool = Pool(ctx.em, candidates, false, false);
  pool.insert(pool.end(), unlocked.begin(), unlocked.end());
  return SelectEffects(ctx, cur, pool, true, cv);
}

// Effect parameters `fit` determines: its effects' fitted directions.
int EffectParams(const EffectModel& em, const Fit& fit) {
  int n = 0;
  for (size_t e = 0; e < fit.active.size(); ++e) {
    n += e < fit.basis.size() && fit.basis[e].size() > 0
             ? static_cast<int>(fit.basis[e].cols())
             : em.candidates()[fit.active[e]].num_params;  // empty basis: every direction
  }
  return n;
}

// Whether the held-out error `cv` of `fit` is what the stated noise alone leaves: at most the
// (1 - explained_p) quantile of a mean chi-square over its residuals, raised by the share of
// fitted unknowns (a held-out residual's variance is about sigma^2 (1 + k / n)). Above it the
// chosen model leaves something unexplained, so being simpler than an alternative that does as
// well is no reason to prefer it: both may stand in for a cause the library lacks.
bool HeldOutAtNoise(const Fit& fit, double cv, const IdentifyOptions& opt) {
  const double n = std::max(1, fit.num_residuals);
  const double bound =
      stats::ChiSquareQuantile(1.0 - opt.explained_p, n) / n * (1.0 + fit.num_params / n);
  return cv <= bound;
}

// For each chosen effect, the best model without it (cross-validation only): the chosen model
// with it removed and refitted from the others' values, then forward selection from there over
// the named candidates with it banned. When the removal alone keeps the held-out error within
// ambiguity_cv, nothing is searched: the data does not single the effect out beyond noise. An
// alternative as good with more parameters is kept apart (Alternative): Occam's razor, as
// PreferSimpler applies it to the chosen model. The alternatives are independent: they run side
// by side, and are reported in the chosen order.
void FindAlternatives(const SelectionContext& ctx, const std::vector<int>& candidates,
                      const Fit& chosen, IdentifyResult* res) {
  if (!ctx.opt.cross_validation) return;
  std::vector<int> pool = Pool(ctx.em, candidates, false, false);
  for (const std::string& u : res->unlocked) pool.push_back(ctx.em.FindCandidate(u));
  std::vector<size_t> banned_list;  // index into chosen.active
  std::vector<std::vector<int>> rests;
  for (size_t e = 0; e < chosen.active.size(); ++e) {
    const int banned = chosen.active[e];
    if (ctx.em.candidates()[banned].generic_geometry) continue;
    // A wider family of the same kind (the generic error curve beside a transmission error)
    // reproduces it by construction: no competing cause.
    const bool angle_family = ctx.em.candidates()[banned].type == EffectType::kTransmissionError;
    std::vector<int> rest;
    for (int c : pool) {
      if (c == banned) continue;
      if (angle_family && ctx.em.candidates()[c].type == EffectType::kJointErrorCurve &&
          ctx.em.candidates()[c].q_index == ctx.em.candidates()[banned].q_index) {
        continue;
      }
      rest.push_back(c);
    }
    banned_list.push_back(e);
    rests.push_back(std::move(rest));
  }
  const double close_cv = (1.0 + ctx.opt.ambiguity_cv) * res->cv_after;
  const int n = static_cast<int>(banned_list.size());
  const int threads = TaskThreads(n, static_cast<int>(ctx.data.rows.size()), ctx.opt.threads);
  const IdentifyOptions task_opt = TaskOptions(ctx.opt, threads);
  std::vector<Fit> alts(n);
  std::vector<double> cvs(n);
  std::vector<int> kept(n);  // chosen effects the alternative keeps (the first of its list)
  ForEachTask(n, threads, [&](int i) {
    std::vector<std::string> quiet;
    const SelectionContext alt_ctx = TaskContext(ctx, task_opt, &quiet);
    const Fit start = FitWithout(ctx.em, ctx.data, ctx.loads, chosen, banned_list[i], task_opt);
    cvs[i] = CvError(alt_ctx, start);
    kept[i] = static_cast<int>(start.active.size());
    alts[i] = start;
    if (!start.active.empty() && cvs[i] < close_cv) return;
    // Forward steps only: the others were chosen beside the banned effect; a replacement is
    // what is looked for (no swap step either: found, not polished).
    alts[i] = SelectEffects(alt_ctx, start, rests[i], false, &cvs[i], false);
  });
  // A more complex alternative clearly better on held-out data still counts against the cause.
  const double better_cv = (1.0 - ctx.opt.cv_min_gain) * res->cv_after;
  const bool at_noise = HeldOutAtNoise(chosen, res->cv_after, ctx.opt);
  for (int i = 0; i < n; ++i) {
    const Fit& alt = alts[i];
    const double cv = cvs[i];
    Alternative a;
    a.banned = ctx.em.candidates()[chosen.active[banned_list[i]]].Name();
    a.cv = cv;
    a.num_params = EffectParams(ctx.em, alt);
    a.chosen_params = EffectParams(ctx.em, chosen);
    std::string added;
    for (size_t k = 0; k < alt.active.size(); ++k) {
      a.effects.push_back(ctx.em.candidates()[alt.active[k]].Name());
      if (static_cast<int>(k) >= kept[i]) added += (added.empty() ? "" : " + ") + a.effects.back();
    }
    const bool close = !alt.active.empty() && cv < close_cv;
    const bool costlier = close && a.num_params > a.chosen_params && !(cv < better_cv);
    const bool also_fits = costlier && at_noise;
    if (close && !also_fits) res->attribution_unique = false;
    const std::string what = alt.active.empty() ? "nothing"
                             : kept[i] == 0     ? added
                             : added.empty()    ? "the other chosen effects"
                                                : "the others + " + added;
    std::string judged;
    if (also_fits) {
      judged =
          Fmt(": also fits, with %d parameters instead of %d: the data favour the simpler "
              "chosen cause",
              a.num_params, a.chosen_params);
    } else if (close) {
      judged = Fmt(": as good, with %d parameters (chosen %d)%s: the cause is not singled out",
                   a.num_params, a.chosen_params,
                   costlier ? ", and the chosen model leaves more than the stated noise" : "");
    }
    res->steps.push_back(Fmt("without %s: %s reach held-out %.4g sigma^2 (chosen %.4g)%s",
                             a.banned.c_str(), what.c_str(), cv, res->cv_after, judged.c_str()));
    if (also_fits) res->also_fits.push_back(a);
    res->alternatives.push_back(std::move(a));
  }
}

// Chosen effects that together equal one simpler listed candidate are replaced by it when the
// data agrees (BIC lower, held-out error not higher, inside its bounds): Occam's razor on the
// model, e.g. a linear gear compliance plus a payload that only mimic a stiffening spring.
Fit PreferSimpler(const SelectionContext& ctx, const std::vector<int>& candidates, Fit cur,
                  double* cv) {
  for (int round = 0; round < 4; ++round) {
    bool replaced = false;
    for (const SimplerEquivalent& se :
         SimplerEquivalents(ctx.em, ctx.data, ctx.loads, cur, ctx.opt)) {
      if (std::find(candidates.begin(), candidates.end(), se.candidate) == candidates.end()) {
        continue;
      }
      Fit rest = cur;
      for (auto it = se.effects.rbegin(); it != se.effects.rend(); ++it) {
        rest = FitWithout(ctx.em, ctx.data, ctx.loads, rest, *it, ctx.opt);
      }
      const int np = ctx.em.candidates()[se.candidate].num_params;
      const Fit trial = FitWith(ctx.em, ctx.data, ctx.loads, rest, se.candidate,
                                Eigen::MatrixXd::Identity(np, np), ctx.opt);
      if (!(trial.bic < cur.bic) || !BoundViolations(ctx.em, trial).empty()) continue;
      const double cv_trial = CvError(ctx, trial);
      if (ctx.opt.cross_validation && cv_trial > *cv * (1.0 + ctx.opt.cv_min_gain)) continue;
      std::string names;
      for (int e : se.effects) {
        names += (names.empty() ? "" : " + ") + ctx.em.candidates()[cur.active[e]].Name();
      }
      ctx.log->push_back(Fmt("replace %s by the simpler %s (same correction): BIC %.1f -> %.1f",
                             names.c_str(), ctx.em.candidates()[se.candidate].Name().c_str(),
                             cur.bic, trial.bic));
      cur = trial;
      *cv = cv_trial;
      replaced = true;
      break;
    }
    if (!replaced) break;
  }
  return cur;
}

// `fit` refitted with the loads at the joint angles its own kinematic corrections give
// (EffectModel::LoadsFor), until those corrections settle (they move the loads by ~1%, so one
// or two passes); `*loads` those loads, left empty when the model does not shift them.
Fit RefitAtCorrectedLoads(const EffectModel& em, const DataSet& data, Fit fit,
                          const IdentifyOptions& opt, RowLoads* loads) {
  *loads = RowLoads();
  if (!em.LoadsShift(fit.active)) return fit;
  Eigen::VectorXd theta_used;
  for (int pass = 0; pass < 4; ++pass) {
    if (theta_used.size() == fit.theta.size() &&
        (fit.theta - theta_used).lpNorm<Eigen::Infinity>() <=
            1e-9 * std::max(1e-12, fit.theta.lpNorm<Eigen::Infinity>())) {
      break;
    }
    theta_used = fit.theta;
    *loads = ComputeLoads(em, data, fit.active, fit.theta);
    fit = FitEffects(em, data, *loads, fit.active, fit.basis, fit.theta, opt);
  }
  return fit;
}

}  // namespace

namespace {

// Whether the rows' loads keep their nominal poses (ConfigLoads::T_nominal, a pose per frame on
// the way to the points: most of a row's loads): while they take at most
// kNominalPoseCacheBytes in all. Beyond, PredictPose computes them (the same bits, slower).
bool CacheNominalPoses(const EffectModel& em, const DataSet& data) {
  const double bytes = static_cast<double>(data.rows.size()) * sizeof(lie::SE3) *
                       static_cast<double>(em.chain().num_frames());
  return bytes <= kNominalPoseCacheBytes;
}

// `L` with its motion signs and, unless cached, without its nominal poses.
ConfigLoads Stored(ConfigLoads L, const Observation& o, bool cache) {
  L.motion_sign = o.motion_sign;
  if (!cache) {
    L.T_nominal = std::vector<lie::SE3>();
    L.q_nominal = Eigen::VectorXd();
  }
  return L;
}

}  // namespace

size_t LoadsBytes(const ConfigLoads& L) {
  size_t gravity = 0;  // the gravity_tilt candidate's loads
  for (const GravityTerms& h : L.horizontal) {
    gravity += sizeof(GravityTerms) + sizeof(double) * (h.tau.size() + h.tau_unit.size()) +
               sizeof(Vec3) * (h.M_mid.size() + h.M_mid_unit.size()) +
               sizeof(double) * (h.M_lat.size() + h.M_lat_unit.size());
  }
  return sizeof(ConfigLoads) +
         sizeof(double) * (L.tau.size() + L.tau_unit.size() + L.M_lat.size() + L.M_lat_unit.size() +
                           L.axis_base.size() + L.lat_a_base.size() + L.lat_b_base.size() +
                           L.motion_sign.size() + L.q_nominal.size()) +
         sizeof(Vec3) * (L.M_mid.size() + L.M_mid_unit.size()) + sizeof(Mat3) * L.R_mid_T.size() +
         sizeof(lie::SE3) * L.T_nominal.size() + gravity;
}

RowLoads::RowLoads(std::vector<ConfigLoads> loads) : kept_(std::move(loads)), size_(kept_.size()) {}

RowLoads::RowLoads(const EffectModel& em, const DataSet& data, std::vector<int> active,
                   Eigen::VectorXd theta, double max_bytes)
    : em_(&em),
      active_(std::move(active)),
      theta_(std::move(theta)),
      max_bytes_(max_bytes),
      size_(data.rows.size()) {
  if (!em.LoadsShift(active_)) active_.clear();
  const bool cache = CacheNominalPoses(em, data);
  double bytes = 0.0;
  for (const Observation& o : data.rows) {
    ConfigLoads L = Stored(em.LoadsFor(o.q, active_, theta_.data()), o, cache);
    const double row_bytes = static_cast<double>(LoadsBytes(L));
    bytes += row_bytes;
    if (bytes > max_bytes_) break;
    // Reserved once: a vector's doubling would take up to twice the budget for a moment.
    if (kept_.empty()) kept_.reserve(std::min(size_, static_cast<size_t>(max_bytes_ / row_bytes)));
    kept_.push_back(std::move(L));
  }
}

const ConfigLoads& RowLoads::Compute(const Observation& o, EffectModel::Workspace& ws) const {
  ConfigLoads& L = em_->LoadsFor(o.q, active_, theta_.data(), ws);
  L.motion_sign = o.motion_sign;
  return L;
}

RowLoads RowLoads::Subset(const DataSet& subset, const std::vector<int>& rows) const {
  if (em_) return RowLoads(*em_, subset, active_, theta_, max_bytes_);
  std::vector<ConfigLoads> s;
  s.reserve(rows.size());
  for (int r : rows) s.push_back(kept_[r]);
  return RowLoads(std::move(s));
}

RowLoads ComputeLoads(const EffectModel& em, const DataSet& data) { return RowLoads(em, data); }

RowLoads ComputeLoads(const EffectModel& em, const DataSet& data, const std::vector<int>& active,
                      const Eigen::VectorXd& theta) {
  return RowLoads(em, data, active, theta);
}

std::vector<Vec3> PredictAll(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const std::vector<int>& active, const Eigen::VectorXd& theta) {
  std::vector<Vec3> p(data.rows.size());
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (size_t r = 0; r < data.rows.size(); ++r) {
    p[r] = em.Predict(data.rows[r].q, loads.At(r, data.rows[r], ws), active, theta.data(), ws,
                      data.rows[r].point);
  }
  return p;
}

Fit FitEffects(const EffectModel& em, const DataSet& data, const RowLoads& loads,
               const std::vector<int>& active, const Eigen::VectorXd& init,
               const IdentifyOptions& opt) {
  return FitEffects(em, data, loads, active, {}, init, opt);
}

IdentifyResult Identify(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                        const std::vector<int>& candidates, const IdentifyOptions& opt) {
  IdentifyResult res;
  res.before = FitEffects(em, data, loads, {}, Eigen::VectorXd(), opt);
  if (res.before.num_residuals <= res.before.num_params) {
    throw InputError(
        Fmt("identify: %d residuals for %d unknowns (group points): the data cannot "
            "determine its own sockets, let alone an effect",
            res.before.num_residuals, res.before.num_params));
  }
  {
    // A group of one row fixes its own point and nothing else: refused, not silently used.
    std::vector<int> count(data.groups.size(), 0);
    for (const Observation& o : data.rows) {
      if (o.type == ObservationType::kGroup) ++count[o.group];
    }
    for (size_t g = 0; g < count.size(); ++g) {
      if (count[g] == 1) {
        throw InputError("identify: group '" + data.groups[g] +
                         "' has one row; a group (socket) needs two or more");
      }
    }
  }
  Folds folds = MakeFolds(data, opt.folds_by);
  if (opt.cross_validation) CacheFolds(data, loads, &folds);
  res.folds_by = opt.cross_validation ? folds.by : "";
  res.num_folds = opt.cross_validation ? static_cast<int>(folds.test_rows.size()) : 0;
  if (opt.cross_validation && folds.test_rows.size() < 2) {
    const std::string unit = folds.by == "row" ? "rows" : folds.by + "s with rows";
    throw InputError("identify: cross-validation by " + folds.by + " needs at least two " + unit +
                     "; the data has " + std::to_string(folds.test_rows.size()) +
                     " (set cross_validation: false, or another folds_by)");
  }
  bool capped = false, out_of_time = false;
  SelectionMemo memo;
  SelectionContext ctx{em, data, loads, folds, opt, &res.steps, &capped, &memo};
  ctx.out_of_time = &out_of_time;
  size_t emitted = 0;
  const std::function<void()> flush = [&] {
    for (; emitted < res.steps.size(); ++emitted) {
      if (opt.on_step) opt.on_step(res.steps[emitted]);
    }
  };
  ctx.flush = &flush;
  double cv = CvError(ctx, res.before);
  res.cv_before = cv;
  if (opt.cross_validation) {
    res.steps.push_back(
        Fmt("cross-validation over %d folds by %s; declared model's held-out "
            "error %.4g sigma^2 (mean squared residual in units of the stated noise)",
            res.num_folds, folds.by.c_str(), cv));
  }
  flush();
  Fit cur = SelectEffects(ctx, res.before, Pool(em, candidates, false, false), true, &cv);
  cur = FollowFinding(ctx, candidates, std::move(cur), &cv, &res);
  flush();
  const std::vector<int> after_named = Pool(em, candidates, false, false, true);
  if (!after_named.empty()) {
    res.steps.push_back("beyond the named effects: lateral joint compliance");
    // Backward steps: a named effect that stood in for one of them may leave (no swap step,
    // which would trade named effects for them).
    cur = SelectEffects(ctx, cur, after_named, true, &cv, /*swap=*/false);
    flush();
  }
  const std::vector<int> generic = Pool(em, candidates, false, true);
  // Always tried: a cap limits what forward selection adds, never whether the joint origins are
  // looked at (the block is one step, kept only when the held-out error falls).
  if (!generic.empty() && !OutOfTime(ctx, "so the complete geometry is not tried")) {
    res.steps.push_back("complete geometry: joint origins beyond the named effects");
    cur = SelectEffects(ctx, cur, generic, false, &cv);
    double cv_block = cv;
    Fit block = AddGeometryBlock(ctx, cur, generic, &cv_block);
    const bool full =
        opt.max_effects >= 0 && static_cast<int>(cur.active.size()) >= opt.max_effects;
    if (block.active.size() > cur.active.size() && full) {
      res.steps.push_back(
          Fmt("stop: max_effects %d reached, so the geometry block above is not "
              "kept: the cap, not the data, ends the selection",
              opt.max_effects));
      capped = true;
    } else if (block.active.size() > cur.active.size()) {
      cur = std::move(block);
      cv = cv_block;
      // The block changes what is left: a named effect that stood in for geometry may go, one
      // the geometry hid may now lower the held-out error (no swap step: that would trade
      // named effects for joint origins).
      res.steps.push_back("after the complete geometry: the named effects again");
      std::vector<int> again = Pool(em, candidates, false, false);
      for (const std::string& u : res.unlocked) again.push_back(em.FindCandidate(u));
      again.insert(again.end(), after_named.begin(), after_named.end());
      cur = SelectEffects(ctx, cur, again, true, &cv, /*swap=*/false);
    }
  }
  cur = PreferSimpler(ctx, candidates, std::move(cur), &cv);
  flush();
  // The selection ran on the loads at the readings; the chosen model's values are refitted on
  // the loads where its own joint corrections put the arm, and analysed there.
  RowLoads shifted;
  const Fit chosen = cur;  // at the loads the selection used, where the alternatives start
  cur = RefitAtCorrectedLoads(em, data, std::move(cur), opt, &shifted);
  const RowLoads& final_loads = shifted.empty() ? loads : shifted;
  res.after = cur;
  res.cv_after = cv;
  res.stopped_by = out_of_time            ? "time_budget"
                   : capped               ? "max_effects"
                   : opt.cross_validation ? "held_out"
                                          : "bic";
  res.finding = FindResidualStructure(em, data, final_loads, cur, opt);
  if (!cur.active.empty() || !res.unlocked.empty()) {
    res.steps.push_back(std::string("diagnostics after: ") + res.finding.message +
                        (res.finding.significant ? " (significant)" : ""));
  }
  flush();
  FindAlternatives(ctx, candidates, chosen, &res);
  flush();
  FindEquivalents(em, data, final_loads, cur, candidates, opt, &res);
  FindSimplerEquivalents(em, data, final_loads, cur, candidates, opt, &res);
  for (const EquivalenceSet& s : res.equivalence) {
    if (s.members.size() > 1) {
      res.steps.push_back("equivalent on this data (named by all): " + s.name);
    }
  }
  flush();
  FindUnidentifiable(em, data, final_loads, cur, candidates, opt, &res);
  Report(em, data, final_loads, opt, &res);
  res.frame_cov = FrameCovariances(em, data, final_loads, cur, opt, &res.marker_offset_cov);
  flush();
  return res;
}

namespace {

// The angle between two directions (rad; accurate near 0, where acos is not).
double Angle(const Vec3& a, const Vec3& b) { return std::atan2(a.cross(b).norm(), a.dot(b)); }

}  // namespace

std::vector<int> FindOutliers(const EffectModel& em, const DataSet& data_in, const RowLoads& loads,
                              const IdentifyOptions& opt) {
  std::vector<int> out;
  if (!(opt.outlier_iqr > 0) || data_in.rows.empty()) return out;
  // Rows in measurement frames against the frames' reference poses (a registration).
  const DataSet data = InBase(data_in, ReferencePoses(data_in));
  const std::vector<Vec3> p = PredictAll(em, data, loads, {}, Eigen::VectorXd());
  const std::vector<Eigen::Vector2d> uv = PredictPixels(em, data, loads, {}, Eigen::VectorXd());
  // Coordinate-wise median of each group: a far-off row cannot drag it.
  std::vector<Vec3> median(data.groups.size(), Vec3::Zero());
  for (size_t g = 0; g < data.groups.size(); ++g) {
    for (int a = 0; a < 3; ++a) {
      std::vector<double> v;
      for (size_t r = 0; r < data.rows.size(); ++r) {
        if (data.rows[r].type == ObservationType::kGroup && data.rows[r].group == (int)g) {
          v.push_back(p[r][a]);
        }
      }
      if (v.empty()) continue;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      median[g][a] = v[v.size() / 2];
    }
  }
  const std::vector<Vec3> up = PredictUps(em, data, loads, {}, Eigen::VectorXd());
  std::vector<double> err(data.rows.size());
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Observation& o = data.rows[r];
    switch (o.type) {
      case ObservationType::kGroup:
        err[r] = (p[r] - median[o.group]).norm();
        break;
      case ObservationType::kPixel:
        err[r] = (uv[r] - o.uv).norm();
        break;
      case ObservationType::kGravity:
        err[r] = Angle(up[r], o.up());
        break;
      default:
        err[r] = (p[r] - o.p_base).norm();
        break;
    }
  }
  for (const RowUnit unit : {RowUnit::kMetres, RowUnit::kPixels, RowUnit::kRadians}) {
    std::vector<double> v;
    for (size_t r = 0; r < data.rows.size(); ++r) {
      if (UnitOf(data.rows[r].type) == unit) v.push_back(err[r]);
    }
    if (v.size() < 4) continue;
    std::sort(v.begin(), v.end());
    const auto quantile = [&](double f) {
      const double i = f * (v.size() - 1);
      const size_t lo = static_cast<size_t>(i);
      return lo + 1 < v.size() ? v[lo] + (i - lo) * (v[lo + 1] - v[lo]) : v[lo];
    };
    const double q1 = quantile(0.25), q3 = quantile(0.75);
    const double std = unit == RowUnit::kPixels    ? opt.pixel_std_px
                       : unit == RowUnit::kRadians ? opt.gravity_std_rad
                                                   : opt.point_std_m;
    const double limit = std::max(q3 + opt.outlier_iqr * (q3 - q1), 10.0 * std);
    for (size_t r = 0; r < data.rows.size(); ++r) {
      if (UnitOf(data.rows[r].type) == unit && !(err[r] <= limit)) {
        out.push_back(static_cast<int>(r));
      }
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

DataSet WithoutRows(const DataSet& data, const std::vector<int>& drop) {
  DataSet d = data;
  d.rows.clear();
  size_t k = 0;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (k < drop.size() && drop[k] == static_cast<int>(r)) {
      ++k;
      continue;
    }
    d.rows.push_back(data.rows[r]);
  }
  return d;
}

double NoiseRatio(const Fit& fit) {
  return std::sqrt(fit.rss / std::max(1, fit.num_residuals - fit.num_params));
}

std::string Verdict(const IdentifyResult& res, double val_before, double val_after) {
  if (!(NoiseRatio(res.after) <= kFarAboveNoise)) return "unexplained";
  const Fit& b = res.before;
  const bool noisy = b.rss > 2.0 * std::max(1, b.num_residuals - b.num_params);
  if (res.effects.empty()) {
    return res.finding.significant || noisy ? "unexplained" : "no_effect";
  }
  if (!(val_after < 0.99 * val_before)) return "unexplained";
  const Fit& a = res.after;
  const bool left = a.rss > 2.0 * std::max(1, a.num_residuals - a.num_params);
  // A cap that stopped the selection leaves what the data would still explain: never complete.
  if (res.finding.notable || left || res.stopped_by == "max_effects" ||
      res.stopped_by == "time_budget") {
    return "partly_explained";
  }
  return res.attribution_unique ? "explained" : "ambiguous";
}

std::vector<Eigen::Vector2d> PredictPixels(const EffectModel& em, const DataSet& data,
                                           const RowLoads& loads, const std::vector<int>& active,
                                           const Eigen::VectorXd& theta) {
  std::vector<Eigen::Vector2d> uv(data.rows.size(), Eigen::Vector2d::Zero());
  if (!data.camera.present) return uv;
  const lie::SE3 T_base_cam = CameraPose(em, data, active, theta.data());
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (data.rows[r].type != ObservationType::kPixel) continue;
    uv[r] = Project(data.camera, T_base_cam,
                    em.Predict(data.rows[r].q, loads.At(r, data.rows[r], ws), active, theta.data(),
                               ws, data.rows[r].point));
  }
  return uv;
}

std::vector<Vec3> PredictUps(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const std::vector<int>& active, const Eigen::VectorXd& theta) {
  std::vector<Vec3> up(data.rows.size(), Vec3::Zero());
  const Vec3 up_base = GravityUp(em, active, theta.data());
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Observation& o = data.rows[r];
    if (o.type != ObservationType::kGravity) continue;
    up[r] = em.PredictPose(o.q, loads.At(r, o, ws), active, theta.data(), ws, o.point)
                .rotation()
                .transpose() *
            up_base;
  }
  return up;
}

std::vector<Vec3> GroupMeans(const DataSet& data, const std::vector<Vec3>& points) {
  const int G = static_cast<int>(data.groups.size());
  std::vector<Vec3> mean(G, Vec3::Zero());
  std::vector<int> count(G, 0);
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (data.rows[r].type != ObservationType::kGroup) continue;
    mean[data.rows[r].group] += points[r];
    ++count[data.rows[r].group];
  }
  for (int g = 0; g < G; ++g) {
    if (count[g] > 0) mean[g] /= count[g];
  }
  return mean;
}

std::vector<double> RowErrors(const DataSet& data, const std::vector<Vec3>& points,
                              const std::vector<Eigen::Vector2d>& pixels,
                              const std::vector<Vec3>& ups) {
  const std::vector<Vec3> mean = GroupMeans(data, points);
  std::vector<double> e(data.rows.size());
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Observation& o = data.rows[r];
    switch (o.type) {
      case ObservationType::kGroup:
        e[r] = (points[r] - mean[o.group]).norm();
        break;
      case ObservationType::kPixel:
        e[r] = pixels.empty() ? std::nan("") : (pixels[r] - o.uv).norm();
        break;
      case ObservationType::kGravity:
        e[r] = ups.empty() ? std::nan("") : Angle(ups[r], o.up());
        break;
      default:  // a row still in a measurement frame has no base-frame point: InBase first
        e[r] = o.frame < 0 ? (points[r] - o.p_base).norm() : std::nan("");
        break;
    }
  }
  return e;
}

double ConsistencyError(const DataSet& data, const std::vector<double>& row_errors) {
  const int S = std::max<int>(1, static_cast<int>(data.sets.size()));
  std::vector<double> sum(S, 0.0);
  std::vector<int> count(S, 0);
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (UnitOf(data.rows[r].type) != RowUnit::kMetres) continue;
    sum[data.rows[r].set] += row_errors[r];
    ++count[data.rows[r].set];
  }
  double total = 0.0;
  int used = 0;
  for (int s = 0; s < S; ++s) {
    if (count[s] == 0) continue;
    total += sum[s] / count[s];
    ++used;
  }
  return used > 0 ? total / used : 0.0;
}

double MeanRowError(const DataSet& data, const std::vector<double>& row_errors, RowUnit unit) {
  double sum = 0.0;
  int n = 0;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (UnitOf(data.rows[r].type) != unit) continue;
    sum += row_errors[r];
    ++n;
  }
  return n > 0 ? sum / n : 0.0;
}

}  // namespace flexbench::identify
