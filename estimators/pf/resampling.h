// Resampling of weighted particles (Li, Bolic and Djuric, "Resampling Methods for Particle
// Filtering", IEEE SPM 2015; the particle-filter paper's ref. [17]). Both schemes are unbiased:
// the expected number of copies of particle i is N w_i.
//
// - Stratified: one uniform per stratum, u_k = (k + U_k) / N.
// - Systematic: one uniform for all, u_k = (k + U) / N (lower variance, not independent).
//
// Inputs are normalised weights (sum 1, >= 0); outputs are ancestor indices, non-decreasing.
// Nothing allocates: the caller owns the index array.
#pragma once

#include <random>

namespace flexbench::pf {

enum class ResamplingScheme { kStratified, kSystematic };

// ancestors[k] for k < n from weights[0..n). Weights need not sum exactly to 1 (the cumulative
// sum is rescaled by its last value); they must be finite, >= 0, with a positive sum.
void Resample(ResamplingScheme scheme, const double* weights, int n, std::mt19937_64& rng,
              int* ancestors);

// 1 / sum w_i^2 for normalised weights, in [1, n].
double EffectiveSampleSize(const double* weights, int n);

}  // namespace flexbench::pf
