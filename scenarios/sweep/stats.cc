#include "scenarios/sweep/stats.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace flexbench::scenarios::sweep {
namespace {

std::uint64_t SplitMix64(std::uint64_t* state) {
  std::uint64_t z = (*state += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

}  // namespace

double SortedQuantile(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return std::numeric_limits<double>::quiet_NaN();
  const double h = q * static_cast<double>(sorted.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(h));
  const size_t hi = std::min(lo + 1, sorted.size() - 1);
  return sorted[lo] + (h - static_cast<double>(lo)) * (sorted[hi] - sorted[lo]);
}

std::uint64_t StableHash(const char* text) {
  std::uint64_t h = 1469598103934665603ULL;
  for (; *text; ++text) {
    h ^= static_cast<unsigned char>(*text);
    h *= 1099511628211ULL;
  }
  return h;
}

SampleSummary Summarize(const std::vector<double>& x, std::uint64_t seed, int resamples) {
  std::vector<double> v;
  for (double e : x) {
    if (std::isfinite(e)) v.push_back(e);
  }
  SampleSummary s;
  s.n = static_cast<int>(v.size());
  if (v.empty()) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    s.mean = s.std = s.median = s.min = s.max = s.ci_low = s.ci_high = nan;
    return s;
  }
  double sum = 0.0;
  for (double e : v) sum += e;
  s.mean = sum / s.n;
  double ss = 0.0;
  for (double e : v) ss += (e - s.mean) * (e - s.mean);
  s.std = s.n > 1 ? std::sqrt(ss / (s.n - 1)) : 0.0;
  std::vector<double> sorted = v;
  std::sort(sorted.begin(), sorted.end());
  s.median = SortedQuantile(sorted, 0.5);
  s.min = sorted.front();
  s.max = sorted.back();
  // Percentile bootstrap of the mean; the index draw's modulo bias is below 1e-15 for any n a
  // sweep has.
  std::vector<double> means(static_cast<size_t>(std::max(resamples, 1)));
  std::uint64_t state = seed;
  for (double& m : means) {
    double acc = 0.0;
    for (int i = 0; i < s.n; ++i) acc += v[SplitMix64(&state) % v.size()];
    m = acc / s.n;
  }
  std::sort(means.begin(), means.end());
  s.ci_low = SortedQuantile(means, 0.025);
  s.ci_high = SortedQuantile(means, 0.975);
  return s;
}

Proportion WilsonInterval(int passes, int n) {
  Proportion p;
  p.passes = passes;
  p.n = n;
  if (n <= 0) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    p.fraction = p.wilson_low = p.wilson_high = nan;
    return p;
  }
  constexpr double z = 1.959963984540054;  // two-sided 95%
  const double f = static_cast<double>(passes) / n;
  const double denom = 1.0 + z * z / n;
  const double centre = (f + z * z / (2.0 * n)) / denom;
  const double half = z * std::sqrt(f * (1.0 - f) / n + z * z / (4.0 * n * n)) / denom;
  p.fraction = f;
  p.wilson_low = std::max(0.0, centre - half);
  p.wilson_high = std::min(1.0, centre + half);
  return p;
}

}  // namespace flexbench::scenarios::sweep
