#include "scenarios/identify/cross_validation.h"

#include <algorithm>
#include <string>
#include <unordered_map>

#include "scenarios/identify/parallel.h"
#include "scenarios/identify/problem.h"

namespace flexbench::identify {

namespace {

// Per row, its posture in order of first appearance: the `pose` label within its set where the
// data gives one, else its set and identical readings (every marker seen at one posture).
std::vector<int> PostureOfRows(const DataSet& data) {
  std::unordered_map<std::string, int> index;
  std::vector<int> posture(data.rows.size());
  std::string key;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Observation& o = data.rows[r];
    key.assign(reinterpret_cast<const char*>(&o.set), sizeof(o.set));
    if (o.pose >= 0) {
      key += 'p';
      key.append(reinterpret_cast<const char*>(&o.pose), sizeof(o.pose));
    } else {
      key += 'q';
      key.append(reinterpret_cast<const char*>(o.q.data()), sizeof(double) * o.q.size());
    }
    posture[r] = index.emplace(key, static_cast<int>(index.size())).first->second;
  }
  return posture;
}

}  // namespace

Folds MakeFolds(const DataSet& data, const std::string& by) {
  Folds f;
  const auto by_label = [&](const char* by, int n, auto label_of) {
    f.by = by;
    f.test_rows.assign(n, {});
    for (size_t r = 0; r < data.rows.size(); ++r) {
      const int l = label_of(data.rows[r]);
      if (l >= 0) f.test_rows[l].push_back(static_cast<int>(r));
    }
    f.test_rows.erase(std::remove_if(f.test_rows.begin(), f.test_rows.end(),
                                     [](const std::vector<int>& v) { return v.empty(); }),
                      f.test_rows.end());
  };
  if (by == "auto" || by == "set") {
    by_label("set", static_cast<int>(data.sets.size()), [](const Observation& o) { return o.set; });
    if (f.test_rows.size() >= 2 || by == "set") return f;
  }
  if (by == "auto" || by == "group")
    by_label("group", static_cast<int>(data.groups.size()),
             [](const Observation& o) { return o.type == ObservationType::kGroup ? o.group : -1; });
  const std::vector<int> posture = PostureOfRows(data);
  if (f.test_rows.size() >= 4 || by == "group") {
    // Rows without a group (points) join the folds in round robin by posture.
    std::unordered_map<int, int> fold_of;
    for (size_t r = 0; r < data.rows.size(); ++r) {
      if (data.rows[r].type != ObservationType::kGroup) {
        const int k = fold_of.emplace(posture[r], static_cast<int>(fold_of.size())).first->second;
        f.test_rows[k % f.test_rows.size()].push_back(static_cast<int>(r));
      }
    }
    for (auto& t : f.test_rows) std::sort(t.begin(), t.end());
    return f;
  }
  // Round robin over postures, so two markers of one posture never sit in different folds.
  f.by = "row";
  const int postures = posture.empty() ? 0 : *std::max_element(posture.begin(), posture.end()) + 1;
  const int k = std::min(5, postures);
  f.test_rows.assign(k, {});
  for (size_t r = 0; r < data.rows.size(); ++r) {
    f.test_rows[posture[r] % k].push_back(static_cast<int>(r));
  }
  return f;
}

DataSet Subset(const DataSet& data, const std::vector<int>& rows) {
  DataSet s;
  s.camera = data.camera;
  s.frames = data.frames;
  s.points = data.points;
  s.offset_unknown = data.offset_unknown;
  std::vector<int> group_map(data.groups.size(), -1), set_map(data.sets.size(), -1);
  for (int r : rows) {
    Observation o = data.rows[r];
    if (o.type == ObservationType::kGroup) {
      if (group_map[o.group] < 0) {
        group_map[o.group] = static_cast<int>(s.groups.size());
        s.groups.push_back(data.groups[o.group]);
      }
      o.group = group_map[o.group];
    }
    if (o.set >= 0 && o.set < static_cast<int>(set_map.size())) {
      if (set_map[o.set] < 0) {
        set_map[o.set] = static_cast<int>(s.sets.size());
        s.sets.push_back(data.sets[o.set]);
      }
      o.set = set_map[o.set];
    }
    s.rows.push_back(std::move(o));
  }
  for (const GroupDistance& d : data.distances) {
    if (group_map[d.a] >= 0 && group_map[d.b] >= 0) {
      s.distances.push_back({group_map[d.a], group_map[d.b], d.distance_m});
    }
  }
  return s;
}

