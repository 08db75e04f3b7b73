#include "scenarios/identify/dynamic/select.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>

#include "estimators/format.h"
#include "scenarios/identify/parallel.h"

namespace flexbench::identify::dynamic {
namespace {

// A candidate whose neutral values change the model (a mode's joints released at the MJCF's
// stiffness): its screening starts from a rollout with it in.
bool NeutralChangesModel(sim::DynamicKind k) {
  return k == sim::DynamicKind::kLinkMode || k == sim::DynamicKind::kBaseMode;
}

void ZeroUnmasked(const std::vector<char>& mask, Eigen::MatrixXd* J, Eigen::VectorXd* r) {
  for (int k = 0; k < J->rows(); ++k) {
    if (!mask[k]) {
      J->row(k).setZero();
      (*r)[k] = 0.0;
    }
  }
}

// min |r + J d| over d with lo <= theta + d <= hi: an active-set loop (a coordinate the
// unconstrained step pushes past its bound is held there, the others solved again, until no
// free coordinate leaves its bounds).
double LinearRss(const Eigen::MatrixXd& J, const Eigen::VectorXd& r, const Eigen::VectorXd& theta,
                 const Eigen::VectorXd& lo, const Eigen::VectorXd& hi, Eigen::VectorXd* d_out) {
  const int n = static_cast<int>(theta.size());
  const Eigen::MatrixXd A = J.transpose() * J;
  const Eigen::VectorXd g = J.transpose() * r;
  Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
  std::vector<char> held(n, 0);
  for (int pass = 0; pass <= n; ++pass) {
    std::vector<int> free;
    for (int i = 0; i < n; ++i) {
      if (!held[i]) free.push_back(i);
    }
    const int m = static_cast<int>(free.size());
    Eigen::MatrixXd Af(m, m);
    Eigen::VectorXd gf(m);
    for (int a = 0; a < m; ++a) {
      gf[a] = g[free[a]];
      for (int i = 0; i < n; ++i) {
        if (held[i]) gf[a] += A(free[a], i) * d[i];
      }
      for (int b = 0; b < m; ++b) Af(a, b) = A(free[a], free[b]);
    }
    Af.diagonal() += 1e-9 * Af.diagonal().cwiseMax(1e-12);
    const Eigen::VectorXd df = m > 0 ? Eigen::VectorXd(-Af.ldlt().solve(gf)) : Eigen::VectorXd();
    bool changed = false;
    for (int a = 0; a < m; ++a) {
      const int i = free[a];
      d[i] = df[a];
      if (theta[i] + d[i] < lo[i] || theta[i] + d[i] > hi[i]) {
        d[i] = std::clamp(theta[i] + d[i], lo[i], hi[i]) - theta[i];
        held[i] = 1;
        changed = true;
      }
    }
    if (!changed) break;
  }
  if (d_out) *d_out = d;
  return (r + J * d).squaredNorm();
}

struct Screened {
  int candidate = -1;
  double bic = 0.0;
  double rss = 0.0;
  Eigen::VectorXd start;  // the stacked values to fit from
};

class Selection {
 public:
  Selection(const DynamicProblem& p, const DynamicIdentifyOptions& o, DynamicReport* rep)
      : p_(p), o_(o), rep_(rep), all_(p.Mask(-1)) {
    for (char m : all_) n_ += m;
  }

  double Bic(double rss, int k) const { return n_ * std::log(rss / n_) + k * std::log(n_); }

