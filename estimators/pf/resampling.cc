#include "estimators/pf/resampling.h"

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
  const double common = scheme == ResamplingScheme::kSystematic ? Uniform53(rng) : 0.0;
  // Walk the cumulative sum once; u_k increases with k.
  int i = 0;
  double cumulative = weights[0];
  for (int k = 0; k < n; ++k) {
    const double u =
        (k + (scheme == ResamplingScheme::kSystematic ? common : Uniform53(rng))) * step;
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
