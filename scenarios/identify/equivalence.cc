#include "scenarios/identify/equivalence.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <memory>

#include "scenarios/identify/problem.h"

namespace flexbench::identify {

Projector::Projector(const Eigen::MatrixXd& J_fit) {
  if (J_fit.cols() == 0) return;
  // An orthonormal basis of the columns' span; columns of (numerically) no rank add nothing.
  Eigen::MatrixXd Jn = J_fit;
  for (int k = 0; k < Jn.cols(); ++k) {
    const double n = Jn.col(k).norm();
    if (n > 0) Jn.col(k) /= n;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Jn);
  qr.setThreshold(1e-10);
  const int rank = static_cast<int>(qr.rank());
  Q_ = qr.householderQ() * Eigen::MatrixXd::Identity(Jn.rows(), rank);
}

Eigen::MatrixXd Projector::Apply(const Eigen::MatrixXd& M) const {
  if (Q_.cols() == 0) return M;
  return M - Q_ * (Q_.transpose() * M);
}

void Projector::ApplyInPlace(Eigen::MatrixXd* M) const {
  if (Q_.cols() == 0) return;
  const Eigen::MatrixXd QtM = Q_.transpose() * *M;
  M->noalias() -= Q_ * QtM;
}

Eigen::MatrixXd ObservableBasis(const Eigen::MatrixXd& Jc, const Projector& proj, double tol,
                                double* rel) {
  const int np = static_cast<int>(Jc.cols());
  // Scale each parameter to unit sensitivity, so directions compare by their effect.
  Eigen::VectorXd scale(np);
  for (int k = 0; k < np; ++k) {
    const double n = Jc.col(k).norm();
    scale[k] = n > 0 ? 1.0 / n : 0.0;
  }
  Eigen::MatrixXd Js, Rs, G;
  if (Jc.rows() < 2 * kRowBlock) {
    Js = Jc * scale.asDiagonal();
    Rs = proj.Apply(Js);
  } else {
    // Many rows: one copy of the columns, projected in place and reduced to its triangular
    // factor (the same singular values and directions); |Js v| from the Gram matrix.
    Rs = Jc * scale.asDiagonal();
    G = scale.asDiagonal() * (Jc.transpose() * Jc) * scale.asDiagonal();
    proj.ApplyInPlace(&Rs);
    Eigen::HouseholderQR<Eigen::Ref<Eigen::MatrixXd>> qr(Rs);
    Rs = Eigen::MatrixXd(qr.matrixQR()
                             .topRows(std::min<Eigen::Index>(np, Rs.rows()))
                             .triangularView<Eigen::Upper>());
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Rs, Eigen::ComputeThinV);
  std::vector<Eigen::VectorXd> keep;
  double best = 0.0;
  for (int i = 0; i < svd.singularValues().size(); ++i) {
    const Eigen::VectorXd v = svd.matrixV().col(i);
    const double full = G.size() > 0 ? std::sqrt(std::max(0.0, v.dot(G * v))) : (Js * v).norm();
    const double r = full > 0 ? svd.singularValues()[i] / full : 0.0;
    best = std::max(best, r);
    if (r > tol) keep.push_back((scale.asDiagonal() * v).normalized());
  }
  *rel = best;
  Eigen::MatrixXd B(np, keep.size());
  for (size_t i = 0; i < keep.size(); ++i) B.col(i) = keep[i];
  return B;
}

Eigen::MatrixXd StackedColumns(const Problem& pr,
                               const std::function<Eigen::MatrixXd(const Problem& block)>& cols,
                               bool* compressed) {
  Eigen::MatrixXd R;
  if (compressed) *compressed = pr.InRowBlocks();
  pr.ForEachRowBlock([&](const Problem& block, int at) {
    Eigen::MatrixXd C = cols(block);
    if (&block == &pr) {
      R = std::move(C);
      return;
    }
    const Eigen::Index k = C.cols();
    const Eigen::Index m = at == 0 ? C.rows() : block.rows_dim();  // priors: once
    if (R.cols() != k) R.resize(0, k);                             // the first block
    Eigen::MatrixXd M(R.rows() + m, k);
    M.topRows(R.rows()) = R;
    M.bottomRows(m) = C.topRows(m);
    C.resize(0, 0);
    Eigen::HouseholderQR<Eigen::Ref<Eigen::MatrixXd>> qr(M);
    R = M.topRows(std::min(k, M.rows())).triangularView<Eigen::Upper>();
  });
  return R;
}

namespace {

// cs split into batches of at most kCandidateColumnBytes of columns with `base` columns
// beside each (at least one candidate a batch); a column has `entries` doubles.
std::vector<std::vector<int>> Batches(const EffectModel& em, const std::vector<int>& cs, int base,
                                      double entries) {
  const double column_bytes = sizeof(double) * entries;
  std::vector<std::vector<int>> out;
  double bytes = 0.0;
  for (int c : cs) {
    const double more = column_bytes * em.candidates()[c].num_params;
    if (out.empty() || (out.back().size() > 0 && bytes + more > kCandidateColumnBytes)) {
      out.emplace_back();
      bytes = column_bytes * base;
    }
    out.back().push_back(c);
    bytes += more;
  }
  if (out.empty()) out.emplace_back();
  return out;
}

// The columns of each of `cs` in R, one after the other from column `at` on.
std::vector<Eigen::MatrixXd> Split(const Eigen::MatrixXd& R, int at, const std::vector<int>& cs,
                                   const EffectModel& em) {
  std::vector<Eigen::MatrixXd> out;
  for (int c : cs) {
    const int w = em.candidates()[c].num_params;
    out.emplace_back(R.middleCols(at, w));
    at += w;
  }
  return out;
}

}  // namespace

void ForEachColumnBatch(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                        const Fit& fit, const std::vector<int>& fixed, const std::vector<int>& cs,
                        bool residuals, const IdentifyOptions& opt,
                        const std::function<void(const ColumnBatch&)>& fn) {
  const Problem pr(em, data, loads, fit.active, fit.basis, opt);
  const Eigen::VectorXd x = StateOf(pr, fit);
  const int p = pr.num_params();
  const int base = p + (residuals ? 1 : 0) + NumTheta(em, fixed);
  ColumnBatch cb;
  cb.rows = pr.num_residuals();
  cb.compressed = pr.InRowBlocks();
  if (!cb.compressed) {
    // Few rows: the fit's columns once, the candidates' a batch at a time (each candidate's
    // are the same bits alone).
    cb.fit = pr.Jacobian(x);
    if (residuals) cb.r = pr.Residuals(x);
    cb.fixed = pr.CandidateColumns(x, fixed);
    for (const std::vector<int>& batch : Batches(em, cs, 0, cb.rows)) {
      cb.batch = pr.CandidateColumns(x, batch);
      fn(cb);
      cb.begin += batch.size();
    }
    return;
  }
  // A block's share of the residual entries (its last block up to two blocks' rows).
  const double entries =
      static_cast<double>(cb.rows) * 2.0 * opt.row_block / static_cast<double>(pr.num_rows());
  for (const std::vector<int>& batch : Batches(em, cs, base, entries)) {
    std::vector<int> all = fixed;
    all.insert(all.end(), batch.begin(), batch.end());
    const Eigen::MatrixXd R = StackedColumns(pr, [&](const Problem& block) {
      Eigen::MatrixXd C(block.num_residuals(), base + NumTheta(em, batch));
      C.leftCols(p) = block.Jacobian(x);
      if (residuals) C.col(p) = block.Residuals(x);
      int at = base - NumTheta(em, fixed);
      for (Eigen::MatrixXd& Jc : block.CandidateColumns(x, all)) {
        C.middleCols(at, Jc.cols()) = Jc;
        at += static_cast<int>(Jc.cols());
      }
      return C;
    });
    cb.fit = R.leftCols(p);
    if (residuals) cb.r = R.col(p);
    cb.fixed = Split(R, base - NumTheta(em, fixed), fixed, em);
    cb.batch = Split(R, base, batch, em);
    fn(cb);
    cb.begin += batch.size();
  }
}

Eigen::MatrixXd CandidateBasis(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                               const Fit& fit, int c, const IdentifyOptions& opt, double* rel) {
  Eigen::MatrixXd B;
  ForEachColumnBatch(em, data, loads, fit, {c}, {}, false, opt, [&](const ColumnBatch& cb) {
    B = ObservableBasis(cb.fixed[0], Projector(cb.fit), opt.rank_tol, rel);
  });
  return B;
}

Eigen::MatrixXd FitJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                            const Fit& fit, const IdentifyOptions& opt) {
  const Problem pr(em, data, loads, fit.active, fit.basis, opt);
  return pr.Jacobian(StateOf(pr, fit));
}

