// Choosing the effects: forward selection screened by BIC and checked on held-out data.
//
// Each round fits every eligible candidate (its observable directions only) beside the chosen
// ones, ranks them by BIC = N ln(RSS/N) + k ln N, and takes the best few that lower BIC by more
// than the threshold to cross-validation (cross_validation.h): the candidate kept is the one
// with the lowest held-out error, and only if that error drops by more than `cv_min_gain`
// relative to the current model's; a fit outside a candidate's physical bounds is rejected and
// logged. After each addition, an earlier effect that neither BIC nor the held-out error still
// needs goes back to the pool. Nothing is ever set aside for good: a candidate whose
// sensitivity a chosen effect covers is simply unobservable while that effect stays, and comes
// back when it leaves. At the end, a chosen effect is swapped for another candidate when the
// swap lowers BIC by more than `ambiguity_bic` without raising the held-out error.
#pragma once
#include <atomic>
#include <chrono>
#include <functional>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "scenarios/identify/cross_validation.h"
#include "scenarios/identify/identify.h"

namespace flexbench::identify {

// The selection's steps by their exact inputs, for one data set, its loads, folds and options:
// the alternatives (a selection per chosen effect, each with one candidate banned) retrace the
// chosen selection's rounds until the banned effect would enter, and those rounds' screens,
// refits, removals and held-out errors are the same bits. Safe for tasks side by side.
class SelectionMemo {
 public:
  // The most the memo holds (keys and values): beyond, results are computed and not kept (the
  // chosen selection's rounds, which the alternatives retrace, come first).
  static constexpr size_t kMaxBytes = size_t{256} << 20;

  // The exact state of a fit (effects, bases, parameters, nuisance states), as bytes.
  static std::string Key(const Fit& fit);
  // What a copy of `fit` takes.
  static size_t Bytes(const Fit& fit);

  template <typename V>
  class Table {
   public:
    explicit Table(std::atomic<size_t>* bytes) : bytes_(bytes) {}
    bool Find(const std::string& key, V* out) const {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto it = map_.find(key);
      if (it == map_.end()) return false;
      *out = it->second;
      return true;
    }
    // Keeps v (of `value_bytes`) unless the memo is full.
    void Put(const std::string& key, const V& v, size_t value_bytes) {
      const size_t b = key.size() + value_bytes;
      if (bytes_->fetch_add(b) + b > kMaxBytes) {
        bytes_->fetch_sub(b);
        return;
      }
      std::lock_guard<std::mutex> lock(mutex_);
      map_.emplace(key, v);
    }

   private:
    std::atomic<size_t>* bytes_;
    mutable std::mutex mutex_;
    std::unordered_map<std::string, V> map_;
  };

  struct Screen {
    bool kept = false;
    Fit fit;
  };
  struct Refit {
    Fit fit;
    std::vector<std::string> log;  // earlier effects it pushed past their bounds
    std::vector<std::string> out;  // its own bound violations
    double cv = 0.0;
  };
  std::atomic<size_t> bytes{0};    // held by all tables
  Table<Screen> screens{&bytes};   // Key(cur) + candidate
  Table<Refit> refits{&bytes};     // Key(screened fit) + candidate
  Table<Fit> withouts{&bytes};     // Key(fit) + index of the effect removed
  Table<double> held_out{&bytes};  // Key(fit)
};

struct SelectionContext {
  const EffectModel& em;
  const DataSet& data;
  const RowLoads& loads;
  const Folds& folds;
  const IdentifyOptions& opt;
  std::vector<std::string>* log;
  bool* capped = nullptr;  // set when max_effects stopped a selection the data would continue
  SelectionMemo* memo = nullptr;  // null: every step computed
  // When the selection started, for IdentifyOptions::time_budget_s; set when it ran out (null:
  // no budget, as in a task of its own: the alternatives re-run selections beyond it).
  std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now();
  bool* out_of_time = nullptr;
  // Hands the log's new lines to IdentifyOptions::on_step (null: a task's own log, kept).
  const std::function<void()>* flush = nullptr;
};

// Whether the time budget has run out (logged once, with what it stops).
bool OutOfTime(const SelectionContext& ctx, const char* stops);

// `ctx` for a task of its own: options `opt` (TaskOptions), log `log`, no cap or budget to
// report; the data, folds and memo shared.
SelectionContext TaskContext(const SelectionContext& ctx, const IdentifyOptions& opt,
                             std::vector<std::string>* log);

// ", held-out A -> B sigma^2" (the mean squared held-out residual in units of the stated
// noise), or "" without cross-validation.
std::string HeldOutChange(const SelectionContext& ctx, double from, double to);

// Parameters of `fit` outside their candidates' bounds, as "name[k] = v outside [lo, hi]";
// empty when all are inside.
std::vector<std::string> BoundViolations(const EffectModel& em, const Fit& fit);

// Held-out error of `fit` (NaN when cross-validation is off).
double CvError(const SelectionContext& ctx, const Fit& fit);

// Selection from `start` over `pool`. `backward`: earlier effects may leave again, and the
// swap step runs at the end when `swap`. `*cv` holds the current model's held-out error on
// entry and on return.
Fit SelectEffects(const SelectionContext& ctx, const Fit& start, const std::vector<int>& pool,
                  bool backward, double* cv, bool swap = true);

// Complete geometry in one block: every candidate of `pool` (joint origins) at once, each in
// the directions still observable beside the chosen effects and the block so far, kept only
// when the whole block lowers the held-out error by cv_min_gain and stays inside its bounds.
// Small corrections spread over many joints (what a full recalibration fits) never pass
// forward selection one at a time; as a block they may.
Fit AddGeometryBlock(const SelectionContext& ctx, const Fit& start, const std::vector<int>& pool,
                     double* cv);

}  // namespace flexbench::identify