double HeldOutSquares(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                      const std::vector<int>& active, const Eigen::VectorXd& theta,
                      const IdentifyOptions& opt, int* entries, const Fit* nuisance,
                      const std::vector<int>* rows) {
  const Problem pr(em, data, loads, active, {}, opt, rows);
  Eigen::VectorXd x(pr.num_params());
  x.head(pr.num_alpha()) = theta;
  SetFrameStates(pr, nuisance ? *nuisance : Fit(), &x);
  if (!data.groups.empty()) {
    std::vector<lie::SE3> T;
    pr.Poses(theta, &T);
    std::vector<Vec3> points(T.size());
    for (size_t r = 0; r < T.size(); ++r) points[r] = T[r].translation();
    const std::vector<Vec3> d_marker = pr.MarkerOffsets(x);
    for (size_t r = 0; r < T.size() && !d_marker.empty(); ++r) {
      points[r] = T[r] * d_marker[data.rows[r].point];
    }
    const std::vector<Vec3> mean = GroupMeans(data, points);
    for (size_t g = 0; g < mean.size(); ++g) x.segment<3>(pr.num_alpha() + 3 * g) = mean[g];
  }
  int priors = 0;
  for (const MeasurementFrame& f : data.frames) priors += f.has_prior;
  const Eigen::VectorXd r = pr.Residuals(x).head(pr.num_residuals() - 6 * priors);
  *entries = static_cast<int>(r.size());
  return r.squaredNorm();
}

namespace {

// Rows without groups are read in place: a group renumbering is all a subset would add.
bool InPlace(const DataSet& data) { return data.groups.empty(); }

FoldData MakeFoldData(const DataSet& data, const RowLoads& loads, const std::vector<int>& test) {
  std::vector<char> in_test(data.rows.size(), 0);
  for (int r : test) in_test[r] = 1;
  FoldData f;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    if (!in_test[r]) f.train_rows.push_back(static_cast<int>(r));
  }
  if (InPlace(data)) return f;
  f.train = Subset(data, f.train_rows);
  f.train_loads = loads.Subset(f.train, f.train_rows);
  f.test = Subset(data, test);
  f.test_loads = loads.Subset(f.test, test);
  return f;
}

}  // namespace

void CacheFolds(const DataSet& data, const RowLoads& loads, Folds* folds, size_t max_bytes) {
  folds->cache.clear();
  size_t row_bytes = sizeof(int);
  if (!InPlace(data)) {
    row_bytes += sizeof(Observation);
    if (loads.num_kept() > 0) row_bytes += LoadsBytes(loads.kept(0));
    if (!data.rows.empty()) row_bytes += sizeof(double) * data.rows.front().q.size();
  }
  if (row_bytes * data.rows.size() * folds->test_rows.size() > max_bytes) return;
  for (const std::vector<int>& test : folds->test_rows) {
    folds->cache.push_back(MakeFoldData(data, loads, test));
  }
}

double CrossValidate(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                     const Folds& folds, const Fit& fit, const IdentifyOptions& opt) {
  // Each fold starts from the full-data fit, a few steps from its own optimum. The folds run
  // side by side when cached (made here, one fold's copy of the rows at a time); their sums
  // add up in fold order.
  const int num_folds = static_cast<int>(folds.test_rows.size());
  const bool cached = folds.cache.size() == folds.test_rows.size();
  const int threads =
      cached ? TaskThreads(num_folds, static_cast<int>(data.rows.size()), opt.threads) : 1;
  IdentifyOptions fold_opt = TaskOptions(opt, threads);
  const IdentifyOptions test_opt = fold_opt;
  fold_opt.max_iterations = std::min(opt.max_iterations, 8);
  const bool nuisance =
      !data.frames.empty() || std::count(data.offset_unknown.begin(), data.offset_unknown.end(), 1);
  std::vector<double> fold_ss(num_folds, 0.0);
  std::vector<int> fold_entries(num_folds, 0);
  ForEachTask(num_folds, threads, [&](int k) {
    FoldData made;
    if (!cached) made = MakeFoldData(data, loads, folds.test_rows[k]);
    const FoldData& f = cached ? folds.cache[k] : made;
    const bool in_place = InPlace(data);
    Fit train = fit;
    if (!fit.active.empty() || nuisance) {
      train = in_place ? FitEffects(em, data, loads, fit.active, fit.basis, fit.theta, fold_opt,
                                    &f.train_rows)
                       : FitEffects(em, f.train, f.train_loads, fit.active, fit.basis, fit.theta,
                                    fold_opt);
    }
    fold_ss[k] = in_place ? HeldOutSquares(em, data, loads, fit.active, train.theta, test_opt,
                                           &fold_entries[k], &train, &folds.test_rows[k])
                          : HeldOutSquares(em, f.test, f.test_loads, fit.active, train.theta,
                                           test_opt, &fold_entries[k], &train);
  });
  double ss = 0.0;
  int entries = 0;
  for (int k = 0; k < num_folds; ++k) {
    ss += fold_ss[k];
    entries += fold_entries[k];
  }
  return entries > 0 ? ss / entries : 0.0;
}

}  // namespace flexbench::identify