Eigen::VectorXd FitResiduals(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const Fit& fit, const IdentifyOptions& opt) {
  const Problem pr(em, data, loads, fit.active, fit.basis, opt);
  return pr.Residuals(StateOf(pr, fit));
}

Eigen::MatrixXd CandidateJacobian(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                                  const Fit& fit, int c, const IdentifyOptions& opt) {
  const Problem pr(em, data, loads, fit.active, fit.basis, opt);
  return pr.CandidateColumns(StateOf(pr, fit), c);
}

namespace {

// `fit` without its e-th effect, the others at their values (no refit).
Fit Remove(const EffectModel& em, const Fit& fit, size_t e, Eigen::VectorXd* theta_e) {
  Fit rest = fit;
  rest.active.clear();
  rest.basis.clear();
  std::vector<double> th;
  int off = 0;
  for (size_t k = 0; k < fit.active.size(); ++k) {
    const int np = em.candidates()[fit.active[k]].num_params;
    if (k != e) {
      rest.active.push_back(fit.active[k]);
      rest.basis.push_back(k < fit.basis.size() ? fit.basis[k] : Eigen::MatrixXd());
      for (int i = 0; i < np; ++i) th.push_back(fit.theta[off + i]);
    } else {
      *theta_e = fit.theta.segment(off, np);
    }
    off += np;
  }
  rest.theta = Eigen::Map<const Eigen::VectorXd>(th.data(), th.size());
  return rest;
}

// Minimum-norm parameters of R reproducing d, and the parameter directions R does not see.
EquivalentMember Member(const EffectModel& em, int c, const Eigen::MatrixXd& R,
                        const Eigen::VectorXd& d) {
  EquivalentMember m;
  m.candidate = c;
  m.name = em.candidates()[c].Name();
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(R, Eigen::ComputeThinU | Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  const double cut = s.size() ? 1e-3 * s[0] : 0.0;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(R.cols());
  for (int i = 0; i < s.size(); ++i) {
    if (s[i] > cut) x += svd.matrixV().col(i) * (svd.matrixU().col(i).dot(d) / s[i]);
  }
  m.value.assign(x.data(), x.data() + x.size());
  for (int i = 0; i < R.cols(); ++i) {
    if (i >= s.size() || s[i] <= cut) {
      const Eigen::VectorXd v = svd.matrixV().col(i);
      m.unobservable.emplace_back(v.data(), v.data() + v.size());
    }
  }
  return m;
}

// The candidates an equivalence set of chosen effect ce may name.
std::vector<int> Rivals(const EffectModel& em, const Fit& fit, int ce,
                        const std::vector<int>& candidates) {
  std::vector<int> cs;
  const bool generic = em.candidates()[ce].generic_geometry;
  for (int c : candidates) {
    if (c == ce || std::find(fit.active.begin(), fit.active.end(), c) != fit.active.end()) {
      continue;
    }
    // A full joint-origin recalibration can make any geometric correction at its joint;
    // naming it beside every geometric finding says nothing.
    if (em.candidates()[c].generic_geometry && !generic) continue;
    // A lateral compliance (chosen after the named effects) beside a named effect: where its
    // axis is the axis of the joint before it through the same point, it is that joint's
    // compliance by construction, not a competing cause.
    if (em.candidates()[c].after_named && !em.candidates()[ce].after_named) continue;
    // Likewise the wider families that need evidence (a stiffening spring contains the
    // linear one, the error curve the transmission error) beside a narrower chosen one.
    if (em.candidates()[c].needs_evidence &&
        (!em.candidates()[ce].needs_evidence ||
         em.candidates()[c].type == EffectType::kJointErrorCurve)) {
      continue;
    }
    cs.push_back(c);
  }
  return cs;
}

}  // namespace

void FindEquivalents(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                     const Fit& fit, const std::vector<int>& candidates, const IdentifyOptions& opt,
                     IdentifyResult* result) {
  for (size_t e = 0; e < fit.active.size(); ++e) {
    const int ce = fit.active[e];
    Eigen::VectorXd theta_e;
    const Fit rest = Remove(em, fit, e, &theta_e);
    EquivalenceSet set;
    set.effect = static_cast<int>(e);
    const std::vector<int> cs = Rivals(em, fit, ce, candidates);
    // The effect's correction with the rest projected out (every batch has it: in row blocks
    // each batch's R is a basis of its own), and the rivals' columns that reproduce it.
    ForEachColumnBatch(em, data, loads, rest, {ce}, cs, false, opt, [&](const ColumnBatch& cb) {
      const Projector proj(cb.fit);
      const Eigen::MatrixXd Re = proj.Apply(cb.fixed[0]);
      const Eigen::VectorXd d = Re * theta_e;
      if (set.members.empty()) {
        set.correction_rms = std::sqrt(d.squaredNorm() / std::max(1, cb.rows));
        set.members.push_back(Member(em, ce, Re, d));
      }
      if (!(d.norm() > 0)) return;
      for (size_t i = 0; i < cb.batch.size(); ++i) {
        const Eigen::MatrixXd Rc = proj.Apply(cb.batch[i]);
        if (!(Rc.norm() > 0)) continue;
        const Eigen::VectorXd pd = Rc * Rc.colPivHouseholderQr().solve(d);
        if (pd.norm() / d.norm() > opt.ambiguity_cos) {
          set.members.push_back(Member(em, cs[cb.begin + i], Rc, d));
        }
      }
    });
    std::string name;
    std::vector<std::string> names;
    for (const EquivalentMember& m : set.members) {
      name += (name.empty() ? "" : " | ") + m.name;
      names.push_back(m.name);
    }
    set.name = name;
    if (names.size() > 1) result->indistinguishable.push_back(names);
    result->equivalence.push_back(set);
  }
}

std::vector<SimplerEquivalent> SimplerEquivalents(const EffectModel& em, const DataSet& data,
                                                  const RowLoads& loads, const Fit& fit,
                                                  const IdentifyOptions& opt) {
  std::vector<SimplerEquivalent> out;
  const int k = static_cast<int>(fit.active.size());
  if (k < 2 || k > 10) return out;
  Fit groups_only = fit;
  groups_only.active.clear();
  groups_only.basis.clear();
  groups_only.theta.resize(0);
  std::vector<int> cs;
  for (size_t c = 0; c < em.candidates().size(); ++c) {
    const Candidate& cand = em.candidates()[c];
    if (cand.generic_geometry || cand.type == EffectType::kCameraOffset) continue;
    if (std::find(fit.active.begin(), fit.active.end(), static_cast<int>(c)) != fit.active.end()) {
      continue;
    }
    cs.push_back(static_cast<int>(c));
  }
  ForEachColumnBatch(em, data, loads, groups_only, fit.active, cs, false, opt,
                     [&](const ColumnBatch& cb) {
                       const Projector proj(cb.fit);
                       // Each chosen effect's correction (group points projected out).
                       std::vector<Eigen::VectorXd> d(k);
                       std::vector<int> np(k);
                       for (int e = 0, off = 0; e < k; ++e) {
                         np[e] = em.candidates()[fit.active[e]].num_params;
                         d[e] = proj.Apply(cb.fixed[e]) * fit.theta.segment(off, np[e]);
                         off += np[e];
                       }
                       for (size_t i = 0; i < cb.batch.size(); ++i) {
                         const int c = cs[cb.begin + i];
                         const Candidate& cand = em.candidates()[c];
                         const Eigen::MatrixXd Rc = proj.Apply(cb.batch[i]);
                         if (!(Rc.norm() > 0)) continue;
                         const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Rc);
                         for (int mask = 1; mask < (1 << k); ++mask) {
                           if (__builtin_popcount(mask) < 2) continue;
                           Eigen::VectorXd sum = Eigen::VectorXd::Zero(d[0].size());
                           int params = 0;
                           SimplerEquivalent se;
                           se.candidate = c;
                           for (int e = 0; e < k; ++e) {
                             if (!(mask & (1 << e))) continue;
                             sum += d[e];
                             params += np[e];
                             se.effects.push_back(e);
                           }
                           if (cand.num_params >= params || !(sum.norm() > 0)) continue;
                           const Eigen::VectorXd pd = Rc * qr.solve(sum);
                           if (pd.norm() / sum.norm() > opt.ambiguity_cos) out.push_back(se);
                         }
                       }
                     });
  return out;
}

