#include "estimators/pf/circular_quantile.h"

#include <algorithm>
#include <cmath>

namespace flexbench::pf {
namespace {

// Monotone in atan2(y, x) over (-pi, pi], onto (-2, 2]: the "diamond angle". The sign bit of y
// decides the side on the negative x axis, as atan2 does for y = -0.
double PseudoAngle(double y, double x) {
  const double l1 = std::abs(x) + std::abs(y);
  if (l1 == 0.0) return 0.0;  // atan2(0, 0) = 0
  const double r = y / l1;
  if (x >= 0.0) return r;
  return std::signbit(y) ? -2.0 - r : 2.0 - r;
}

}  // namespace

CircularQuantileScratch::CircularQuantileScratch(int n) : key_(n), bin_(n) { pairs_.reserve(n); }

void WeightedCircularQuantiles(const double* c, const double* s, const double* w, int n, double cm,
                               double sm, double negligible, const double* probs, int np,
                               double* out, CircularQuantileScratch* scratch) {
  constexpr int kBins = CircularQuantileScratch::kBins;
  std::vector<double>& key = scratch->key_;
  std::vector<int>& bin = scratch->bin_;
  std::array<double, kBins>& mass = scratch->mass_;
  double kept = 0.0, kmin = HUGE_VAL, kmax = -HUGE_VAL;
  for (int i = 0; i < n; ++i) {
    if (w[i] < negligible) {
      bin[i] = -1;
      continue;
    }
    key[i] = PseudoAngle(s[i] * cm - c[i] * sm, c[i] * cm + s[i] * sm);
    kmin = std::min(kmin, key[i]);
    kmax = std::max(kmax, key[i]);
    kept += w[i];
  }
  if (!(kept > 0.0)) {
    for (int k = 0; k < np; ++k) out[k] = 0.0;
    return;
  }
  mass.fill(0.0);
  const double scale = kmax > kmin ? kBins / (kmax - kmin) : 0.0;
  for (int i = 0; i < n; ++i) {
    if (bin[i] < 0) continue;
    bin[i] = std::min(kBins - 1, static_cast<int>((key[i] - kmin) * scale));
    mass[bin[i]] += w[i];
  }
  int first_bin = 0;
  while (mass[first_bin] == 0.0 && first_bin + 1 < kBins) ++first_bin;
  for (int k = 0; k < np; ++k) {
    const double target = probs[k] * kept;
    // b: the first bin whose cumulative mass reaches the target. The first particle whose middle
    // does lies in b or in the next non-empty bin; the one before it, in b or the previous one.
    double before = 0.0;
    int b = 0;
    while (b + 1 < kBins && before + mass[b] < target) before += mass[b++];
    int lo = b, hi = b;
    double start = before;
    while (lo > 0) {
      if (mass[lo - 1] > 0.0) {
        --lo;
        start -= mass[lo];
        break;
      }
      --lo;
    }
    if (mass[lo] == 0.0) lo = b;  // nothing non-empty before b
    if (lo == b) start = before;
    for (int h = b + 1; h < kBins; ++h) {
      if (mass[h] > 0.0) {
        hi = h;
        break;
      }
    }
    std::vector<std::pair<double, double>>& pairs = scratch->pairs_;
    pairs.clear();
    for (int i = 0; i < n; ++i) {
      if (bin[i] < lo || bin[i] > hi) continue;
      pairs.emplace_back(std::atan2(s[i] * cm - c[i] * sm, c[i] * cm + s[i] * sm), w[i]);
    }
    std::sort(pairs.begin(), pairs.end());
    // The walk of the sorted definition, from the gathered bins' start.
    double cum = start;
    double prev_mid = lo == first_bin ? -1.0 : start;  // a particle before lo exists
    double prev_d = pairs.front().first;
    double result = pairs.back().first;
    for (const auto& [d, wi] : pairs) {
      const double mid = cum + 0.5 * wi;
      if (mid >= target) {
        result = prev_mid < 0.0 || &d == &pairs.front().first
                     ? d
                     : prev_d + (d - prev_d) * (target - prev_mid) / (mid - prev_mid);
        break;
      }
      cum += wi;
      prev_mid = mid;
      prev_d = d;
    }
    out[k] = result;
  }
}

}  // namespace flexbench::pf