  // Screens every candidate beside `state`'s; `J_state`: the Jacobian at `state` when known.
  std::vector<Screened> Screen(const FitState& state, const Eigen::MatrixXd* J_state = nullptr) {
    const std::vector<int>& active = state.active;
    Eigen::MatrixXd Ja = J_state ? *J_state : p_.Jacobian(active, state.theta, state.prediction);
    Eigen::VectorXd ra = state.prediction.residual;
    ZeroUnmasked(all_, &Ja, &ra);
    const int nc = static_cast<int>(p_.candidates().size());
    std::vector<Screened> out(nc);
    ForEachTask(nc, p_.threads(), [&](int c) {
      out[c].candidate = c;
      out[c].bic = std::numeric_limits<double>::infinity();
      if (std::find(active.begin(), active.end(), c) != active.end()) return;
      std::vector<int> ext = active;
      ext.push_back(c);
      Eigen::VectorXd theta(state.theta.size() + p_.candidates()[c].num_values());
      theta << state.theta, p_.Neutral({c});
      Prediction base = state.prediction;
      if (NeutralChangesModel(p_.candidates()[c].kind)) {
        FitState s = p_.Evaluate(ext, theta, all_);
        if (!s.ok) return;
        base = std::move(s.prediction);
      }
      // Only c's own columns are new: the chosen ones' are the state's.
      Eigen::MatrixXd Jc = SingleColumns(ext, theta, base, static_cast<int>(state.theta.size()));
      Eigen::VectorXd r = base.residual;
      ZeroUnmasked(all_, &Jc, &r);
      Eigen::MatrixXd J(Ja.rows(), Ja.cols() + Jc.cols());
      J << Ja, Jc;
      Eigen::VectorXd d;
      const double rss = LinearRss(J, r, theta, p_.Lower(ext), p_.Upper(ext), &d);
      out[c].rss = rss;
      out[c].bic = Bic(std::max(rss, 1e-300), static_cast<int>(theta.size()));
      out[c].start = theta + d;
    });
    return out;
  }

  // The Jacobian columns from `from` on (a candidate's own), each a rollout.
  Eigen::MatrixXd SingleColumns(const std::vector<int>& ext, const Eigen::VectorXd& theta,
                                const Prediction& at, int from) const {
    return p_.Jacobian(ext, theta, at, from);
  }

  // The fit's values from the entries of every fold but `f`: a Gauss-Newton step from `fit`
  // (J its Jacobian).
  Eigen::VectorXd FoldValues(const FitState& fit, const Eigen::MatrixXd& J, int f) const {
    Eigen::MatrixXd Jt = J;
    Eigen::VectorXd r = fit.prediction.residual;
    ZeroUnmasked(p_.Mask(f), &Jt, &r);
    Eigen::VectorXd d;
    const Eigen::VectorXd lo = p_.Lower(fit.active), hi = p_.Upper(fit.active);
    LinearRss(Jt, r, fit.theta, lo, hi, &d);
    // Clamped again: theta + (bound - theta) can round to just outside the bound.
    return (fit.theta + d).cwiseMax(lo).cwiseMin(hi);
  }

  // Held-out normalised RMS: per fold a Gauss-Newton step from the fit on the other folds'
  // entries, then the held-out fold's rollout at it.
  // `J_out`: the fit's Jacobian, which this computes (a later Screen of the fit reuses it).
  double HeldOut(const FitState& fit, Eigen::MatrixXd* J_out = nullptr) {
    const auto& L = p_.layout();
    if (fit.theta.size() == 0) return std::sqrt(p_.Cost(fit.prediction.residual, all_) / n_);
    Eigen::MatrixXd J = p_.Jacobian(fit.active, fit.theta, fit.prediction);
    const int folds = p_.data().folds;
    std::vector<double> cost(folds, 0.0);
    ForEachTask(folds, p_.threads(), [&](int f) {
      const FitState at = p_.EvaluateFold(fit.active, FoldValues(fit, J, f), f);
      if (!at.ok) {
        cost[f] = std::numeric_limits<double>::infinity();  // the fold's fit does not hold
        return;
      }
      const Eigen::VectorXd& res = at.prediction.residual;
      for (int k = 0; k < L.size(); ++k) {
        if (all_[k] && p_.data().segments[L.segment[k]].fold == f) cost[f] += res[k] * res[k];
      }
    });
    double sum = 0.0;
    for (double c : cost) sum += c;
    if (J_out) *J_out = std::move(J);
    return std::sqrt(sum / n_);
  }

  const std::vector<char>& all() const { return all_; }
  double n() const { return n_; }

