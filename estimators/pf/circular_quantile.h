// Weighted quantiles of particle angles about their circular mean, for the particle filter's
// per-joint 95% intervals, without sorting every particle.
#pragma once

#include <array>
#include <utility>
#include <vector>

namespace flexbench::pf {

// Preallocated for n particles; reused across joints and steps (nothing allocated per call).
class CircularQuantileScratch {
 public:
  static constexpr int kBins = 512;
  CircularQuantileScratch() = default;
  explicit CircularQuantileScratch(int n);

  struct BandEntry {
    double key, w;  // sorted by (pseudo-angle, weight), as the definition sorts (d, w)
    int i;
    int bucket;
    bool operator<(const BandEntry& o) const { return key < o.key || (key == o.key && w < o.w); }
  };

 private:
  friend void WeightedCircularQuantiles(const double*, const double*, const double*, int, double,
                                        double, double, const double*, int, double*,
                                        CircularQuantileScratch*);
  friend void SortBand(const double*, const double*, const double*, const int*, int, double, double,
                       double, double, CircularQuantileScratch*);
  friend int WeightedCircularTailQuantiles(const double*, const double*, const double*, int, double,
                                           double, double, double, double, const double*, int,
                                           double*, CircularQuantileScratch*);
  std::vector<double> key_;
  std::vector<double> lo_, hi_, wk_;  // per particle: key or +-inf, weight or 0 (kept or not)
  std::vector<int> bin_;              // -1: a negligible particle
  std::vector<int> idx_;  // the particles gathered near a quantile (n + 1: one spare write)
  std::vector<int> idx_lo_, idx_hi_;  // the lower and upper bands' particles (n + 1)
  std::vector<long long> band_;       // per particle: 1 lower band, 2 upper band, 0 neither
  std::vector<std::pair<double, double>> pairs_;
  std::vector<BandEntry> band_pairs_, band_unsorted_;
  std::vector<int> bucket_start_;  // the band's counting sort (n + 1)
  std::array<double, kBins> mass_{};
};

// The deviations d_i = atan2(s_i cm - c_i sm, c_i cm + s_i sm) of the particles (cos c_i, sin
// s_i, normalised weight w_i) from the mean direction (cm, sm), over those with w_i >=
// negligible, and their weighted p-quantiles for p in probs[0..np): each particle's mass sits at
// the middle of its step of the cumulative distribution, linear in between (below the first
// middle: the first deviation; above the last: the last). The result equals that definition
// computed on the sorted deviations up to rounding (tests/unit/pf/circular_quantile_test.cc),
// but no particle is sorted or put through atan2 except those near each quantile: a histogram
// of a pseudo-angle (monotone in the angle, no trigonometry) finds the step, and only the
// particles of its bin and the non-empty bins on either side are converted and sorted (the bins
// span the kept particles' pseudo-angles: narrower, from the spread, was measured slower).
void WeightedCircularQuantiles(const double* c, const double* s, const double* w, int n, double cm,
                               double sm, double negligible, const double* probs, int np,
                               double* out, CircularQuantileScratch* scratch);

// The same quantiles, looked for first in two bands of deviations: p <= 1/2 among the particles
// with deviation in (-outer, -inner), p > 1/2 in (inner, outer) (0 < inner < outer). One
// vectorised pass puts the particles into the bands and adds up the mass beyond them, which is
// all the definition needs of those; only the bands' particles are ordered (by the pseudo-angle,
// a counting sort; atan2 only for the two that the interpolation uses). The bands are a guess
// (the summary's: 1.6 to 2.5 circular standard deviations for the 2.5% and 97.5% quantiles);
// when a quantile's step or the particle before it is not safely inside its band, the band moves
// (beyond it, or towards the mean) and the pass is repeated, twice at most, before
// WeightedCircularQuantiles computes that quantile instead (also for negligible <= 0). The result
// is the definition's up to rounding either way (tests/unit/pf/circular_quantile_test.cc); returns
// how many quantiles needed the fallback.
int WeightedCircularTailQuantiles(const double* c, const double* s, const double* w, int n,
                                  double cm, double sm, double negligible, double inner,
                                  double outer, const double* probs, int np, double* out,
                                  CircularQuantileScratch* scratch);

}  // namespace flexbench::pf