void FindSimplerEquivalents(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                            const Fit& fit, const std::vector<int>& candidates,
                            const IdentifyOptions& opt, IdentifyResult* result) {
  for (const SimplerEquivalent& se : SimplerEquivalents(em, data, loads, fit, opt)) {
    const Candidate& cand = em.candidates()[se.candidate];
    std::string names;
    int params = 0;
    for (int e : se.effects) {
      names += (names.empty() ? "" : " + ") + em.candidates()[fit.active[e]].Name();
      params += em.candidates()[fit.active[e]].num_params;
    }
    const bool listed =
        std::find(candidates.begin(), candidates.end(), se.candidate) != candidates.end();
    const std::string line = names + " together make the same correction as " + cand.Name() + " (" +
                             std::to_string(cand.num_params) + " parameter(s) instead of " +
                             std::to_string(params) + (listed ? "" : "; not among the candidates") +
                             "): the cause is not singled out";
    result->simpler.push_back(line);
    result->steps.push_back(line);
    result->attribution_unique = false;
  }
}

void FindUnidentifiable(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                        const Fit& fit, const std::vector<int>& candidates,
                        const IdentifyOptions& opt, IdentifyResult* result) {
  std::vector<int> cs;
  for (int c : candidates) {
    if (std::find(fit.active.begin(), fit.active.end(), c) != fit.active.end()) continue;
    bool member = false;
    for (const EquivalenceSet& s : result->equivalence) {
      for (const EquivalentMember& m : s.members) member = member || m.candidate == c;
    }
    if (!member) cs.push_back(c);
  }
  std::unique_ptr<Projector> proj;
  ForEachColumnBatch(em, data, loads, fit, {}, cs, false, opt, [&](const ColumnBatch& cb) {
    if (!proj || cb.compressed) proj = std::make_unique<Projector>(cb.fit);
    for (size_t i = 0; i < cb.batch.size(); ++i) {
      const int c = cs[cb.begin + i];
      double rel = 0.0;
      const Eigen::MatrixXd B = ObservableBasis(cb.batch[i], *proj, opt.rank_tol, &rel);
      if (B.cols() > 0) continue;
      result->unidentifiable.push_back(em.candidates()[c].Name());
      char line[256];
      std::snprintf(line, sizeof(line),
                    "%s: unidentifiable (%.2g of its sensitivity lies outside the chosen effects "
                    "and group points)",
                    em.candidates()[c].Name().c_str(), rel);
      result->steps.push_back(line);
    }
  });
}

}  // namespace flexbench::identify