 private:
  const DynamicProblem& p_;
  const DynamicIdentifyOptions& o_;
  DynamicReport* rep_;
  std::vector<char> all_;
  double n_ = 0.0;
};

// Sandwich covariance with segments as clusters. `J`: the effects' Jacobian at `fit` with the
// starts projected out (DynamicProblem::WithoutStarts): the starts are free parameters of the
// fit too, their uncertainty the effects'.
Eigen::MatrixXd ClusterCovariance(const DynamicProblem& p, const FitState& fit,
                                  const std::vector<char>& mask, Eigen::MatrixXd J) {
  Eigen::VectorXd r = fit.prediction.residual;
  ZeroUnmasked(mask, &J, &r);
  const int n = static_cast<int>(fit.theta.size());
  const Eigen::MatrixXd A = J.transpose() * J;
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(n, n);
  const auto& L = p.layout();
  Eigen::VectorXd s = Eigen::VectorXd::Zero(n);
  int seg = -1;
  for (int k = 0; k <= L.size(); ++k) {
    if (k == L.size() || L.segment[k] != seg) {
      B += s * s.transpose();
      s.setZero();
      if (k == L.size()) break;
      seg = L.segment[k];
    }
    s += J.row(k).transpose() * r[k];
  }
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(A);
  if (!lu.isInvertible()) return Eigen::MatrixXd::Constant(n, n, std::nan(""));
  const Eigen::MatrixXd Ainv = lu.inverse();
  return Ainv * B * Ainv;
}

StreamError StreamStats(const DynamicProblem& p, const FitState& before, const FitState& after,
                        const std::vector<char>& mask, int stream) {
  static const char* kNames[kStreams] = {"encoders", "gyro", "accel", "tags"};
  static const char* kUnits[kStreams] = {"rad", "rad/s", "m/s^2", "px"};
  const MotionData& d = p.data();
  StreamError e;
  e.stream = kNames[stream];
  e.unit = kUnits[stream];
  e.noise = d.Noise(stream);
  e.noise_from_log = d.noise_from_log[stream];
  double b = 0.0, a = 0.0;
  const auto& L = p.layout();
  for (int k = 0; k < L.size(); ++k) {
    if (!mask[k] || L.stream[k] != stream) continue;
    ++e.entries;
    b += before.prediction.error[k] * before.prediction.error[k];
    a += after.prediction.error[k] * after.prediction.error[k];
  }
  if (e.entries > 0) {
    e.rms_before = std::sqrt(b / e.entries);
    e.rms_after = std::sqrt(a / e.entries);
  }
  return e;
}

}  // namespace

namespace {

// A fit of a set, its held-out error and its Jacobian (empty until HeldOut computed it).
struct Scored {
  FitState fit;
  double heldout = std::numeric_limits<double>::infinity();
  Eigen::MatrixXd J;
};

// The values of `active` without its i-th effect.
Eigen::VectorXd Without(const DynamicProblem& p, const FitState& f, int i) {
  const int off = p.Offset(f.active, i);
  const int nv = p.candidates()[f.active[i]].num_values();
  Eigen::VectorXd t(f.theta.size() - nv);
  t << f.theta.head(off), f.theta.tail(f.theta.size() - off - nv);
  return t;
}

std::vector<int> Erase(std::vector<int> v, int i) {
  v.erase(v.begin() + i);
  return v;
}

}  // namespace

bool Better(double heldout, double than, const DynamicIdentifyOptions& o) {
  return heldout < (1.0 - o.cv_min_gain) * than;
}

// Forward rounds per possible effect before selection gives up (an add-remove cycle).
constexpr int kMaxRounds = 4;

class Stages {
 public:
  Stages(const DynamicProblem& p, const DynamicIdentifyOptions& o, DynamicReport* rep)
      : p_(p), o_(o), rep_(rep), sel_(p, o, rep) {}

  Scored Score(const std::vector<int>& active, const Eigen::VectorXd& theta0) {
    Scored s;
    s.fit = p_.Fit(active, theta0, sel_.all(), o_.iterations);
    if (s.fit.ok) s.heldout = sel_.HeldOut(s.fit, &s.J);
    return s;
  }
  bool Better(double heldout, double than) const { return dynamic::Better(heldout, than, o_); }

