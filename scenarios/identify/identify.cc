#include "scenarios/identify/identify.h"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "estimators/error.h"
#include "estimators/lie/so3.h"

namespace flexbench::identify {
namespace {

int NumTheta(const EffectModel& em, const std::vector<int>& active) {
  int n = 0;
  for (int i : active) n += em.candidates()[i].num_params;
  return n;
}

int RowDim(const Observation& o) {
  switch (o.type) {
    case ObservationType::kPose:
      return 6;
    case ObservationType::kPixel:
      return 2;
    default:
      return 3;
  }
}

// The camera with the active camera_offset (if any) applied.
lie::SE3 CameraPose(const EffectModel& em, const DataSet& data, const std::vector<int>& active,
                    const double* theta) {
  lie::SE3 T = data.camera.T_base_cam;
  for (int i : active) {
    const Candidate& c = em.candidates()[i];
    if (c.type == EffectType::kCameraOffset) {
      Vec6 xi;
      for (int k = 0; k < 6; ++k) xi[k] = theta[k];
      T = T * lie::SE3::Exp(xi);
    }
    theta += c.num_params;
  }
  return T;
}

// Pixel of a base-frame point; far off when behind the camera, so a fit never goes there.
Eigen::Vector2d Project(const CameraModel& cam, const lie::SE3& T_base_cam, const Vec3& p_base) {
  const Vec3 p = T_base_cam.rotation().transpose() * (p_base - T_base_cam.translation());
  const double z = std::max(p.z(), 1e-6);
  return Eigen::Vector2d(cam.fx * p.x() / z + cam.cx, cam.fy * p.y() / z + cam.cy);
}

// Whitened residuals of the full parameter vector x = [theta; group points]. Rows contribute 3
// (point, group), 6 (pose: position, then rotation) or 2 (pixel) entries, then one per distance.
class Problem {
 public:
  Problem(const EffectModel& em_, const DataSet& data_, const std::vector<ConfigLoads>& loads_,
          const std::vector<int>& active_, const IdentifyOptions& opt_, int num_theta_)
      : em(em_), data(data_), loads(loads_), active(active_), opt(opt_), num_theta(num_theta_) {
    offset_.reserve(data.rows.size());
    int o = 0;
    for (const Observation& r : data.rows) {
      offset_.push_back(o);
      o += RowDim(r);
    }
    rows_dim_ = o;
  }

  const EffectModel& em;
  const DataSet& data;
  const std::vector<ConfigLoads>& loads;
  const std::vector<int>& active;
  const IdentifyOptions& opt;
  int num_theta;

  int num_params() const { return num_theta + 3 * static_cast<int>(data.groups.size()); }
  int num_residuals() const { return rows_dim_ + static_cast<int>(data.distances.size()); }

  void Poses(const Eigen::VectorXd& x, std::vector<lie::SE3>* T) const {
    EffectModel::Workspace ws = em.MakeWorkspace();
    T->resize(data.rows.size());
    for (size_t r = 0; r < data.rows.size(); ++r) {
      (*T)[r] = em.PredictPose(data.rows[r].q, loads[r], active, x.data(), ws);
    }
  }

  Vec3 GroupPoint(const Eigen::VectorXd& x, int g) const { return x.segment<3>(num_theta + 3 * g); }

  Eigen::VectorXd Residuals(const Eigen::VectorXd& x, const std::vector<lie::SE3>& T) const {
    Eigen::VectorXd r(num_residuals());
    const lie::SE3 T_base_cam =
        data.camera.present ? CameraPose(em, data, active, x.data()) : lie::SE3();
    for (size_t i = 0; i < data.rows.size(); ++i) {
      const Observation& o = data.rows[i];
      const int k = offset_[i];
      const Vec3 p = T[i].translation();
      switch (o.type) {
        case ObservationType::kGroup:
          r.segment<3>(k) = (p - GroupPoint(x, o.group)) / opt.point_std_m;
          break;
        case ObservationType::kPoint:
          r.segment<3>(k) = (p - o.p_base) / opt.point_std_m;
          break;
        case ObservationType::kPose:
          r.segment<3>(k) = (p - o.p_base) / opt.point_std_m;
          r.segment<3>(k + 3) =
              lie::SO3Log(o.R_base.transpose() * T[i].rotation()) / opt.rotation_std_rad;
          break;
        case ObservationType::kPixel:
          r.segment<2>(k) = (Project(data.camera, T_base_cam, p) - o.uv) / opt.pixel_std_px;
          break;
      }
    }
    for (size_t k = 0; k < data.distances.size(); ++k) {
      const GroupDistance& d = data.distances[k];
      r[rows_dim_ + k] =
          ((GroupPoint(x, d.a) - GroupPoint(x, d.b)).norm() - d.distance_m) / opt.distance_std_m;
    }
    return r;
  }

