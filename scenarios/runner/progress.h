// Progress of a long run on stderr: on a terminal one updating line (stage k/n,
// elapsed, ETA); in a log (CI) a plain line at most every `log_period_s`; nothing for runs
// shorter than `quiet_below_s`, and nothing at all with --quiet.
#pragma once

#include <chrono>
#include <functional>
#include <string>

namespace flexbench::scenarios {

class ProgressLine {
 public:
  using Clock = std::function<double()>;  // seconds, monotonic
  struct Options {
    bool terminal = false;
    bool quiet = false;
    double quiet_below_s = 2.0;  // a run this short shows no progress
    double log_period_s = 10.0;  // in a log, at most one line this often (and a stage's end)
  };

  // `write` receives finished text (with "\r" / "\n" as the destination needs).
  ProgressLine(Options options, std::function<void(const std::string&)> write,
               Clock clock = SteadySeconds);

  // Stage `stage` has done `done` of `total` steps.
  void Update(const std::string& stage, int done, int total);

  static double SteadySeconds();

 private:
  std::string Text(const std::string& stage, int done, int total, double now) const;

  Options options_;
  std::function<void(const std::string&)> write_;
  Clock clock_;
  double start_;
  double last_update_;
  std::string stage_;
  double stage_start_ = 0.0;
  double last_line_ = -1e300;
  bool shown_in_stage_ = false;
};

}  // namespace flexbench::scenarios
