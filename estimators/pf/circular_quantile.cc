#include "estimators/pf/circular_quantile.h"

#include <algorithm>
#include <cmath>

#include "estimators/pf/particle_loop.h"

namespace flexbench::pf {
namespace {

// The "diamond angle" of the particles' deviations (y, x) = (s cm - c sm, c cm + s sm): monotone
// in atan2(y, x) over (-pi, pi], onto (-2, 2], the sign bit of y deciding the side on the
// negative x axis as atan2 does for y = -0; 0 for (0, 0) as atan2. lo/hi get the key of a kept
// particle (w_i >= negligible) and +-inf otherwise, wk its weight or 0. Branch-free: it
// vectorises.
FLEXBENCH_PARTICLE_LOOP void DiamondKeys(const double* __restrict c, const double* __restrict s,
                                         const double* __restrict w, int n, double cm, double sm,
                                         double negligible, double* __restrict key,
                                         double* __restrict lo, double* __restrict hi,
                                         double* __restrict wk) {
  for (int i = 0; i < n; ++i) {
    const double y = s[i] * cm - c[i] * sm;
    const double x = c[i] * cm + s[i] * sm;
    const double l1 = std::abs(x) + std::abs(y);
    const double r = y / (l1 > 0.0 ? l1 : 1.0);
    const double left = std::copysign(2.0, y) - r;
    const double k = x >= 0.0 ? r : left;
    key[i] = k;
    const bool keep = w[i] >= negligible;
    lo[i] = keep ? k : HUGE_VAL;
    hi[i] = keep ? k : -HUGE_VAL;
    wk[i] = keep ? w[i] : 0.0;
  }
}

// The kept keys' range and weight, in four fixed lanes (the same bits from either clone).
FLEXBENCH_PARTICLE_LOOP void KeptRange(const double* __restrict lo, const double* __restrict hi,
                                       const double* __restrict wk, int n, double* kmin,
                                       double* kmax, double* kept) {
  double l4[4] = {HUGE_VAL, HUGE_VAL, HUGE_VAL, HUGE_VAL};
  double h4[4] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  double s4[4] = {0.0, 0.0, 0.0, 0.0};
  int i = 0;
  for (; i + 4 <= n; i += 4) {
    for (int l = 0; l < 4; ++l) {
      l4[l] = lo[i + l] < l4[l] ? lo[i + l] : l4[l];
      h4[l] = hi[i + l] > h4[l] ? hi[i + l] : h4[l];
      s4[l] += wk[i + l];
    }
  }
  for (; i < n; ++i) {
    l4[i & 3] = lo[i] < l4[i & 3] ? lo[i] : l4[i & 3];
    h4[i & 3] = hi[i] > h4[i & 3] ? hi[i] : h4[i & 3];
    s4[i & 3] += wk[i];
  }
  *kmin = std::min(std::min(l4[0], l4[1]), std::min(l4[2], l4[3]));
  *kmax = std::max(std::max(h4[0], h4[1]), std::max(h4[2], h4[3]));
  *kept = (s4[0] + s4[1]) + (s4[2] + s4[3]);
}

}  // namespace

CircularQuantileScratch::CircularQuantileScratch(int n) : key_(n), lo_(n), hi_(n), wk_(n), bin_(n), idx_(n + 1) {
  pairs_.reserve(n);
}

void WeightedCircularQuantiles(const double* c, const double* s, const double* w, int n, double cm,
                               double sm, double negligible, const double* probs, int np,
                               double* out, CircularQuantileScratch* scratch) {
  constexpr int kBins = CircularQuantileScratch::kBins;
  std::vector<double>& key = scratch->key_;
  std::vector<int>& bin = scratch->bin_;
  std::array<double, kBins>& mass = scratch->mass_;
  double kept = 0.0, kmin = HUGE_VAL, kmax = -HUGE_VAL;
  DiamondKeys(c, s, w, n, cm, sm, negligible, key.data(), scratch->lo_.data(),
              scratch->hi_.data(), scratch->wk_.data());
  KeptRange(scratch->lo_.data(), scratch->hi_.data(), scratch->wk_.data(), n, &kmin, &kmax, &kept);
  if (!(kept > 0.0)) {
    for (int k = 0; k < np; ++k) out[k] = 0.0;
    return;
  }
  mass.fill(0.0);
  const double scale = kmax > kmin ? kBins / (kmax - kmin) : 0.0;
  for (int i = 0; i < n; ++i) {
    if (w[i] < negligible) {
      bin[i] = -1;
      continue;
    }
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
    // Branch-free gather (which particles fall in [lo, hi] is unpredictable): every index is
    // written, the count advances only for those inside (bin -1, negligible, wraps above).
    int* idx = scratch->idx_.data();
    int count = 0;
    const unsigned width = static_cast<unsigned>(hi - lo);
    for (int i = 0; i < n; ++i) {
      idx[count] = i;
      count += static_cast<unsigned>(bin[i] - lo) <= width;
    }
    for (int j = 0; j < count; ++j) {
      const int i = idx[j];
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
