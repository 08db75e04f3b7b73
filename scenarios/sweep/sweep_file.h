// A sweep file: one scenario run over seeds and a grid of overrides, with statistical gates.
//
//   sweep: rover_exp1_seeds
//   scenario: ../rover_apriltag_exp1.yaml      # relative to this file
//   seeds: {from: 1, to: 32}                  # or a list: [1, 2, 7]
//   set: {render.mode: fast}                  # the same overrides for every run (optional)
//   grid:                                     # a point per combination, first key outermost
//     truth.effects.base_compliance.k: [2000, 4000, 8000]
//   gates:
//     - {name: ordering, metric: pass_fraction(ppoe_beats_naive), op: ">=", threshold: 0.9}
//     - name: ratio_ci
//       metric: ci_high(ratio(estimators.ppoe_ekf.metrics.x, estimators.naive_ekf.metrics.x))
//       op: "<"
//       threshold: 0.8
//   plot: {metrics: [estimators.ppoe_ekf.metrics.x], x: truth.effects.base_compliance.k}
//
// A gate's metric is STAT(ARG): STAT one of mean, std, median, min, max, ci_low, ci_high, n of
// a metric path or of ratio(A, B) (the paired per-seed ratio of two metrics), or one of
// pass_fraction, wilson_low, wilson_high of a scenario gate's name. A gate holds at every
// point unless it names one (`point: NAME`).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "scenarios/runner/output.h"

namespace flexbench::scenarios::sweep {

struct SweepAxis {
  std::string key;                  // dotted scenario key
  std::vector<std::string> values;  // YAML text of each value
};

struct SweepPoint {
  std::string name;                 // folder name: "base", or "<key>=<value>" parts joined by "__"
  std::vector<std::string> set;     // KEY=VALUE overrides of this point (after the fixed ones)
  std::vector<std::string> values;  // the axis values, in axis order
};

struct SweepRun {
  size_t point = 0;
  std::uint64_t seed = 0;
  std::string dir;  // runs/<point>/seed_<N>, relative to the sweep's output folder
};

// STAT(ARG) of a sweep gate or plot.
struct Statistic {
  std::string stat;
  std::string path;      // a metric path, or ratio's numerator, or a scenario gate's name
  std::string divisor;   // ratio's denominator; empty: not a ratio
  bool of_gate = false;  // pass_fraction, wilson_low, wilson_high
  std::string text;      // as written
};

struct SweepGate {
  std::string name;
  Statistic metric;
  std::string op;
  double threshold = 0.0;
  bool threshold_is_statistic = false;
  Statistic threshold_metric;
  double scale = 1.0;
  std::string point;  // empty: every point
  std::string where;  // "<file>:<line>"
};

struct SweepSpec {
  std::string file;  // as given
  std::string name;
  std::string description;
  std::string scenario;  // resolved path
  std::vector<std::uint64_t> seeds;
  std::vector<std::string> set;  // fixed KEY=VALUE overrides
  std::vector<SweepAxis> grid;
  std::vector<SweepGate> gates;
  std::vector<std::string> plot_metrics;
  std::string plot_x;  // a grid key; empty: the first grid key
  int bootstrap_resamples = 2000;
  // Images each run writes (`frames:`; default none: a sweep keeps its runs' numbers).
  FrameOutput frames = FrameOutput::kNone;
  // Files each run keeps (`run_files:` all, or summary: summary.json and report.html only;
  // --run-files overrides it). The aggregate is made from the summaries either way.
  bool run_data_files = true;
};

// Reads and checks a sweep file (not the scenario); throws InputError naming file and line.
SweepSpec LoadSweep(const std::string& path);

// "all" (true) or "summary" (false); anything else is InputError naming `option`.
bool ParseRunFiles(const std::string& text, const std::string& option);

// Parses STAT(ARG); throws InputError "<where>: ..." when malformed.
Statistic ParseStatistic(const std::string& text, const std::string& where);

std::vector<SweepPoint> ExpandPoints(const SweepSpec& spec);
// Point-major, seeds in the file's order.
std::vector<SweepRun> ExpandRuns(const SweepSpec& spec, const std::vector<SweepPoint>& points);

}  // namespace flexbench::scenarios::sweep
