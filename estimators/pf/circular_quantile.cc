#include "estimators/pf/circular_quantile.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "estimators/lie/se3.h"
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

// The lanes of the kinematics' 4-wide code (lie/se3.h): lane-wise IEEE, the same bits on AVX2
// and on the baseline build.
using lie::internal::V4;
using lie::internal::V4i;
inline V4 Load4(const double* p) { return lie::internal::LoadV4(p); }

inline double LaneSum(V4 v) { return (v[0] + v[1]) + (v[2] + v[3]); }

// GCC vector casts reinterpret the bits; spelled out.
inline V4i Bits(V4 v) {
  V4i b;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

inline V4 FromBits(V4i b) {
  V4 v;
  std::memcpy(&v, &b, sizeof v);
  return v;
}

// What the band pass adds up besides the per-particle band codes.
struct BandMass {
  double kept = 0.0;
  double lower_deep = 0.0, upper_deep = 0.0;  // mass beyond -outer and beyond outer
};

// cos and sin of a band's inner and outer edge.
struct BandEdges {
  double ci, si, co, so;
};

// The band tests as linear forms in a particle's (c, s). The deviation (x, y) = (c cm + s sm,
// s cm - c sm) lies below -a when it is in the closed lower half-plane (sign bit of y, as atan2
// puts (-1, -0) at -pi) and clockwise of (cos a, -sin a): cos a y + sin a x < 0, which is
// s (cos a cm + sin a sm) + c (sin a cm - cos a sm) < 0; above a likewise. y itself is formed as
// the definition forms it, so the sides agree with its atan2; the edges' rounding is the walks'
// margin.
struct BandForms {
  V4 cm, sm;            // y = s cm - c sm
  V4 lo_in_s, lo_in_c;  // < 0: beyond -inner
  V4 lo_deep_s, lo_deep_c;
  V4 hi_in_s, hi_in_c;  // > 0: beyond inner
  V4 hi_deep_s, hi_deep_c;
  V4 negligible;
};

BandForms Forms(double cm, double sm, double negligible, const BandEdges& lo, const BandEdges& hi) {
  const auto v = [](double a) { return V4{a, a, a, a}; };
  BandForms f;
  f.cm = v(cm);
  f.sm = v(sm);
  f.lo_in_s = v(lo.ci * cm + lo.si * sm);
  f.lo_in_c = v(lo.si * cm - lo.ci * sm);
  f.lo_deep_s = v(lo.co * cm + lo.so * sm);
  f.lo_deep_c = v(lo.so * cm - lo.co * sm);
  // cos a y - sin a x = s (cos a cm - sin a sm) - c (cos a sm + sin a cm).
  f.hi_in_s = v(hi.ci * cm - hi.si * sm);
  f.hi_in_c = v(-(hi.ci * sm + hi.si * cm));
  f.hi_deep_s = v(hi.co * cm - hi.so * sm);
  f.hi_deep_c = v(-(hi.co * sm + hi.so * cm));
  f.negligible = v(negligible);
  return f;
}

// The band pass on four particles; lanes as in the sums.
inline V4i BandLanes(V4 c, V4 s, V4 w, const BandForms& f, V4* kept, V4* lo_mass, V4* hi_mass) {
  const V4 y = s * f.cm - c * f.sm;
  const V4i zero = {0, 0, 0, 0};
  const V4i neg = Bits(y) < zero;
  const V4i keep = w >= f.negligible;
  const V4i lo = neg & keep;
  const V4i hi = ~neg & keep;
  const V4i lo_deep = lo & (s * f.lo_deep_s + c * f.lo_deep_c < 0.0);
  const V4i hi_deep = hi & (s * f.hi_deep_s + c * f.hi_deep_c > 0.0);
  const V4i lo_band = lo & (s * f.lo_in_s + c * f.lo_in_c < 0.0) & ~lo_deep;
  const V4i hi_band = hi & (s * f.hi_in_s + c * f.hi_in_c > 0.0) & ~hi_deep;
  const V4i wb = Bits(w);
  *kept += FromBits(wb & keep);
  *lo_mass += FromBits(wb & lo_deep);
  *hi_mass += FromBits(wb & hi_deep);
  const V4i one = {1, 1, 1, 1}, two = {2, 2, 2, 2};
  return (lo_band & one) | (hi_band & two);
}

// Band codes (1 lower, 2 upper, 0 neither) of every particle, and the masses beyond the bands.
FLEXBENCH_PARTICLE_LOOP void BandPass(const double* __restrict c, const double* __restrict s,
                                      const double* __restrict w, int n, const BandForms& forms,
                                      long long* __restrict band, BandMass* mass) {
  const BandForms f = forms;
  V4 kept = {0.0, 0.0, 0.0, 0.0}, lo = kept, hi = kept;
  const int n4 = n & ~3;
  for (int i = 0; i < n4; i += 4) {
    const V4i code = BandLanes(Load4(c + i), Load4(s + i), Load4(w + i), f, &kept, &lo, &hi);
    std::memcpy(band + i, &code, sizeof code);
  }
  if (n4 < n) {  // the last particles, padded with unkept ones (w = -1)
    V4 cr = {1.0, 1.0, 1.0, 1.0}, sr = {0.0, 0.0, 0.0, 0.0}, wr = {-1.0, -1.0, -1.0, -1.0};
    for (int i = n4; i < n; ++i) {
      cr[i - n4] = c[i];
      sr[i - n4] = s[i];
      wr[i - n4] = w[i];
    }
    const V4i code = BandLanes(cr, sr, wr, f, &kept, &lo, &hi);
    for (int i = n4; i < n; ++i) band[i] = code[i - n4];
  }
  mass->kept = LaneSum(kept);
  mass->lower_deep = LaneSum(lo);
  mass->upper_deep = LaneSum(hi);
}

// The pseudo-angle of DiamondKeys for one deviation.
inline double DiamondKey(double y, double x) {
  const double l1 = std::abs(x) + std::abs(y);
  const double r = y / (l1 > 0.0 ? l1 : 1.0);
  return x >= 0.0 ? r : std::copysign(2.0, y) - r;
}

// Far enough inside a band that rounding cannot have put a particle of that deviation on the
// wrong side of its edges (the edge tests are exact to a few ulp).
constexpr double kBandMargin = 1e-9;

using BandEntry = CircularQuantileScratch::BandEntry;

// What a tail walk needs of the particles: their deviations and weights.
struct Particles {
  const double* c;
  const double* s;
  const double* w;
  double cm, sm;
  double Deviation(int i) const { return std::atan2(s[i] * cm - c[i] * sm, c[i] * cm + s[i] * sm); }
};

// Where a band walk found its quantile's step, or which way the band should move.
enum class Walk { kFound, kDeeper, kShallower };

// The definition's walk (the first particle whose mid-step reaches the target, interpolated from
// the one before) over the lower band (-outer, -inner), starting at the mass `below` of the
// particles beyond -outer (`deep`: whether there are any). The step and the particle before it
// must be safely inside the band.
Walk LowerWalk(const Particles& p, const std::vector<BandEntry>& band, double below, bool deep,
               double target, double inner, double outer, double* out) {
  double cum = below;
  double prev_mid = 0.0;
  for (size_t j = 0; j < band.size(); ++j) {
    const double wi = band[j].w;
    const double mid = cum + 0.5 * wi;
    if (mid >= target) {
      if (j == 0 && deep) return Walk::kDeeper;  // the particle before is beyond the band
      const double d = p.Deviation(band[j].i);
      if (!(d <= -inner - kBandMargin)) return Walk::kShallower;
      if (j == 0) {  // the first particle of all
        *out = d;
        return Walk::kFound;
      }
      const double prev_d = p.Deviation(band[j - 1].i);
      if (!(prev_d >= -outer + kBandMargin)) return Walk::kDeeper;
      *out = prev_d + (d - prev_d) * (target - prev_mid) / (mid - prev_mid);
      return Walk::kFound;
    }
    cum += wi;
    prev_mid = mid;
  }
  return Walk::kShallower;
}

// The same walk over the upper band (inner, outer) from the top: `above` is the mass beyond
// outer, `kept` all the kept mass; mid-steps are kept - (mass from the particle up) + w / 2.
Walk UpperWalk(const Particles& p, const std::vector<BandEntry>& band, double above, bool deep,
               double kept, double target, double inner, double outer, double* out) {
  double from_top = above;
  double next_mid = 0.0;  // the mid-step of the particle after (above) this one
  for (size_t j = band.size(); j-- > 0;) {
    const double wi = band[j].w;
    from_top += wi;
    const double mid = (kept - from_top) + 0.5 * wi;
    if (mid < target) {
      const bool top = j + 1 == band.size();
      if (top && deep) return Walk::kDeeper;  // the particle after is beyond the band
      const double d = p.Deviation(band[j].i);
      if (!(d >= inner + kBandMargin)) return Walk::kShallower;
      if (top) {  // the last particle of all: no mid-step reaches the target
        *out = d;
        return Walk::kFound;
      }
      const double next_d = p.Deviation(band[j + 1].i);
      if (!(next_d <= outer - kBandMargin)) return Walk::kDeeper;
      *out = d + (next_d - d) * (target - mid) / (next_mid - mid);
      return Walk::kFound;
    }
    next_mid = mid;
  }
  return Walk::kShallower;
}

// (inner, outer) of a band, in rad from the mean.
struct Band {
  double inner, outer;
  bool operator==(const Band& o) const { return inner == o.inner && outer == o.outer; }
  // Valid: a non-empty range that starts inside the circle.
  bool ok() const { return inner > 0.0 && inner < outer && inner < M_PI; }
  // The next guess after a walk missed: beyond the band, or between it and the mean (overlapping
  // it a little), or the quantile's own band once found.
  Band Moved(Walk miss) const {
    if (miss == Walk::kDeeper) return {0.95 * outer, std::min(1.6 * outer, M_PI)};
    return {0.5 * inner, 1.05 * inner};
  }
};

}  // namespace