  // Forward rounds, each followed by removal of effects no longer needed, until no candidate
  // lowers the held-out error or max_effects are chosen and one still would (rep.capped). The
  // round limit only guards against an add-remove cycle.
  Scored Forward(Scored state) {
    const auto& cands = p_.candidates();
    for (int n = 0; n < kMaxRounds * (o_.max_effects + 1); ++n) {
      const int round = ++rounds_;
      const bool known = state.fit.theta.size() > 0 && state.J.cols() == state.fit.theta.size();
      const std::vector<Screened> screened = sel_.Screen(state.fit, known ? &state.J : nullptr);
      const double bic_now = sel_.Bic(state.fit.cost, static_cast<int>(state.fit.theta.size()));
      std::vector<Screened> kept;
      for (const Screened& s : screened) {
        if (s.bic < bic_now - o_.bic_threshold) kept.push_back(s);
      }
      std::sort(kept.begin(), kept.end(),
                [](const Screened& a, const Screened& b) { return a.bic < b.bic; });
      if (kept.size() > static_cast<size_t>(o_.screen_keep)) kept.resize(o_.screen_keep);
      Scored best;
      for (const Screened& s : kept) {
        std::vector<int> ext = state.fit.active;
        ext.push_back(s.candidate);
        Scored t = Score(ext, s.start);
        Log("round " + std::to_string(round) + ": " + cands[s.candidate].Name() + " screened BIC " +
            ShortNum(s.bic - bic_now) + ", held-out " + ShortNum(t.heldout) + " (now " +
            ShortNum(state.heldout) + ")");
        if (t.heldout < best.heldout) best = std::move(t);
      }
      const bool more = !kept.empty() && Better(best.heldout, state.heldout);
      if (more && static_cast<int>(state.fit.active.size()) >= o_.max_effects) {
        // The cap, not the data, ends selection: said in the log, the summary and the verdict.
        const std::string would = cands[best.fit.active.back()].Name() +
                                  " would still lower the held-out error to " +
                                  ShortNum(best.heldout);
        rep_->capped = "selection stopped by max_effects = " + std::to_string(o_.max_effects) +
                       ": " + would + " (identify.max_effects to go on)";
        Log("round " + std::to_string(round) + ": max_effects = " + std::to_string(o_.max_effects) +
            " chosen; " + would);
        break;
      }
      if (!more) {
        Log("round " + std::to_string(round) + ": " +
            (kept.empty() ? "no candidate lowers BIC by " + ShortNum(o_.bic_threshold)
                          : "no candidate lowers the held-out error by " +
                                ShortNum(100 * o_.cv_min_gain) + " %") +
            "; selection ends");
        break;
      }
      Log("round " + std::to_string(round) + ": chose " + cands[best.fit.active.back()].Name());
      const int added = static_cast<int>(best.fit.active.size()) - 1;
      state = Remove(std::move(best), added);
    }
    return state;
  }

  // Drops each effect (but `keep`) whose removal costs less than cv_min_gain of held-out error.
  Scored Remove(Scored state, int keep) {
    for (int i = static_cast<int>(state.fit.active.size()) - 1; i >= 0; --i) {
      if (i == keep || state.fit.active.size() < 2) continue;
      Scored w = Score(Erase(state.fit.active, i), Without(p_, state.fit, i));
      if (w.fit.ok && !Better(state.heldout, w.heldout)) {
        Log("removed " + p_.candidates()[state.fit.active[i]].Name() + ": held-out " +
            ShortNum(w.heldout) + " without it (" + ShortNum(state.heldout) + " with)");
        if (keep > i) --keep;
        state = std::move(w);
      }
    }
    return state;
  }

  // Each chosen effect replaced by the candidates that best explain its share (linearised),
  // refitted; a swap is kept when it lowers the held-out error by cv_min_gain.
  Scored Swap(Scored state) {
    for (int pass = 0; pass < 3 * o_.max_effects; ++pass) {
      bool changed = false;
      for (size_t i = 0; i < state.fit.active.size(); ++i) {
        const std::vector<int> others = Erase(state.fit.active, static_cast<int>(i));
        const FitState wo =
            p_.Evaluate(others, Without(p_, state.fit, static_cast<int>(i)), sel_.all());
        if (!wo.ok) continue;
        std::vector<Screened> alt = sel_.Screen(wo);
        std::sort(alt.begin(), alt.end(),
                  [](const Screened& a, const Screened& b) { return a.bic < b.bic; });
        for (int k = 0; k < std::min<int>(o_.screen_keep, static_cast<int>(alt.size())); ++k) {
          if (alt[k].candidate == state.fit.active[i] || !std::isfinite(alt[k].bic)) continue;
          std::vector<int> ext = others;
          ext.push_back(alt[k].candidate);
          Scored t = Score(ext, alt[k].start);
          if (!Better(t.heldout, state.heldout)) continue;
          Log("swapped " + p_.candidates()[state.fit.active[i]].Name() + " for " +
              p_.candidates()[alt[k].candidate].Name() + ": held-out " + ShortNum(t.heldout) +
              " (" + ShortNum(state.heldout) + " before)");
          const int added = static_cast<int>(ext.size()) - 1;
          state = Remove(std::move(t), added);
          changed = true;
          break;
        }
        if (changed) break;
      }
      if (!changed) break;
    }
    return state;
  }

