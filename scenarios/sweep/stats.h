// Statistics of a sweep: what a set of runs says about a metric, with intervals that are the
// same bytes for the same data (the bootstrap draws from a fixed, seeded stream).
#pragma once

#include <cstdint>
#include <vector>

namespace flexbench::scenarios::sweep {

struct SampleSummary {
  int n = 0;
  double mean = 0.0;
  double std = 0.0;  // sample standard deviation (n - 1); 0 for one value
  double median = 0.0;
  double min = 0.0;
  double max = 0.0;
  double ci_low = 0.0;  // 95% percentile-bootstrap interval of the mean
  double ci_high = 0.0;
};

// Summarises the finite values of `x` (non-finite ones are left out; n counts the rest). The
// bootstrap resamples `resamples` times from a splitmix64 stream seeded with `seed`, so the
// interval depends on the data and the seed only. n = 0: every field NaN.
SampleSummary Summarize(const std::vector<double>& x, std::uint64_t seed, int resamples = 2000);

struct Proportion {
  int passes = 0;
  int n = 0;
  double fraction = 0.0;    // NaN for n = 0
  double wilson_low = 0.0;  // 95% Wilson score interval
  double wilson_high = 0.0;
};

Proportion WilsonInterval(int passes, int n);

// Quantile of sorted values with linear interpolation between order statistics (R type 7).
double SortedQuantile(const std::vector<double>& sorted, double q);

// FNV-1a of `text`: a stable seed for the bootstrap of one metric.
std::uint64_t StableHash(const char* text);

}  // namespace flexbench::scenarios::sweep
