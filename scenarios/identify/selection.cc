#include "scenarios/identify/selection.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <limits>
#include <memory>

#include "scenarios/identify/equivalence.h"
#include "scenarios/identify/parallel.h"
#include "scenarios/identify/problem.h"

namespace flexbench::identify {
namespace {

bool Contains(const std::vector<int>& v, int x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

// Whether `cv` improves on `cv_cur` by the required share (always, without cross-validation).
bool CvLower(const IdentifyOptions& opt, double cv, double cv_cur) {
  if (!opt.cross_validation) return true;
  return cv < cv_cur * (1.0 - opt.cv_min_gain);
}

struct Trial {
  int c;
  Fit fit;
};

// `key` with index i appended.
std::string KeyWith(const std::string& key, int i) {
  std::string out = key;
  out.append(reinterpret_cast<const char*>(&i), sizeof(i));
  return out;
}

// The kept screens of candidates `screened` as trials, best BIC first.
std::vector<Trial> SortedTrials(const std::vector<int>& screened,
                                std::vector<SelectionMemo::Screen>* screens) {
  std::vector<Trial> trials;
  for (size_t i = 0; i < screened.size(); ++i) {
    if ((*screens)[i].kept) trials.push_back({screened[i], std::move((*screens)[i].fit)});
  }
  std::stable_sort(trials.begin(), trials.end(), [](const Trial& a, const Trial& b) {
    if (a.fit.bic != b.fit.bic) return a.fit.bic < b.fit.bic;
    return a.fit.num_params < b.fit.num_params;
  });
  return trials;
}

// Screened fits of every pool candidate beside `cur`, best BIC first. Each candidate's screen
// on its own, side by side, those the memo has taken from there.
std::vector<Trial> ScreenCandidates(const SelectionContext& ctx, const Fit& cur,
                                    const std::vector<int>& pool) {
  std::vector<int> screened;
  for (int c : pool) {
    if (!Contains(cur.active, c)) screened.push_back(c);
  }
  const int n = static_cast<int>(screened.size());
  const std::string key = ctx.memo ? SelectionMemo::Key(cur) : std::string();
  std::vector<SelectionMemo::Screen> screens(n);
  std::vector<int> todo;  // indices into screened
  for (int i = 0; i < n; ++i) {
    if (!ctx.memo || !ctx.memo->screens.Find(KeyWith(key, screened[i]), &screens[i])) {
      todo.push_back(i);
    }
  }
  if (todo.empty()) return SortedTrials(screened, &screens);
  std::vector<int> cs;
  for (int i : todo) cs.push_back(screened[i]);
  // The fit's columns and residuals beside the candidates', a batch at a time; in row blocks
  // their triangular factor, whose products the screening step needs and no more.
  std::unique_ptr<Projector> proj;
  ForEachColumnBatch(
      ctx.em, ctx.data, ctx.loads, cur, {}, cs, true, ctx.opt, [&](const ColumnBatch& cb) {
        if (!proj || cb.compressed) proj = std::make_unique<Projector>(cb.fit);
        const int n_batch = static_cast<int>(cb.batch.size());
        const int threads =
            TaskThreads(n_batch, static_cast<int>(ctx.data.rows.size()), ctx.opt.threads);
        IdentifyOptions screen = TaskOptions(ctx.opt, threads);
        screen.max_iterations = 4;
        ForEachTask(n_batch, threads, [&](int j) {
          const int c = cs[cb.begin + j];
          SelectionMemo::Screen& out = screens[todo[cb.begin + j]];
          double rel = 0.0;
          const Eigen::MatrixXd B = ObservableBasis(cb.batch[j], *proj, ctx.opt.rank_tol, &rel);
          // Never more unknowns than residuals.
          if (B.cols() > 0 && cur.num_params + B.cols() < cur.num_residuals) {
            out.fit = ScreenWith(ctx.em, ctx.data, ctx.loads, cur, c, B, cb.fit, cb.batch[j], cb.r,
                                 screen);
            out.kept = std::isfinite(out.fit.bic);
          }
          if (ctx.memo) ctx.memo->screens.Put(KeyWith(key, c), out, SelectionMemo::Bytes(out.fit));
        });
      });
  return SortedTrials(screened, &screens);
}

// A screened trial refitted in full, the earlier effects it pushes past their bounds dropped
// (with the log lines that say so), its own bound violations and its held-out error.
using Refit = SelectionMemo::Refit;
Refit RefitTrial(const SelectionContext& ctx, const Trial& t) {
  Refit r;
  const std::string key = ctx.memo ? KeyWith(SelectionMemo::Key(t.fit), t.c) : std::string();
  if (ctx.memo && ctx.memo->refits.Find(key, &r)) return r;
  r.fit = FitEffects(ctx.em, ctx.data, ctx.loads, t.fit.active, t.fit.basis, t.fit.theta, ctx.opt);
  const std::string name = ctx.em.candidates()[t.c].Name();
  // An earlier effect pushed past its bound by the new one is made redundant by it: it
  // leaves (the backward step's job, done here so the bound never sees it).
  for (size_t e = 0; e + 1 < r.fit.active.size();) {
    Fit one = r.fit;
    one.active = {r.fit.active[e]};
    int off = 0;
    for (size_t k = 0; k < e; ++k) off += ctx.em.candidates()[r.fit.active[k]].num_params;
    one.theta = r.fit.theta.segment(off, ctx.em.candidates()[r.fit.active[e]].num_params);
    if (BoundViolations(ctx.em, one).empty()) {
      ++e;
      continue;
    }
    r.log.push_back("with " + name + ", " + ctx.em.candidates()[r.fit.active[e]].Name() +
                    " leaves (pushed outside its physical bounds)");
    r.fit = FitWithout(ctx.em, ctx.data, ctx.loads, r.fit, e, ctx.opt);
    e = 0;
  }
  r.out = BoundViolations(ctx.em, r.fit);
  if (r.out.empty()) r.cv = CvError(ctx, r.fit);
  if (ctx.memo) {
    size_t bytes = SelectionMemo::Bytes(r.fit);
    for (const std::string& line : r.log) bytes += sizeof(line) + line.size();
    for (const std::string& line : r.out) bytes += sizeof(line) + line.size();
    ctx.memo->refits.Put(key, r, bytes);
  }
  return r;
}

// The best of the screened trials that passes BIC, bounds and held-out error; -1 when none.
// The trials BIC lets through are refitted side by side, then judged in BIC order.
int PickTrial(const SelectionContext& ctx, const Fit& cur, double cv_cur,
              std::vector<Trial>* trials, double* cv_best) {
  int best = -1;
  *cv_best = std::numeric_limits<double>::infinity();
  std::vector<size_t> tried;
  for (size_t k = 0; k < trials->size() && static_cast<int>(tried.size()) < ctx.opt.cv_trials;
       ++k) {
    if ((*trials)[k].fit.bic - cur.bic > -ctx.opt.bic_threshold) break;
    tried.push_back(k);
  }
  const int threads = TaskThreads(static_cast<int>(tried.size()),
                                  static_cast<int>(ctx.data.rows.size()), ctx.opt.threads);
  const IdentifyOptions task_opt = TaskOptions(ctx.opt, threads);
  const SelectionContext task_ctx = TaskContext(ctx, task_opt, ctx.log);
  std::vector<Refit> refits(tried.size());
  ForEachTask(static_cast<int>(tried.size()), threads,
              [&](int i) { refits[i] = RefitTrial(task_ctx, (*trials)[tried[i]]); });
  for (size_t i = 0; i < tried.size(); ++i) {
    const size_t k = tried[i];
    Trial& t = (*trials)[k];
    Refit& r = refits[i];
    t.fit = std::move(r.fit);
    ctx.log->insert(ctx.log->end(), r.log.begin(), r.log.end());
    const std::string name = ctx.em.candidates()[t.c].Name();
    if (!r.out.empty()) {
      ctx.log->push_back("reject " + name + ": outside its physical bounds (" + r.out[0] + ")");
      continue;
    }
    const double cv = r.cv;
    if (!CvLower(ctx.opt, cv, cv_cur)) {
      ctx.log->push_back(
          Fmt("not kept %s: BIC %.1f -> %.1f but held-out error %.4g -> %.4g "
              "sigma^2",
              name.c_str(), cur.bic, t.fit.bic, cv_cur, cv));
      continue;
    }
    if (best < 0 || (ctx.opt.cross_validation && cv < *cv_best)) {
      best = static_cast<int>(k);
      *cv_best = cv;
    }
  }
  return best;
}

// Whether removing each of `cur`'s effects but the last could pass BIC's test: the sum of
// squares rises by its linearised rise (RemovalRises) or by as little as half of it, which
// leaves room for the model's curvature. Those that could are refitted.
std::vector<char> MayDrop(const SelectionContext& ctx, const Fit& cur) {
  const Problem pr(ctx.em, ctx.data, ctx.loads, cur.active, cur.basis, ctx.opt);
  const std::vector<double> rises = RemovalRises(pr, cur);
  std::vector<char> may(cur.active.size() - 1, 1);
  for (size_t e = 0; e < may.size(); ++e) {
    if (!std::isfinite(rises[e])) continue;
    const int m = static_cast<int>(pr.basis(e).cols());
    may[e] = Bic(cur.rss + 0.5 * rises[e], cur.num_residuals, cur.num_params - m) - cur.bic <
             ctx.opt.bic_threshold;
  }
  return may;
}

// Drops earlier effects (all but the last) that neither BIC nor the held-out error needs.
Fit BackwardStep(const SelectionContext& ctx, Fit cur, double* cv_cur) {
  while (cur.active.size() > 1) {
    size_t worst = 0;
    Fit best_without;
    double best_bic = std::numeric_limits<double>::infinity();
    // Each removal that may pass refitted on its own, side by side; the first lowest BIC wins.
    const std::vector<char> may = MayDrop(ctx, cur);
    std::vector<int> tried;
    for (size_t e = 0; e < may.size(); ++e) {
      if (may[e]) tried.push_back(static_cast<int>(e));
    }
    if (tried.empty()) break;
    const int n = static_cast<int>(tried.size());
    const int threads = TaskThreads(n, static_cast<int>(ctx.data.rows.size()), ctx.opt.threads);
    const IdentifyOptions task_opt = TaskOptions(ctx.opt, threads);
    std::vector<Fit> without(n);
    const std::string key = ctx.memo ? SelectionMemo::Key(cur) : std::string();
    ForEachTask(n, threads, [&](int i) {
      const int e = tried[i];
      if (ctx.memo && ctx.memo->withouts.Find(KeyWith(key, e), &without[i])) return;
      without[i] = FitWithout(ctx.em, ctx.data, ctx.loads, cur, e, task_opt);
      if (ctx.memo) {
        ctx.memo->withouts.Put(KeyWith(key, e), without[i], SelectionMemo::Bytes(without[i]));
      }
    });
    for (int i = 0; i < n; ++i) {
      if (without[i].bic < best_bic) {
        best_bic = without[i].bic, best_without = std::move(without[i]), worst = tried[i];
      }
    }
    if (!std::isfinite(best_bic) || best_bic - cur.bic >= ctx.opt.bic_threshold) break;
    const double cv = CvError(ctx, best_without);
    if (ctx.opt.cross_validation && cv > *cv_cur * (1.0 + ctx.opt.cv_min_gain)) break;
    ctx.log->push_back(Fmt("drop %s: BIC %.1f -> %.1f without it",
                           ctx.em.candidates()[cur.active[worst]].Name().c_str(), cur.bic,
                           best_bic));
    cur = std::move(best_without);
    *cv_cur = cv;
  }
  return cur;
}

// Swaps a chosen effect for a pool candidate that the data clearly prefers.
Fit SwapStep(const SelectionContext& ctx, Fit cur, const std::vector<int>& pool, double* cv_cur) {
  for (bool swapped = true; swapped;) {
    swapped = false;
    for (size_t e = 0; e < cur.active.size() && !swapped; ++e) {
      const Fit without = FitWithout(ctx.em, ctx.data, ctx.loads, cur, e, ctx.opt);
      std::vector<int> others;
      for (int c : pool) {
        if (c != cur.active[e]) others.push_back(c);
      }
      std::vector<Trial> trials = ScreenCandidates(ctx, without, others);
      if (trials.empty() || trials[0].fit.bic >= cur.bic - ctx.opt.ambiguity_bic) continue;
      Fit best = FitEffects(ctx.em, ctx.data, ctx.loads, trials[0].fit.active, trials[0].fit.basis,
                            trials[0].fit.theta, ctx.opt);
      if (best.bic >= cur.bic - ctx.opt.ambiguity_bic) continue;
      if (!BoundViolations(ctx.em, best).empty()) continue;
      const double cv = CvError(ctx, best);
      if (ctx.opt.cross_validation && cv > *cv_cur) continue;
      ctx.log->push_back(Fmt("swap %s for %s: BIC %.1f -> %.1f",
                             ctx.em.candidates()[cur.active[e]].Name().c_str(),
                             ctx.em.candidates()[trials[0].c].Name().c_str(), cur.bic, best.bic));
      cur = std::move(best);
      *cv_cur = cv;
      swapped = true;
    }
  }
  return cur;
}

}  // namespace

std::vector<std::string> BoundViolations(const EffectModel& em, const Fit& fit) {
  std::vector<std::string> out;
  int off = 0;
  for (int c : fit.active) {
    const Candidate& cand = em.candidates()[c];
    for (int k = 0; k < cand.num_params; ++k) {
      const double v = fit.theta[off + k];
      const double lo = k < static_cast<int>(cand.lower.size()) ? cand.lower[k] : -HUGE_VAL;
      const double hi = k < static_cast<int>(cand.upper.size()) ? cand.upper[k] : HUGE_VAL;
      if (!(v >= lo && v <= hi)) {
        out.push_back(Fmt("%s[%d] = %.4g outside [%.4g, %.4g] %s", cand.Name().c_str(), k, v, lo,
                          hi, cand.unit.c_str()));
      }
    }
    off += cand.num_params;
  }
  return out;
}

SelectionContext TaskContext(const SelectionContext& ctx, const IdentifyOptions& opt,
                             std::vector<std::string>* log) {
  return SelectionContext{ctx.em, ctx.data, ctx.loads, ctx.folds, opt, log, nullptr, ctx.memo};
}

double CvError(const SelectionContext& ctx, const Fit& fit) {
  if (!ctx.opt.cross_validation) return std::nan("");
  const std::string key = ctx.memo ? SelectionMemo::Key(fit) : std::string();
  double cv = 0.0;
  if (ctx.memo && ctx.memo->held_out.Find(key, &cv)) return cv;
  cv = CrossValidate(ctx.em, ctx.data, ctx.loads, ctx.folds, fit, ctx.opt);
  if (ctx.memo) ctx.memo->held_out.Put(key, cv, sizeof(cv));
  return cv;
}

size_t SelectionMemo::Bytes(const Fit& fit) {
  size_t doubles = fit.theta.size() + 3 * fit.group_points.size() + 12 * fit.T_base_frames.size() +
                   3 * fit.marker_offsets.size();
  for (const Eigen::MatrixXd& B : fit.basis) doubles += B.size();
  return sizeof(Fit) + sizeof(double) * doubles + sizeof(int) * fit.active.size() +
         sizeof(Eigen::MatrixXd) * fit.basis.size();
}

std::string SelectionMemo::Key(const Fit& fit) {
  std::string k;
  const auto add = [&k](const void* p, size_t bytes) {
    k.append(static_cast<const char*>(p), bytes);
  };
  const auto add_int = [&add](long v) { add(&v, sizeof(v)); };
  add_int(static_cast<long>(fit.active.size()));
  add(fit.active.data(), sizeof(int) * fit.active.size());
  add_int(static_cast<long>(fit.basis.size()));
  for (const Eigen::MatrixXd& B : fit.basis) {
    add_int(B.rows());
    add_int(B.cols());
    add(B.data(), sizeof(double) * B.size());
  }
  add_int(fit.theta.size());
  add(fit.theta.data(), sizeof(double) * fit.theta.size());
  add_int(static_cast<long>(fit.group_points.size()));
  for (const Vec3& p : fit.group_points) add(p.data(), sizeof(double) * 3);
  add_int(static_cast<long>(fit.T_base_frames.size()));
  for (const lie::SE3& T : fit.T_base_frames) {
    add(T.rotation().data(), sizeof(double) * 9);
    add(T.translation().data(), sizeof(double) * 3);
  }
  add_int(static_cast<long>(fit.marker_offsets.size()));
  for (const Vec3& d : fit.marker_offsets) add(d.data(), sizeof(double) * 3);
  return k;
}

Fit AddGeometryBlock(const SelectionContext& ctx, const Fit& start, const std::vector<int>& pool,
                     double* cv) {
  if (!ctx.opt.cross_validation) return start;
  Fit block = start;
  int added = 0;
  for (int c : pool) {
    if (Contains(block.active, c)) continue;
    double rel = 0.0;
    const Eigen::MatrixXd B = CandidateBasis(ctx.em, ctx.data, ctx.loads, block, c, ctx.opt, &rel);
    if (B.cols() == 0 || block.num_params + B.cols() >= block.num_residuals) continue;
    block.active.push_back(c);
    block.basis.push_back(B);
    block.theta.conservativeResize(block.theta.size() + ctx.em.candidates()[c].num_params);
    block.theta.tail(ctx.em.candidates()[c].num_params).setZero();
    block.num_params += static_cast<int>(B.cols());
    ++added;
  }
  if (added == 0) return start;
  Fit fit =
      FitEffects(ctx.em, ctx.data, ctx.loads, block.active, block.basis, block.theta, ctx.opt);
  const std::vector<std::string> out = BoundViolations(ctx.em, fit);
  const double cv_block = CvError(ctx, fit);
  if (!out.empty() || !CvLower(ctx.opt, cv_block, *cv)) {
    ctx.log->push_back(
        Fmt("geometry block of %d joint origins (%d directions) not kept: "
            "held-out %.4g -> %.4g sigma^2%s",
            added, fit.num_params - start.num_params, *cv, cv_block,
            out.empty() ? "" : ", outside bounds"));
    return start;
  }
  ctx.log->push_back(
      Fmt("add geometry block of %d joint origins (%d directions): BIC %.1f -> "
          "%.1f, held-out %.4g -> %.4g sigma^2",
          added, fit.num_params - start.num_params, start.bic, fit.bic, *cv, cv_block));
  *cv = cv_block;
  return fit;
}

std::string HeldOutChange(const SelectionContext& ctx, double from, double to) {
  return ctx.opt.cross_validation ? Fmt(", held-out %.4g -> %.4g sigma^2", from, to) : "";
}

bool OutOfTime(const SelectionContext& ctx, const char* stops) {
  if (ctx.opt.time_budget_s <= 0.0 || !ctx.out_of_time) return false;
  const double used =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - ctx.started).count();
  if (used < ctx.opt.time_budget_s) return false;
  if (!*ctx.out_of_time) {
    ctx.log->push_back(
        Fmt("stop: time budget %.4g s used up after %.1f s, %s: the budget, not "
            "the data, ends the selection",
            ctx.opt.time_budget_s, used, stops));
  }
  *ctx.out_of_time = true;
  return true;
}

Fit SelectEffects(const SelectionContext& ctx, const Fit& start, const std::vector<int>& pool,
                  bool backward, double* cv, bool swap) {
  Fit cur = start;
  const int cap = ctx.opt.max_effects;
  // Each round adds one effect; backward steps may take some out again.
  const int rounds = 3 * (cap >= 0 ? cap : static_cast<int>(pool.size() + start.active.size()));
  for (int round = 0; round < rounds; ++round) {
    if (OutOfTime(ctx, "no further effect is screened")) return cur;
    std::vector<Trial> trials = ScreenCandidates(ctx, cur, pool);
    if (trials.empty()) break;
    double cv_best = 0.0;
    const int k = PickTrial(ctx, cur, *cv, &trials, &cv_best);
    if (k >= 0 && cap >= 0 && static_cast<int>(cur.active.size()) >= cap) {
      ctx.log->push_back(
          Fmt("stop: max_effects %d reached, but %s would still be added "
              "(BIC %.1f -> %.1f%s): the cap, not the data, ends the selection",
              cap, ctx.em.candidates()[trials[k].c].Name().c_str(), cur.bic, trials[k].fit.bic,
              HeldOutChange(ctx, *cv, cv_best).c_str()));
      if (ctx.capped) *ctx.capped = true;
      break;
    }
    if (k < 0) {
      ctx.log->push_back(Fmt("stop: best next %s changes BIC by %.1f%s",
                             ctx.em.candidates()[trials[0].c].Name().c_str(),
                             trials[0].fit.bic - cur.bic,
                             ctx.opt.cross_validation ? "; none lowers the held-out error" : ""));
      break;
    }
    const Trial& t = trials[k];
    ctx.log->push_back(Fmt("add %s: BIC %.1f -> %.1f, RSS %.4g -> %.4g%s",
                           ctx.em.candidates()[t.c].Name().c_str(), cur.bic, t.fit.bic, cur.rss,
                           t.fit.rss, HeldOutChange(ctx, *cv, cv_best).c_str()));
    cur = t.fit;
    *cv = cv_best;
    if (backward) cur = BackwardStep(ctx, std::move(cur), cv);
    if (ctx.flush) (*ctx.flush)();
  }
  if (backward && swap) cur = SwapStep(ctx, std::move(cur), pool, cv);
  return cur;
}

}  // namespace flexbench::identify
