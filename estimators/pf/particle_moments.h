// The particle filter summary's weight and resultant loops: branch-free and in fixed
// lanes, so they vectorise in the AVX2 clone and give the same bits in the baseline. With libm's
// exp and a plain running sum they were a sixth of a summary.
#pragma once

#include <vector>

namespace flexbench::pf {

// The particles a summary's spreads sum over (w_i >= negligible), gathered so that each keeps
// its lane (index mod 4): lane l's kept particles in order at positions l, l + 4, ..., a lane
// with fewer padded with weight 0. A sum over these positions in four fixed lanes therefore adds
// exactly the terms, in the order, of the same sum over all particles with the negligible ones
// contributing +0. A filter that has just weighed a reading has about half its particles
// negligible (bench_pf): the summary's log and band passes run over the others only.
class KeptParticles {
 public:
  KeptParticles() = default;
  explicit KeptParticles(int capacity);  // particles; allocates everything Select needs

  // From normalised weights; allocates nothing. NaN weights are not kept.
  void Select(const double* w, int n, double negligible);
  int size() const { return size_; }                // positions, padding included: a multiple of 4
  const int* index() const { return idx_.data(); }  // each position's particle (padding: 0)
  const double* weight() const { return w_.data(); }  // its weight (padding: 0)
  // out_a[p] = a[index()[p]] and out_b[p] = b[index()[p]] for every position (one index load
  // for both: a joint's cosines and sines).
  void Gather(const double* a, const double* b, double* out_a, double* out_b) const;

 private:
  std::vector<int> idx_;
  std::vector<double> w_;
  int size_ = 0;
};

// w_i = exp(lw_i) / sum_j exp(lw_j) for the max-normalised log weights lw_i <= 0 ([PF eq. 21]; -inf
// allowed, as for a rejected particle); returns the effective sample size (sum e)^2 / sum e^2 of
// the unnormalised e_i = exp(lw_i). exp(lw_i) below 1e-150 counts as 0 (invisible next to the
// largest, 1; no subnormal arithmetic).
double NormalisedWeights(const double* log_w, int n, double* w);

// (sum_i w_i c_i, sum_i w_i s_i): the weighted resultant of the unit vectors (c_i, s_i), whose
// direction is the circular mean [PF eq. 5] and whose length is R.
void WeightedResultant(const double* c, const double* s, const double* w, int n, double* sc,
                       double* ss);

namespace internal {
// exp(x) for x <= 0 (Cephes' exp: x = k ln 2 + r, a Pade form of exp(r), scaled by 2^k built in
// the exponent bits, no branch): within 2 ulp of std::exp down to x = -708 (tested); 0 below
// and for -inf. A log weight that low (e^-708 ~ 1e-308) contributes nothing to any sum here.
double ExpNonPositive(double x);
}  // namespace internal

}  // namespace flexbench::pf