  // Central differences of the row residuals in theta (columns `first` .. `first + count`).
  void ThetaColumns(const Eigen::VectorXd& x, int first, int count, double step,
                    Eigen::Ref<Eigen::MatrixXd> out) const {
    std::vector<lie::SE3> Tp, Tm;
    for (int k = 0; k < count; ++k) {
      Eigen::VectorXd xp = x, xm = x;
      xp[first + k] += step;
      xm[first + k] -= step;
      Poses(xp, &Tp);
      Poses(xm, &Tm);
      out.col(k) = (Residuals(xp, Tp) - Residuals(xm, Tm)) / (2.0 * step);
    }
  }

  // Central differences for theta, exact columns for the group points.
  Eigen::MatrixXd Jacobian(const Eigen::VectorXd& x) const {
    const int nr = num_residuals();
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(nr, num_params());
    int col = 0;
    for (int i : active) {
      const Candidate& c = em.candidates()[i];
      ThetaColumns(x, col, c.num_params, c.step, J.middleCols(col, c.num_params));
      col += c.num_params;
    }
    for (size_t r = 0; r < data.rows.size(); ++r) {
      const int g = data.rows[r].group;
      if (data.rows[r].type == ObservationType::kGroup) {
        J.block<3, 3>(offset_[r], num_theta + 3 * g) = -Mat3::Identity() / opt.point_std_m;
      }
    }
    for (size_t k = 0; k < data.distances.size(); ++k) {
      const GroupDistance& d = data.distances[k];
      const Vec3 diff = GroupPoint(x, d.a) - GroupPoint(x, d.b);
      const double len = diff.norm();
      if (len < 1e-12) continue;
      const Eigen::RowVector3d u = diff.transpose() / (len * opt.distance_std_m);
      const int row = rows_dim_ + static_cast<int>(k);
      J.block<1, 3>(row, num_theta + 3 * d.a) += u;
      J.block<1, 3>(row, num_theta + 3 * d.b) -= u;
    }
    return J;
  }