  // Candidates that, in place of chosen effect i, explain all but `equivalence` of its share:
  // each fitted alone beside the others (linearised from the fit without i).
  std::vector<std::string> Equivalent(const FitState& state, int i) {
    const std::vector<int> others = Erase(state.active, i);
    const FitState wo = p_.Evaluate(others, Without(p_, state, i), sel_.all());
    std::vector<std::string> out;
    if (!wo.ok) return out;
    const double share = wo.cost - state.cost;
    for (const Screened& s : sel_.Screen(wo)) {
      if (s.candidate == state.active[i] || !std::isfinite(s.bic)) continue;
      if (s.rss - state.cost <= o_.equivalence * share) {
        out.push_back(p_.candidates()[s.candidate].Name());
      }
    }
    return out;
  }

  void Log(const std::string& line) { rep_->log.push_back(line); }
  Selection& selection() { return sel_; }

 private:
  const DynamicProblem& p_;
  const DynamicIdentifyOptions& o_;
  DynamicReport* rep_;
  Selection sel_;
  int rounds_ = 0;  // forward rounds so far (the log numbers them)
};

// The warm start's effects among the candidates, fitted: the starting set when they lower the
// held-out error by cv_min_gain (then each that does not earn its place leaves), else `start`.
Scored WarmStart(const DynamicProblem& p, const DynamicIdentifyOptions& o,
                 const std::vector<sim::StaticCounterpart>& warm, Stages& stages, Scored start,
                 DynamicReport* rep) {
  std::vector<int> active;
  std::vector<double> theta;
  std::string names;
  for (const sim::StaticCounterpart& w : warm) {
    const std::string name = std::string(w.dynamic.row->name) + "@" + w.dynamic.location;
    const auto& c = p.candidates();
    const auto it =
        std::find_if(c.begin(), c.end(), [&](const Candidate& x) { return x.Name() == name; });
    if (it == c.end()) continue;
    active.push_back(static_cast<int>(it - c.begin()));
    for (int k = 0; k < w.dynamic.row->num_values; ++k) theta.push_back(w.dynamic.values[k]);
    names += (names.empty() ? "" : ", ") + w.static_effect + " -> " + name;
  }
  if (active.empty()) return start;
  Scored s = stages.Score(active, Eigen::Map<const Eigen::VectorXd>(theta.data(), theta.size()));
  const bool kept = s.fit.ok && Better(s.heldout, start.heldout, o);
  rep->log.push_back("warm start from the declared file's static effects (" + names +
                     "): held-out " + ShortNum(s.heldout) + " (declared " +
                     ShortNum(start.heldout) + "); " + (kept ? "kept" : "not kept"));
  return kept ? stages.Remove(std::move(s), -1) : start;
}

DynamicReport IdentifyDynamics(DynamicProblem& p, const DynamicIdentifyOptions& o,
                               const std::vector<sim::StaticCounterpart>& warm) {
  DynamicReport rep;
  const MotionData& d = p.data();
  rep.segments = static_cast<int>(d.segments.size());
  rep.folds = d.folds;
  rep.diverged_declared = p.declared().num_diverged;
  rep.first_divergence = p.declared().first_divergence;
  Stages stages(p, o, &rep);
  Selection& sel = stages.selection();
  Scored start;
  start.fit = p.Evaluate({}, Eigen::VectorXd(), sel.all());
  start.heldout = sel.HeldOut(start.fit);
  rep.heldout_before = start.heldout;
  Scored state = stages.Swap(stages.Forward(WarmStart(p, o, warm, stages, start, &rep)));
  if (!rep.capped.empty()) {
    // The swaps may have made room (a stand-in and what it stood for became one effect): the
    // rounds go on from the swapped set, and say again whether the cap ends them.
    rep.capped.clear();
    state = stages.Forward(std::move(state));
  }
  rep.heldout_after = state.heldout;
  // The starts are the fit's nuisance whatever it chose: the effects are refitted with them, and
  // the residual the verdict reads is taken from there, with effects or without.
  if (o.joint_iterations > 0) {
    const double before = state.fit.cost;
    state.fit = p.JointFit(state.fit, sel.all(), o.joint_iterations);
    state.J.resize(0, 0);  // of the fit before
    rep.log.push_back("effects and segment start speeds fitted jointly: cost " + ShortNum(before) +
                      " -> " + ShortNum(state.fit.cost));
  }
  const FitState& fit = state.fit;
  // "Before" from the same starts as the fit: the refined speeds are not the effects' credit.
  rep.declared_state = p.Evaluate({}, Eigen::VectorXd(), sel.all());
  const Eigen::MatrixXd J_free =
      fit.theta.size() > 0
          ? p.WithoutStarts(p.Jacobian(fit.active, fit.theta, fit.prediction), p.StartJacobian(fit))
          : Eigen::MatrixXd();
  const Eigen::MatrixXd cov =
      fit.theta.size() > 0 ? ClusterCovariance(p, fit, sel.all(), J_free) : Eigen::MatrixXd();
  // The last fold, for a replay of the log's end that the values it gets never saw.
  const int last = d.folds - 1;
  for (const Segment& s : d.segments) {
    if (s.fold != last) continue;
    if (rep.heldout_to_s <= rep.heldout_from_s) rep.heldout_from_s = d.t[s.row_begin];
    rep.heldout_to_s = d.t[s.row_end - 1];
  }
  const Eigen::VectorXd last_values =
      fit.theta.size() > 0 ? sel.FoldValues(fit, J_free, last) : Eigen::VectorXd();
  for (size_t i = 0; i < fit.active.size(); ++i) {
    ChosenEffect ce;
    const Candidate& c = p.candidates()[fit.active[i]];
    const sim::DynamicRow& row = sim::Row(c.kind);
    ce.name = c.Name();
    const int off = p.Offset(fit.active, static_cast<int>(i));
    for (int k = 0; k < row.num_values; ++k) {
      ce.value_names.push_back(row.value_names[k]);
      ce.values.push_back(fit.theta[off + k]);
      ce.heldout_values.push_back(last_values[off + k]);
      // NaN when the data cannot fix the value (a singular fit), never a false zero.
      const double var = cov(off + k, off + k);
      ce.std_errors.push_back(var >= 0.0 ? std::sqrt(var) : std::nan(""));
    }
    ce.equivalent = stages.Equivalent(fit, static_cast<int>(i));
    for (const sim::StaticCounterpart& w : warm) {
      if (std::string(w.dynamic.row->name) + "@" + w.dynamic.location == ce.name) {
        rep.replaced_static.push_back(w.static_effect);
      }
    }
    rep.chosen.push_back(std::move(ce));
  }
  for (int s = 0; s < kStreams; ++s) {
    StreamError e = StreamStats(p, rep.declared_state, fit, sel.all(), s);
    if (e.entries > 0) rep.streams.push_back(e);
  }
  rep.diagnostics = Diagnose(p, fit.prediction);
  for (const MotionFinding& f : rep.diagnostics.findings) rep.log.push_back("left: " + f.text);
  const bool helped = !rep.chosen.empty() && Better(rep.heldout_after, rep.heldout_before, o);
  if (helped && rep.heldout_after > o.explained_heldout) {
    std::string where;
    for (size_t k = 0; k < rep.diagnostics.levels.size() && k < 3; ++k) {
      where += (k ? ", " : "") + rep.diagnostics.levels[k].channel + " " +
               ShortNum(rep.diagnostics.levels[k].rms);
    }
    rep.log.push_back("left: the held-out residual is " + ShortNum(rep.heldout_after) +
                      " times the readings' noise (explained needs at most " +
                      ShortNum(o.explained_heldout) + "); largest in " + where);
  }
  if (!rep.capped.empty()) rep.log.push_back("left: " + rep.capped);
  const bool fits = rep.diagnostics.findings.empty() && rep.capped.empty() &&
                    rep.heldout_after <= o.explained_heldout;
  rep.verdict = helped                       ? (fits ? "explained" : "partly_explained")
                : rep.chosen.empty() && fits ? "no_effect"  // the declared model holds the log
                                             : "unexplained";
  rep.rollouts = p.rollouts();
  rep.final_state = std::move(state.fit);
  return rep;
}

}  // namespace flexbench::identify::dynamic