// Half-widths of a band below which its particles are ordered by sin(d - centre) instead of the
// pseudo-angle.
constexpr double kLinearKeyHalfWidth = 1.3;

// The gathered particles sorted by (key, weight), the key sin(d - centre) for a band narrower
// than 2 kLinearKeyHalfWidth, else the pseudo-angle: the definition's order, (d, w), up to
// rounding (a key ties another only for the same or a 1e-15-close deviation; equal particles
// must still go by weight, as the interpolation depends on which comes first). A
// counting sort into as many buckets as particles over the band's pseudo-angle range, then an
// insertion sort for the few out of order within a bucket: std::sort of the ~100 particles of a
// band was a fifth of a summary.
void SortBand(const double* c, const double* s, const double* w, const int* idx, int count,
              double cm, double sm, double centre, double half_width,
              CircularQuantileScratch* scratch) {
  std::vector<BandEntry>& raw = scratch->band_unsorted_;
  std::vector<BandEntry>& band = scratch->band_pairs_;
  raw.resize(count);
  band.resize(count);
  if (half_width < kLinearKeyHalfWidth) {
    // sin(d - centre) = y cos(centre) - x sin(centre), linear in (c, s): no division. Its slope
    // is at least cos(kLinearKeyHalfWidth) over the band.
    const double ks = cm * std::cos(centre) - sm * std::sin(centre);
    const double kc = sm * std::cos(centre) + cm * std::sin(centre);
    for (int j = 0; j < count; ++j) {
      const int i = idx[j];
      raw[j] = {s[i] * ks - c[i] * kc, w[i], i, 0};
    }
  } else {
    for (int j = 0; j < count; ++j) {
      const int i = idx[j];
      raw[j] = {DiamondKey(s[i] * cm - c[i] * sm, c[i] * cm + s[i] * sm), w[i], i, 0};
    }
  }
  // Two chains each: a min's latency, not its throughput, bounds a single chain.
  double kmin2[2] = {HUGE_VAL, HUGE_VAL}, kmax2[2] = {-HUGE_VAL, -HUGE_VAL};
  for (int j = 0; j < count; ++j) {
    kmin2[j & 1] = std::min(kmin2[j & 1], raw[j].key);
    kmax2[j & 1] = std::max(kmax2[j & 1], raw[j].key);
  }
  const double kmin = std::min(kmin2[0], kmin2[1]), kmax = std::max(kmax2[0], kmax2[1]);
  // Monotone in the key: the buckets' order is the keys' order. Four buckets per particle: the
  // band's particles crowd towards its inner edge, and each pair that lands in one bucket out of
  // order costs the insertion sort a move.
  const int buckets = std::min(4 * count, static_cast<int>(scratch->bucket_start_.size()) - 1);
  const double scale = kmax > kmin ? buckets / (kmax - kmin) : 0.0;
  int* start = scratch->bucket_start_.data();
  std::fill(start, start + buckets + 1, 0);
  for (BandEntry& e : raw) {
    e.bucket = std::min(buckets - 1, static_cast<int>((e.key - kmin) * scale));
    ++start[e.bucket + 1];
  }
  for (int b = 0; b < buckets; ++b) start[b + 1] += start[b];
  for (const BandEntry& e : raw) band[start[e.bucket]++] = e;
  for (int j = 1; j < count; ++j) {
    const BandEntry e = band[j];
    int k = j;
    for (; k > 0 && e < band[k - 1]; --k) band[k] = band[k - 1];
    band[k] = e;
  }
}