 private:
  std::vector<int> offset_;
  int rows_dim_ = 0;
};

std::string Num(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.4g", v);
  return b;
}

double Bic(double rss, int n, int k) {
  return n * std::log(std::max(rss, 1e-300) / n) + k * std::log(static_cast<double>(n));
}

// How well the candidate with fewer parameters lies in the span of the other's (projected)
// sensitivities: the smallest, over its columns, of |projection| / |column|. 1: every direction
// of one is a direction of the other, so the data cannot tell them apart.
double SameSpan(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  const Eigen::MatrixXd& small = a.cols() <= b.cols() ? a : b;
  const Eigen::MatrixXd& big = a.cols() <= b.cols() ? b : a;
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(big);
  double worst = 1.0;
  for (int i = 0; i < small.cols(); ++i) {
    const double n = small.col(i).norm();
    if (!(n > 0)) return 0.0;
    const Eigen::VectorXd proj = big * qr.solve(small.col(i));
    worst = std::min(worst, proj.norm() / n);
  }
  return worst;
}

// Refit of `cur` with its e-th effect removed (the others start from their values).
Fit FitWithout(const EffectModel& em, const DataSet& data, const std::vector<ConfigLoads>& loads,
               const Fit& cur, size_t e, const IdentifyOptions& opt);

// Whitened Jacobian of the fit's own parameters (theta and group points) at its state.
Eigen::MatrixXd FitJacobian(const EffectModel& em, const DataSet& data,
                            const std::vector<ConfigLoads>& loads, const Fit& fit,
                            const IdentifyOptions& opt) {
  const int nt = static_cast<int>(fit.theta.size());
  Eigen::VectorXd x(nt + 3 * static_cast<int>(data.groups.size()));
  x.head(nt) = fit.theta;
  for (size_t g = 0; g < fit.group_points.size(); ++g)
    x.segment<3>(nt + 3 * g) = fit.group_points[g];
  const Problem pr(em, data, loads, fit.active, opt, nt);
  return pr.Jacobian(x);
}

// Sensitivity of candidate c's parameters at the fit's state (central differences, whitened),
// with the columns of the fit itself (`qr` of its Jacobian) projected out.
Eigen::MatrixXd ProjectedColumns(const EffectModel& em, const DataSet& data,
                                 const std::vector<ConfigLoads>& loads, const Fit& fit, int c,
                                 const Eigen::MatrixXd& J_fit,
                                 const Eigen::ColPivHouseholderQR<Eigen::MatrixXd>& qr,
                                 const IdentifyOptions& opt, double* relative_norm) {
  std::vector<int> act = fit.active;
  act.push_back(c);
  const int nt_old = static_cast<int>(fit.theta.size());
  const Candidate& cand = em.candidates()[c];
  const int np = cand.num_params;
  Eigen::VectorXd theta = Eigen::VectorXd::Zero(nt_old + np);
  theta.head(nt_old) = fit.theta;
  Eigen::VectorXd x(nt_old + np + 3 * static_cast<int>(data.groups.size()));
  x.head(nt_old + np) = theta;
  for (size_t g = 0; g < fit.group_points.size(); ++g) {
    x.segment<3>(nt_old + np + 3 * g) = fit.group_points[g];
  }
  const Problem pr(em, data, loads, act, opt, nt_old + np);
  Eigen::MatrixXd Jc = Eigen::MatrixXd::Zero(J_fit.rows(), np);
  pr.ThetaColumns(x, nt_old, np, cand.step, Jc);
  Eigen::MatrixXd R = Jc;
  if (J_fit.cols() > 0) R = Jc - J_fit * qr.solve(Jc);
  double rel = std::numeric_limits<double>::infinity();
  for (int k = 0; k < np; ++k) {
    const double n0 = Jc.col(k).norm();
    rel = std::min(rel, n0 > 0 ? R.col(k).norm() / n0 : 0.0);
  }
  *relative_norm = rel;
  return R;
}

}  // namespace

std::vector<ConfigLoads> ComputeLoads(const EffectModel& em, const DataSet& data) {
  std::vector<ConfigLoads> loads;
  loads.reserve(data.rows.size());
  for (const Observation& o : data.rows) {
    loads.push_back(em.Loads(o.q));
    loads.back().motion_sign = o.motion_sign;
  }
  return loads;
}

std::vector<Vec3> PredictAll(const EffectModel& em, const DataSet& data,
                             const std::vector<ConfigLoads>& loads, const std::vector<int>& active,
                             const Eigen::VectorXd& theta) {
  std::vector<Vec3> p(data.rows.size());
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (size_t r = 0; r < data.rows.size(); ++r) {
    p[r] = em.Predict(data.rows[r].q, loads[r], active, theta.data(), ws);
  }
  return p;
}

Fit FitEffects(const EffectModel& em, const DataSet& data, const std::vector<ConfigLoads>& loads,
               const std::vector<int>& active, const Eigen::VectorXd& init,
               const IdentifyOptions& opt) {
  const int nt = NumTheta(em, active);
  const Problem pr(em, data, loads, active, opt, nt);
  const int G = static_cast<int>(data.groups.size());
  Eigen::VectorXd x = Eigen::VectorXd::Zero(pr.num_params());
  x.head(std::min<int>(nt, static_cast<int>(init.size()))) =
      init.head(std::min<int>(nt, static_cast<int>(init.size())));
  std::vector<lie::SE3> p;
  pr.Poses(x, &p);
  {
    // Group points start at their rows' mean.
    std::vector<Vec3> points(p.size());
    for (size_t r = 0; r < p.size(); ++r) points[r] = p[r].translation();
    const std::vector<Vec3> mean = GroupMeans(data, points);
    for (int g = 0; g < G; ++g) x.segment<3>(nt + 3 * g) = mean[g];
  }
  Eigen::VectorXd r = pr.Residuals(x, p);
  double rss = r.squaredNorm();
  double lambda = 1e-3;
  for (int it = 0; it < opt.max_iterations; ++it) {
    const Eigen::MatrixXd J = pr.Jacobian(x);
    const Eigen::MatrixXd A = J.transpose() * J;
    const Eigen::VectorXd g = J.transpose() * r;
    bool improved = false;
    for (int tries = 0; tries < 12; ++tries) {
      Eigen::MatrixXd Ad = A;
      for (int k = 0; k < A.rows(); ++k) Ad(k, k) += lambda * std::max(A(k, k), 1e-12);
      const Eigen::VectorXd dx = -Ad.ldlt().solve(g);
      if (!dx.allFinite()) {
        lambda *= 10;
        continue;
      }
      const Eigen::VectorXd xn = x + dx;
      std::vector<lie::SE3> pn;
      pr.Poses(xn, &pn);
      const Eigen::VectorXd rn = pr.Residuals(xn, pn);
      const double rss_n = rn.squaredNorm();
      if (std::isfinite(rss_n) && rss_n < rss) {
        const double gain = rss - rss_n;
        x = xn;
        r = rn;
        rss = rss_n;
        lambda = std::max(lambda / 3.0, 1e-12);
        improved = gain > 1e-12 * rss;
        break;
      }
      lambda *= 4.0;
    }
    if (!improved) break;
  }
  Fit f;
  f.active = active;
  f.theta = x.head(nt);
  f.group_points.resize(G);
  for (int g = 0; g < G; ++g) f.group_points[g] = x.segment<3>(nt + 3 * g);
  f.rss = rss;
  f.num_residuals = pr.num_residuals();
  f.bic = Bic(rss, f.num_residuals, pr.num_params());
  return f;
}

IdentifyResult Identify(const EffectModel& em, const DataSet& data,
                        const std::vector<ConfigLoads>& loads, const std::vector<int>& candidates,
                        const IdentifyOptions& opt) {
  IdentifyResult res;
  res.before = FitEffects(em, data, loads, {}, Eigen::VectorXd(), opt);
  Fit cur = res.before;
  std::vector<int> pool = candidates;
  char line[512];
  std::map<int, std::string> alias;  // a kept correction of indistinguishable candidates
  std::map<int, std::vector<int>> twins_of;
  int rounds = 0;
  while (static_cast<int>(cur.active.size()) < opt.max_effects && !pool.empty() &&
         rounds++ < 3 * opt.max_effects) {
    struct Trial {
      int c;
      Fit fit;
      Eigen::MatrixXd proj;
    };
    std::vector<Trial> trials;
    std::vector<int> keep;
    const Eigen::MatrixXd J_cur = FitJacobian(em, data, loads, cur, opt);
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr_cur;
    if (J_cur.cols() > 0) qr_cur.compute(J_cur);  // no effect and no group point yet: nothing
    // Trials are screened with a few iterations; the winner is refit to convergence.
    IdentifyOptions screen = opt;
    screen.max_iterations = 4;
    for (int c : pool) {
      double rel = 0.0;
      Eigen::MatrixXd proj = ProjectedColumns(em, data, loads, cur, c, J_cur, qr_cur, opt, &rel);
      keep.push_back(c);
      // Not fitted while its sensitivity lies in the span of the chosen effects and the group
      // points; it stays in the pool (a payload becomes visible once a compliance is chosen).
      if (!(rel > opt.rank_tol)) continue;
      std::vector<int> act = cur.active;
      act.push_back(c);
      Eigen::VectorXd init = Eigen::VectorXd::Zero(NumTheta(em, act));
      init.head(cur.theta.size()) = cur.theta;
      trials.push_back({c, FitEffects(em, data, loads, act, init, screen), proj});
    }
    pool = keep;
    if (trials.empty()) break;
    std::sort(trials.begin(), trials.end(),
              [](const Trial& a, const Trial& b) { return a.fit.bic < b.fit.bic; });
    trials[0].fit = FitEffects(em, data, loads, trials[0].fit.active, trials[0].fit.theta, opt);
    // Candidates the data cannot tell apart from the best one.
    std::vector<int> twins;
    for (size_t k = 1; k < trials.size(); ++k) {
      if (trials[k].fit.bic - trials[0].fit.bic >= opt.ambiguity_bic) break;
      if (SameSpan(trials[0].proj, trials[k].proj) > opt.ambiguity_cos) {
        twins.push_back(trials[k].c);
      }
    }
    const double dbic = trials[0].fit.bic - cur.bic;
    if (dbic > -opt.bic_threshold) {
      std::snprintf(line, sizeof(line), "stop: best next %s changes BIC by %.1f (> -%.0f)",
                    em.candidates()[trials[0].c].Name().c_str(), dbic, opt.bic_threshold);
      res.steps.push_back(line);
      break;
    }
    if (!twins.empty()) {
      // The data cannot say which of these it is; their corrections are the same. The
      // correction is kept (it is what the data supports) under all their names, and none of
      // them is named as the cause.
      std::vector<std::string> names{em.candidates()[trials[0].c].Name()};
      for (int t : twins) names.push_back(em.candidates()[t].Name());
      res.indistinguishable.push_back(names);
      std::string joined;
      for (const auto& n : names) joined += (joined.empty() ? "" : " | ") + n;
      alias[trials[0].c] = joined;
      twins_of[trials[0].c] = twins;
      std::snprintf(line, sizeof(line),
                    "indistinguishable (|cos| > %.3g, BIC within %.0f), kept as one correction "
                    "without a cause: %s: BIC %.1f -> %.1f",
                    opt.ambiguity_cos, opt.ambiguity_bic, joined.c_str(), cur.bic,
                    trials[0].fit.bic);
      res.steps.push_back(line);
      pool.erase(std::remove_if(pool.begin(), pool.end(),
                                [&](int c) {
                                  return std::find(twins.begin(), twins.end(), c) != twins.end();
                                }),
                 pool.end());
    } else {
      std::snprintf(line, sizeof(line), "add %s: BIC %.1f -> %.1f, RSS %.4g -> %.4g",
                    em.candidates()[trials[0].c].Name().c_str(), cur.bic, trials[0].fit.bic,
                    cur.rss, trials[0].fit.rss);
      res.steps.push_back(line);
    }
    cur = trials[0].fit;
    pool.erase(std::find(pool.begin(), pool.end(), trials[0].c));
    // Backward step: an earlier effect that the new one made redundant (no longer lowering BIC
    // by the threshold) goes back to the pool.
    while (cur.active.size() > 1) {
      size_t worst = 0;
      Fit best_without;
      double best_bic = std::numeric_limits<double>::infinity();
      for (size_t e = 0; e + 1 < cur.active.size(); ++e) {
        Fit w = FitWithout(em, data, loads, cur, e, opt);
        if (w.bic < best_bic) best_bic = w.bic, best_without = w, worst = e;
      }
      if (!std::isfinite(best_bic) || best_bic - cur.bic >= opt.bic_threshold) break;
      std::snprintf(line, sizeof(line), "drop %s: BIC %.1f -> %.1f without it",
                    em.candidates()[cur.active[worst]].Name().c_str(), cur.bic, best_bic);
      res.steps.push_back(line);
      const int dropped = cur.active[worst];
      pool.push_back(dropped);
      // Its indistinguishable twins were set aside with it; they return with it.
      for (int t : twins_of[dropped]) pool.push_back(t);
      twins_of.erase(dropped);
      alias.erase(dropped);
      cur = best_without;
    }
  }
  // Swap step: a chosen effect with several parameters that a simpler candidate replaces at a
  // lower BIC is swapped (e.g. an offset of the wrist's link that is really one joint offset).
  for (bool swapped = true; swapped;) {
    swapped = false;
    for (size_t e = 0; e < cur.active.size() && !swapped; ++e) {
      const int np = em.candidates()[cur.active[e]].num_params;
      if (np < 2) continue;
      const Fit without = FitWithout(em, data, loads, cur, e, opt);
      Fit best = cur;
      int best_c = -1;
      for (int c : pool) {
        if (em.candidates()[c].num_params >= np) continue;
        std::vector<int> act = without.active;
        act.push_back(c);
        Eigen::VectorXd init = Eigen::VectorXd::Zero(NumTheta(em, act));
        init.head(without.theta.size()) = without.theta;
        IdentifyOptions screen = opt;
        screen.max_iterations = 4;
        Fit f = FitEffects(em, data, loads, act, init, screen);
        if (f.bic < best.bic) best = f, best_c = c;
      }
      if (best_c < 0) continue;
      best = FitEffects(em, data, loads, best.active, best.theta, opt);
      if (best.bic >= cur.bic) continue;
      std::snprintf(line, sizeof(line), "swap %s for %s: BIC %.1f -> %.1f",
                    em.candidates()[cur.active[e]].Name().c_str(),
                    em.candidates()[best_c].Name().c_str(), cur.bic, best.bic);
      res.steps.push_back(line);
      pool.erase(std::find(pool.begin(), pool.end(), best_c));
      pool.push_back(cur.active[e]);
      cur = best;
      swapped = true;
    }
  }
  // Equivalents: a candidate left in the pool whose sensitivity, with the rest of the chosen
  // set projected out, is parallel to a chosen effect's explains the data as well; the data
  // cannot tell them apart, so the chosen correction is named by both.
  for (size_t e = 0; e < cur.active.size(); ++e) {
    const int ce = cur.active[e];
    if (em.candidates()[ce].num_params != 1) continue;
    Fit rest = cur;
    rest.active.clear();
    std::vector<double> th;
    int off = 0;
    for (size_t k = 0; k < cur.active.size(); ++k) {
      const int np = em.candidates()[cur.active[k]].num_params;
      if (k != e) {
        rest.active.push_back(cur.active[k]);
        for (int i = 0; i < np; ++i) th.push_back(cur.theta[off + i]);
      }
      off += np;
    }
    rest.theta = Eigen::Map<const Eigen::VectorXd>(th.data(), th.size());
    const Eigen::MatrixXd J_rest = FitJacobian(em, data, loads, rest, opt);
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr_rest;
    if (J_rest.cols() > 0) qr_rest.compute(J_rest);
    double rel = 0.0;
    const Eigen::MatrixXd a =
        ProjectedColumns(em, data, loads, rest, ce, J_rest, qr_rest, opt, &rel);
    std::vector<std::string> names;
    for (int c : pool) {
      if (em.candidates()[c].num_params != 1) continue;
      const Eigen::MatrixXd b =
          ProjectedColumns(em, data, loads, rest, c, J_rest, qr_rest, opt, &rel);
      const double den = a.col(0).norm() * b.col(0).norm();
      if (den > 0 && std::abs(a.col(0).dot(b.col(0))) / den > opt.ambiguity_cos) {
        names.push_back(em.candidates()[c].Name());
      }
    }
    if (names.empty()) continue;
    std::string joined = alias.count(ce) ? alias.at(ce) : em.candidates()[ce].Name();
    std::vector<std::string> group{joined};
    for (const auto& n : names) joined += " | " + n, group.push_back(n);
    alias[ce] = joined;
    res.indistinguishable.push_back(group);
    res.steps.push_back("indistinguishable from a chosen effect (|cos| > " +
                        Num(opt.ambiguity_cos) + "), named by all: " + joined);
  }
  res.after = cur;
  // Whatever is still in the pool and has no sensitivity of its own at the end is reported.
  const Eigen::MatrixXd J_end = FitJacobian(em, data, loads, cur, opt);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr_end;
  if (J_end.cols() > 0) qr_end.compute(J_end);
  for (int c : pool) {
    double rel = 0.0;
    ProjectedColumns(em, data, loads, cur, c, J_end, qr_end, opt, &rel);
    if (rel > opt.rank_tol) continue;
    res.unidentifiable.push_back(em.candidates()[c].Name());
    std::snprintf(line, sizeof(line),
                  "%s: unidentifiable (%.2g of its sensitivity lies outside the chosen effects "
                  "and group points)",
                  em.candidates()[c].Name().c_str(), rel);
    res.steps.push_back(line);
  }

  // Identifiability of the final fit: covariance, correlations, condition number.
  const int nt = static_cast<int>(cur.theta.size());
  if (nt > 0) {
    Eigen::VectorXd x(nt + 3 * static_cast<int>(data.groups.size()));
    x.head(nt) = cur.theta;
    for (size_t g = 0; g < cur.group_points.size(); ++g) {
      x.segment<3>(nt + 3 * g) = cur.group_points[g];
    }
    const Problem pr(em, data, loads, cur.active, opt, nt);
    const Eigen::MatrixXd J = pr.Jacobian(x);
    const int dof = std::max(1, pr.num_residuals() - pr.num_params());
    const double s2 = cur.rss / dof;
    const Eigen::MatrixXd cov =
        s2 * (J.transpose() * J).ldlt().solve(Eigen::MatrixXd::Identity(J.cols(), J.cols()));
    res.theta_cov = cov.topLeftCorner(nt, nt);
    const Eigen::VectorXd sd = res.theta_cov.diagonal().cwiseMax(0).cwiseSqrt();
    res.theta_corr = res.theta_cov;
    for (int i = 0; i < nt; ++i) {
      for (int j = 0; j < nt; ++j) {
        res.theta_corr(i, j) = sd[i] * sd[j] > 0 ? res.theta_cov(i, j) / (sd[i] * sd[j]) : 0.0;
      }
    }
    Eigen::MatrixXd Jn = J;
    for (int k = 0; k < Jn.cols(); ++k) {
      const double n = Jn.col(k).norm();
      if (n > 0) Jn.col(k) /= n;
    }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Jn);
    const Eigen::VectorXd s = svd.singularValues();
    res.condition_number =
        s[s.size() - 1] > 0 ? s[0] / s[s.size() - 1] : std::numeric_limits<double>::infinity();
    // Shares: the sum of squares each effect removes when it alone is dropped and the rest refit.
    std::vector<double> gain;
    double total = 0.0;
    int off = 0;
    for (size_t e = 0; e < cur.active.size(); ++e) {
      const int c = cur.active[e];
      const int np = em.candidates()[c].num_params;
      const Fit without = FitWithout(em, data, loads, cur, e, opt);
      gain.push_back(std::max(0.0, without.rss - cur.rss));
      total += gain.back();
      FittedEffect fe;
      fe.candidate = c;
      fe.name = alias.count(c) ? alias.at(c) : em.candidates()[c].Name();
      for (int k = 0; k < np; ++k) {
        fe.value.push_back(cur.theta[off + k]);
        fe.std.push_back(sd[off + k]);
      }
      off += np;
      res.effects.push_back(fe);
    }
    for (size_t e = 0; e < res.effects.size(); ++e) {
      res.effects[e].share = total > 0 ? gain[e] / total : 0.0;
    }
  }
  return res;
}

