#include "estimators/pf/resampling.h"

#include <cstdint>

#include "estimators/pf/von_mises.h"

namespace flexbench::pf {

void Resample(ResamplingScheme scheme, const double* weights, int n, std::mt19937_64& rng,
              int* ancestors) {
  double total = 0.0;
  int last = 0;  // the last particle with a positive weight (rounding must not pick a dead one)
  for (int i = 0; i < n; ++i) {
    total += weights[i];
    if (weights[i] > 0.0) last = i;
  }
  const double step = total / n;
  // Stratified: one uniform per stratum, 32 bits each (two per draw): the offset inside a stratum
  // of width 1/N needs no more. Systematic: one 53-bit uniform for all.
  const double common = scheme == ResamplingScheme::kSystematic ? Uniform53(rng) : 0.0;
  std::uint64_t bits = 0;
  // Walk the cumulative sum once; u_k increases with k.
  int i = 0;
  double cumulative = weights[0];
  for (int k = 0; k < n; ++k) {
    double offset = common;
    if (scheme == ResamplingScheme::kStratified) {
      if ((k & 1) == 0) bits = rng();
      const std::uint32_t half =
          (k & 1) == 0 ? static_cast<std::uint32_t>(bits >> 32) : static_cast<std::uint32_t>(bits);
      offset = (static_cast<double>(half) + 0.5) * (1.0 / 4294967296.0);
    }
    const double u = (k + offset) * step;
    while (cumulative <= u && i < last) {
      ++i;
      cumulative += weights[i];
    }
    ancestors[k] = i;
  }
}

double EffectiveSampleSize(const double* weights, int n) {
  double s = 0.0;
  double s2 = 0.0;
  for (int i = 0; i < n; ++i) {
    s += weights[i];
    s2 += weights[i] * weights[i];
  }
  return s2 > 0.0 ? s * s / s2 : 0.0;
}

}  // namespace flexbench::pf