CircularQuantileScratch::CircularQuantileScratch(int n)
    : key_(n),
      lo_(n),
      hi_(n),
      wk_(n),
      bin_(n),
      idx_(n + 1),
      idx_lo_(n + 1),
      idx_hi_(n + 1),
      band_(n) {
  pairs_.reserve(n);
  band_pairs_.reserve(n);
  band_unsorted_.reserve(n);
  bucket_start_.assign(n + 1, 0);
}

void WeightedCircularQuantiles(const double* c, const double* s, const double* w, int n, double cm,
                               double sm, double negligible, const double* probs, int np,
                               double* out, CircularQuantileScratch* scratch) {
  constexpr int kBins = CircularQuantileScratch::kBins;
  std::vector<double>& key = scratch->key_;
  std::vector<int>& bin = scratch->bin_;
  std::array<double, kBins>& mass = scratch->mass_;
  double kept = 0.0, kmin = HUGE_VAL, kmax = -HUGE_VAL;
  DiamondKeys(c, s, w, n, cm, sm, negligible, key.data(), scratch->lo_.data(), scratch->hi_.data(),
              scratch->wk_.data());
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

namespace {

// The scratch arrays of the band passes.
struct BandBuffers {
  long long* band;  // per particle: 1 lower band, 2 upper band, 0 neither
  int* either;      // the particles in a band (n + 1)
  int* lower;       // those of the lower band (n + 1)
  int* upper;       // those of the upper band (n + 1)
};

// The band pass for the lower and upper bands, and the gathers of their particles.
struct BandState {
  Band lower{0.0, 0.0}, upper{0.0, 0.0};  // those of the last pass
  BandMass mass;
  int nl = 0, nu = 0;
  int sorted = 0;  // 1: the lower band's particles are in band_pairs_, 2: the upper's

  void Pass(const double* c, const double* s, const double* w, int n, double cm, double sm,
            double negligible, Band lo, Band hi, const BandBuffers& buf);
};

// cos and sin of the band's edges; sin(pi) is not 0 in doubles, and a band out to pi must reach
// the end of the circle.
BandEdges Edges(Band b) {
  const double outer = std::min(b.outer, M_PI);
  return {std::cos(b.inner), std::sin(b.inner), std::cos(outer),
          outer == M_PI ? 0.0 : std::sin(outer)};
}

void BandState::Pass(const double* c, const double* s, const double* w, int n, double cm, double sm,
                     double negligible, Band lo, Band hi, const BandBuffers& buf) {
  BandPass(c, s, w, n, Forms(cm, sm, negligible, Edges(lo), Edges(hi)), buf.band, &mass);
  // Branch-free gathers (which particles are in a band is unpredictable): first those in
  // either band (one store per particle), then the few of them split by band.
  int ne = 0;
  for (int i = 0; i < n; ++i) {
    buf.either[ne] = i;
    ne += buf.band[i] != 0;
  }
  nl = 0;
  nu = 0;
  for (int j = 0; j < ne; ++j) {
    const int i = buf.either[j];
    buf.lower[nl] = i;
    buf.upper[nu] = i;
    nl += buf.band[i] == 1;
    nu += buf.band[i] == 2;
  }
  lower = lo;
  upper = hi;
  sorted = 0;
}

// Band passes a quantile may take before the histogram: the guess, and two moves.
constexpr int kBandAttempts = 3;

}  // namespace

int WeightedCircularTailQuantiles(const double* c, const double* s, const double* w, int n,
                                  double cm, double sm, double negligible, double inner,
                                  double outer, const double* probs, int np, double* out,
                                  CircularQuantileScratch* scratch) {
  int fallbacks = 0;
  const Particles p{c, s, w, cm, sm};
  BandState state;
  const BandBuffers buf{scratch->band_.data(), scratch->idx_.data(), scratch->idx_lo_.data(),
                        scratch->idx_hi_.data()};
  const Band guess{inner, std::min(outer, M_PI)};
  Band lo = guess, hi = guess;  // the next pass's bands: one pass serves both tails' guesses
  for (int k = 0; k < np; ++k) {
    const bool low = probs[k] <= 0.5;
    (low ? lo : hi) = guess;
    bool done = false;
    for (int attempt = 0; attempt < kBandAttempts && !done; ++attempt) {
      const Band& band = low ? lo : hi;
      // negligible > 0: every kept particle has mass, so mass beyond a band means particles.
      if (!band.ok() || !(negligible > 0.0)) break;
      if (!(state.lower == lo && state.upper == hi)) {
        state.Pass(c, s, w, n, cm, sm, negligible, lo, hi, buf);
      }
      if (!(state.mass.kept > 0.0)) break;
      const int side = low ? 1 : 2;
      if (state.sorted != side) {
        const double centre = 0.5 * (band.inner + std::min(band.outer, M_PI));
        SortBand(c, s, w, low ? buf.lower : buf.upper, low ? state.nl : state.nu, cm, sm,
                 low ? -centre : centre, 0.5 * (std::min(band.outer, M_PI) - band.inner), scratch);
        state.sorted = side;
      }
      const double target = probs[k] * state.mass.kept;
      const Walk walk =
          low ? LowerWalk(p, scratch->band_pairs_, state.mass.lower_deep,
                          state.mass.lower_deep > 0.0, target, lo.inner, lo.outer, &out[k])
              : UpperWalk(p, scratch->band_pairs_, state.mass.upper_deep,
                          state.mass.upper_deep > 0.0, state.mass.kept, target, hi.inner, hi.outer,
                          &out[k]);
      done = walk == Walk::kFound;
      if (!done) (low ? lo : hi) = band.Moved(walk);
    }
    if (!done) {
      ++fallbacks;
      WeightedCircularQuantiles(c, s, w, n, cm, sm, negligible, &probs[k], 1, &out[k], scratch);
    }
  }
  return fallbacks;
}

}  // namespace flexbench::pf