std::vector<Eigen::Vector2d> PredictPixels(const EffectModel& em, const DataSet& data,
                                           const std::vector<ConfigLoads>& loads,
                                           const std::vector<int>& active,
                                           const Eigen::VectorXd& theta) {
  std::vector<Eigen::Vector2d> uv(data.rows.size(), Eigen::Vector2d::Zero());
  if (!data.camera.present) return uv;
  const lie::SE3 T_base_cam = CameraPose(em, data, active, theta.data());
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (data.rows[r].type != ObservationType::kPixel) continue;
    uv[r] = Project(data.camera, T_base_cam,
                    em.Predict(data.rows[r].q, loads[r], active, theta.data(), ws));
  }
  return uv;
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
                              const std::vector<Eigen::Vector2d>& pixels) {
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
      default:
        e[r] = (points[r] - o.p_base).norm();
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
    if (data.rows[r].type == ObservationType::kPixel) continue;
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

double PixelError(const DataSet& data, const std::vector<double>& row_errors) {
  double sum = 0.0;
  int n = 0;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (data.rows[r].type != ObservationType::kPixel) continue;
    sum += row_errors[r];
    ++n;
  }
  return n > 0 ? sum / n : 0.0;
}

}  // namespace flexbench::identify

namespace flexbench::identify {
namespace {

Fit FitWithout(const EffectModel& em, const DataSet& data, const std::vector<ConfigLoads>& loads,
               const Fit& cur, size_t e, const IdentifyOptions& opt) {
  std::vector<int> rest;
  std::vector<double> init;
  int off = 0;
  for (size_t k = 0; k < cur.active.size(); ++k) {
    const int np = em.candidates()[cur.active[k]].num_params;
    if (k != e) {
      rest.push_back(cur.active[k]);
      for (int i = 0; i < np; ++i) init.push_back(cur.theta[off + i]);
    }
    off += np;
  }
  return FitEffects(em, data, loads, rest,
                    Eigen::Map<const Eigen::VectorXd>(init.data(), init.size()), opt);
}

}  // namespace
}  // namespace flexbench::identify
