#include "scenarios/identify/run.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>
#include <tuple>

#include "estimators/error.h"
#include "estimators/format.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/identify/row_noise.h"

namespace flexbench::identify {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

void Say(const std::function<void(const std::string&)>& f, const std::string& line) {
  if (f) f(line);
}

// Rows far off under the declared model are listed and left out (identify.h FindOutliers).
void RejectOutliers(const Job& job, const std::string& where, const std::string& what, DataSet* d,
                    RowLoads* loads, std::vector<std::string>* rejected) {
  const std::vector<int> out = FindOutliers(*job.em, *d, *loads, job.opt);
  if (out.empty()) return;
  if (out.size() >= d->rows.size()) {
    throw InputError(where + ": every " + what + " row was rejected as an outlier");
  }
  for (int r : out) {
    rejected->push_back(d->rows[r].where.empty() ? what + " row " + std::to_string(r)
                                                 : d->rows[r].where);
  }
  Say(job.log, what + ": " + std::to_string(out.size()) + " row(s) rejected as outliers, first " +
                   rejected->back());
  *d = WithoutRows(*d, out);
  std::vector<int> kept;
  size_t k = 0;
  for (size_t r = 0; r < loads->size(); ++r) {
    if (k < out.size() && out[k] == static_cast<int>(r)) {
      ++k;
      continue;
    }
    kept.push_back(static_cast<int>(r));
  }
  *loads = loads->Subset(*d, kept);
}

// Cross-validation by set needs every set to hold more than one row.
void CheckSets(const Job& job, const DataSet& d) {
  if (!job.opt.cross_validation || d.sets.size() < 2) return;
  std::vector<int> count(d.sets.size(), 0);
  for (const auto& r : d.rows) ++count[r.set];
  for (size_t s = 0; s < count.size(); ++s) {
    if (count[s] == 1) {
      throw InputError(job.cal_where + ": set '" + d.sets[s] +
                       "' has one row; cross-validation by set needs two or more (or "
                       "cross_validation: false)");
    }
  }
}

// The loads, the frames' starting poses and the outliers: the rows as identified. Every
// declared measurement frame is used by calibration rows; those without a guess start at a
// registration of their points (measurement_frames.h); validation rows share the
// calibration's frames.
void Prepare(const Job& job, Report* r) {
  r->cal_loads = ComputeLoads(*job.em, r->cal);
  r->val_loads = ComputeLoads(*job.em, r->val);
  if (!r->cal.frames.empty()) {
    CheckFramesUsed(r->cal, "calibration");
    RegisterFrames(*job.em, r->cal_loads, &r->cal);
    r->val.frames = r->cal.frames;
  }
  RejectOutliers(job, job.cal_where, "calibration", &r->cal, &r->cal_loads, &r->rejected);
  RejectOutliers(job, job.val_where, "validation", &r->val, &r->val_loads, &r->rejected);
  CheckSets(job, r->cal);
}

// Row errors of d before or after the fit, and the marker predictions.
std::pair<std::vector<double>, std::vector<Vec3>> Errors(const Job& job, const DataSet& d,
                                                         const RowLoads& L,
                                                         const IdentifyResult& res, bool after) {
  const std::vector<int> act = after ? res.after.active : std::vector<int>{};
  const Eigen::VectorXd th = after ? res.after.theta : Eigen::VectorXd();
  // Rows in a measurement frame against it at the fit's pose (the same distance as in it).
  const DataSet db = InBase(d, after ? res.after.T_base_frames : res.before.T_base_frames);
  const auto p = PredictMarkers(*job.em, db, L, after ? res.after : res.before);
  const auto pix = PredictPixels(*job.em, db, L, act, th);
  const auto ups = PredictUps(*job.em, db, L, act, th);
  return std::make_pair(RowErrors(db, p, pix, ups), p);
}

// The errors before and after; the sets then in the base frame at the fit's frame poses, and
// (with the readings' noise stated) the fitted parameters' covariance from it.
void Score(const Job& job, const NoiseModel& nm, Report* r) {
  IdentifyResult& res = r->result;
  // The augmented model predicts with the loads where its joint corrections put the arm.
  r->cal_loads_after = ComputeLoads(*job.em, r->cal, res.after.active, res.after.theta);
  r->val_loads_after = ComputeLoads(*job.em, r->val, res.after.active, res.after.theta);
  std::tie(r->cal_before, r->cal_p0) = Errors(job, r->cal, r->cal_loads, res, false);
  std::tie(r->cal_after, r->cal_p1) = Errors(job, r->cal, r->cal_loads_after, res, true);
  std::tie(r->val_before, r->val_p0) = Errors(job, r->val, r->val_loads, res, false);
  std::tie(r->val_after, r->val_p1) = Errors(job, r->val, r->val_loads_after, res, true);
  r->cal = InBase(r->cal, res.after.T_base_frames);
  r->val = InBase(r->val, res.after.T_base_frames);
  // In the base frame: a point row's residual is against its measured point.
  if (job.reading_std_rad > 0.0) {
    r->rss_over_reading_noise = UseReadingNoiseCovariance(nm, r->cal, r->cal_loads_after, &res);
    if (std::isfinite(r->rss_over_reading_noise)) {
      Say(job.log, "fitted parameters' covariance from the readings' noise; calibration residual " +
                       ShortNum(r->rss_over_reading_noise) + "x what that noise explains");
    }
  }
}

// The validation error in the data's main unit: metres (consistency), px or degrees.
double JudgedError(const DataSet& d, const std::vector<double>& e) {
  const RowUnit u = MainUnit(d);
  if (u == RowUnit::kMetres) return ConsistencyError(d, e);
  return MeanRowError(d, e, u) / (u == RowUnit::kRadians ? kDeg : 1.0);
}

void Judge(const Job& job, Report* r) {
  const IdentifyResult& res = r->result;
  for (const EffectModel::Skipped& sk : job.em->skipped()) {
    Say(job.log, "skipped candidate " + sk.name + ": " + sk.reason);
  }
  r->val_err_before = JudgedError(r->val, r->val_before);
  r->val_err_after = JudgedError(r->val, r->val_after);
  r->verdict = Verdict(res, r->val_err_before, r->val_err_after);
  r->noise_ratio = NoiseRatio(res.after);
  if (!(r->noise_ratio <= kFarAboveNoise)) {
    char ratio[32];
    std::snprintf(ratio, sizeof(ratio), "%.3g", r->noise_ratio);
    Say(job.warn, std::string("the calibration residual is ") + ratio +
                      " times the stated noise after the fit: outliers the rejection missed "
                      "(rejected_rows), wrong units, or a wrong noise level; verdict unexplained");
  }
  Say(job.log,
      "verdict: " + r->verdict + "; " + res.finding.message +
          (res.finding.significant
               ? (res.unlocked.empty() ? " - not in the candidate library" : " - left over")
               : " (not significant)"));
}

// Sorts the declared sources' directions into those the validation rows constrain (at the
// augmented model's points, against its rows' noise: source_scaling.h) and the others, which
// keep their declared size; returns the chain with the constrained ones alone, the chain itself
// when none is left out (the same bits as before the sorting).
// A source where the fit placed an effect is sized by the fit as well: the effect is the
// measured form of the error the source declared (a compliant plate's tilt fitted as
// base_compliance), and its fitted std now carries that uncertainty.
kinematics::PpoeModel ConstrainedSources(const Job& job, const std::vector<Mat3>& noise,
                                         Report* r) {
  const sim::DeclaredModel& declared = *job.declared;
  r->directions = SourceDirections(job.mj, declared, job.chain->model);
  const std::vector<double> snr = SourceSignalToNoise(job.chain->model, r->val, job.em->points(),
                                                      r->val_p1, noise, r->directions);
  std::set<std::string> fitted_at;
  for (const auto& e : r->result.effects) {
    fitted_at.insert(job.em->candidates()[e.candidate].location);
  }
  r->constrained.assign(r->directions.size(), false);
  std::string kept;
  for (size_t i = 0; i < r->directions.size(); ++i) {
    r->constrained[i] = snr[i] >= kConstrainedSignalToNoise ||
                        fitted_at.count(declared.sources[r->directions[i].source].at) > 0;
    if (r->constrained[i]) continue;
    r->kept_declared.push_back(r->directions[i].name);
    kept += (kept.empty() ? "" : ", ") + r->directions[i].name;
  }
  if (!kept.empty()) {
    Say(job.log,
        "PPOE source directions the validation rows do not constrain, kept as declared: " + kept);
  }
  if (r->kept_declared.empty()) return job.chain->model;
  return WithSourceDirections(job.chain->model, r->directions, r->constrained);
}

// NEES of the declared PPOE covariance (plus the point noise) before and after; the augmented
// model's sources are scaled to what the remaining residual supports.
// With the readings' noise stated, the rows' NEES has a consistent size of its own: the sources
// need only cover what exceeds its upper bound (SharedNeesUpperBound), and the data decide the
// scale down to nothing. A target of 3 there inflated the sources whenever the run's parameter
// error happened to be large, about half the runs. With only a point noise the target is 3 and
// the scale keeps a floor of 1e-6, since that noise usually hides what is left.
void ScoreNees(const Job& job, const NoiseModel& nm, Report* r) {
  const DataSet& val = r->val;
  const std::vector<Mat3> noise_before = RowNoise(nm, val, r->val_loads, nullptr);
  const std::vector<Mat3> noise_after = RowNoise(nm, val, r->val_loads_after, &r->result);
  // Over the rows MeanNees averages: those in metres.
  const int metres =
      static_cast<int>(std::count_if(val.rows.begin(), val.rows.end(), [](const Observation& o) {
        return UnitOf(o.type) == RowUnit::kMetres;
      }));
  r->nees_bounds = stats::MeanChiSquareBounds(3.0, std::max(1, metres));
  r->nees_before = MeanNees(nm, val, r->val_p0, noise_before);
  r->nees_after = MeanNees(nm, val, r->val_p1, noise_after);
  double target = 3.0;
  if (job.reading_std_rad > 0.0) {
    target = SharedNeesUpperBound(nm, val, r->val_loads_after, r->result, noise_after);
    r->nees_bound_high_shared = target;
  }
  const kinematics::PpoeModel constrained = ConstrainedSources(job, noise_after, r);
  const bool any = std::count(r->constrained.begin(), r->constrained.end(), true) > 0;
  r->source_scale = any ? SourceScale(nm, val, r->val_p1, noise_after, target, constrained) : 1.0;
  r->nees_after_scaled = MeanNees(nm, val, r->val_p1, noise_after, r->source_scale, &constrained);
  // At the largest scale and still above: what is left is not where the sources act.
  r->sources_cover_residual = r->nees_after_scaled <= target + 1e-6;
  if (!r->sources_cover_residual) {
    Say(job.log, "the declared sources cannot cover what the effects leave: validation mean NEES " +
                     ShortNum(r->nees_after_scaled) + " at the largest source scale");
  }
}

// The stages on the rows r holds.
void RunOn(const Job& job, Report* out) {
  if (!job.declared || !job.mj || !job.chain || !job.em) {
    throw std::invalid_argument("identify::Run: a job needs its declared model, chain and effects");
  }
  Report& r = *out;
  const Clock::time_point t0 = Clock::now();
  Prepare(job, &r);
  r.prepare_s = SecondsSince(t0);
  Say(job.log, "identify: " + std::to_string(r.cal.rows.size()) + " calibration rows, " +
                   std::to_string(job.candidates.size()) + " candidate effects");
  if (r.cal_loads.num_kept() < r.cal_loads.size()) {
    Say(job.log, "identify: the loads of " + std::to_string(r.cal_loads.num_kept()) + " of " +
                     std::to_string(r.cal_loads.size()) + " rows kept (" +
                     std::to_string(static_cast<int>(kLoadsCacheBytes / (1 << 20))) +
                     " MB); the others are computed in each pass over the rows (the "
                     "same results, more time)");
  }
  const Clock::time_point t1 = Clock::now();
  // The selection log as it is written: a long identification shows where it is.
  IdentifyOptions opt = job.opt;
  if (job.log) opt.on_step = [&job](const std::string& s) { job.log("  " + s); };
  r.result = Identify(*job.em, r.cal, r.cal_loads, job.candidates, opt);
  r.identify_s = SecondsSince(t1);
  const NoiseModel nm{job.em, job.chain, job.opt.point_std_m, job.reading_std_rad};
  Score(job, nm, &r);
  Judge(job, &r);
  ScoreNees(job, nm, &r);
}

}  // namespace

bool HasUnit(const DataSet& d, RowUnit unit) {
  return std::any_of(d.rows.begin(), d.rows.end(),
                     [&](const auto& o) { return UnitOf(o.type) == unit; });
}

RowUnit MainUnit(const DataSet& d) {
  for (const RowUnit u : {RowUnit::kMetres, RowUnit::kPixels}) {
    if (HasUnit(d, u)) return u;
  }
  return RowUnit::kRadians;
}

Report Run(const Job& job) {
  Report r;
  r.cal = job.cal;
  r.val = job.val;
  RunOn(job, &r);
  return r;
}

Report Run(Job&& job) {
  Report r;
  r.cal = std::move(job.cal);
  r.val = std::move(job.val);
  job.cal = DataSet();
  job.val = DataSet();
  RunOn(job, &r);
  return r;
}

}  // namespace flexbench::identify
