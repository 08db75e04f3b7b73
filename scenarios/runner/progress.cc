#include "scenarios/runner/progress.h"

#include <algorithm>
#include <cstdio>

namespace flexbench::scenarios {

double ProgressLine::SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

ProgressLine::ProgressLine(Options options, std::function<void(const std::string&)> write,
                           Clock clock)
    : options_(options),
      write_(std::move(write)),
      clock_(std::move(clock)),
      start_(clock_()),
      last_update_(start_) {}

std::string ProgressLine::Text(const std::string& stage, int done, int total, double now) const {
  const double elapsed = now - start_;
  const double in_stage = now - stage_start_;
  char eta[48] = "";
  if (done > 0 && done < total && in_stage > 0.0) {
    std::snprintf(eta, sizeof(eta), ", ETA %.0f s", in_stage / done * (total - done));
  }
  char text[256];
  std::snprintf(text, sizeof(text), "[flexbench] %s %d/%d, elapsed %.1f s%s", stage.c_str(), done,
                total, elapsed, eta);
  return text;
}

void ProgressLine::Update(const std::string& stage, int done, int total) {
  if (options_.quiet) return;
  const double now = clock_();
  if (stage != stage_) {
    stage_ = stage;
    // The stage began when its first step did: at the previous update (or the run's start).
    stage_start_ = last_update_;
    shown_in_stage_ = false;
  }
  last_update_ = now;
  const bool last = done >= total;
  if (now - start_ < options_.quiet_below_s && !(last && shown_in_stage_)) return;
  if (options_.terminal) {
    // Padded so that a shorter line overwrites a longer one.
    std::string text = Text(stage, done, total, now);
    text.resize(std::max<size_t>(text.size(), 72), ' ');
    write_("\r" + text + (last ? "\n" : ""));
    shown_in_stage_ = !last;
    return;
  }
  if (!(last && shown_in_stage_) && now - last_line_ < options_.log_period_s) return;
  write_(Text(stage, done, total, now) + "\n");
  last_line_ = now;
  shown_in_stage_ = !last;
}

}  // namespace flexbench::scenarios
