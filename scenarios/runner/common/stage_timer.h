// Wall time of a pipeline's stages summed over a run, for summary.json's "timing" (the
// throughput a user of a whole scenario sees, not a kernel in isolation). Timing is the one
// part of a result that is not the same bytes at the same seed, so it never enters the metrics.
#pragma once

#include <chrono>
#include <map>
#include <string>

#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

class StageTimer {
 public:
  using Clock = std::chrono::steady_clock;

  // Times one stretch of `stage` for as long as it lives; stretches of a stage add up.
  class Scope {
   public:
    Scope(StageTimer* timer, std::string stage)
        : timer_(timer), stage_(std::move(stage)), start_(Clock::now()) {}
    ~Scope() { timer_->Add(stage_, std::chrono::duration<double>(Clock::now() - start_).count()); }
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    StageTimer* timer_;
    std::string stage_;
    Clock::time_point start_;
  };

  Scope Time(std::string stage) { return Scope(this, std::move(stage)); }
  void Add(const std::string& stage, double seconds) { seconds_[stage] += seconds; }
  double Seconds(const std::string& stage) const;
  double TotalSeconds() const;

  // timing["<stage>_ms_per_<unit>"] for every stage and timing["pipeline_<unit>s_per_s"]: `count`
  // units (frames, steps) over the stages' total.
  void Write(Json* timing, const std::string& unit, int count) const;

 private:
  std::map<std::string, double> seconds_;
};

}  // namespace flexbench::scenarios
