#include "estimators/pf/particle_moments.h"

#include <algorithm>
#include <cstdint>
#include <cstring>

#include "estimators/pf/particle_loop.h"

namespace flexbench::pf {
namespace {

// Four lanes as one GCC vector: the lane sums stay in registers (written as scalar lanes, GCC
// shuffled them through the stack). The baseline clone splits it into two SSE2 halves, lane by
// lane the same arithmetic.
typedef double V4 __attribute__((vector_size(32)));

inline V4 Load4(const double* p) {
  V4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

inline void Store4(double* p, V4 v) { std::memcpy(p, &v, sizeof v); }

inline double LaneSum(V4 v) { return (v[0] + v[1]) + (v[2] + v[3]); }

inline double ExpNonPositiveInline(double x) {
  constexpr double kLog2e = 1.4426950408889634073599;
  // ln 2 split so that k * kLn2Hi is exact for |k| <= 1024 (Cephes).
  constexpr double kLn2Hi = 6.93145751953125e-1;
  constexpr double kLn2Lo = 1.42860682030941723212e-6;
  constexpr double kP[3] = {1.26177193074810590878e-4, 3.02994407707441961300e-2,
                            9.99999999999999999910e-1};
  constexpr double kQ[4] = {3.00198505138664455042e-6, 2.52448340349684104192e-3,
                            2.27265548208155028766e-1, 2.00000000000000000009e0};
  // Adding 1.5 * 2^52 rounds to an integer and leaves it in the low mantissa bits.
  constexpr double kShift = 6755399441055744.0;
  const bool underflow = !(x >= -708.0);  // also -inf and NaN
  const double xc = underflow ? 0.0 : x;
  const double shifted = kLog2e * xc + kShift;
  const double k = shifted - kShift;
  const double r = (xc - k * kLn2Hi) - k * kLn2Lo;
  const double rr = r * r;
  const double px = r * ((kP[0] * rr + kP[1]) * rr + kP[2]);
  const double qx = ((kQ[0] * rr + kQ[1]) * rr + kQ[2]) * rr + kQ[3];
  const double e = 1.0 + 2.0 * (px / (qx - px));
  std::int64_t bits;
  std::memcpy(&bits, &shifted, sizeof bits);
  std::int64_t shift_bits;
  std::memcpy(&shift_bits, &kShift, sizeof shift_bits);
  // k in [-1022, 0]: 2^k is a normal double.
  const std::int64_t scale_bits = (bits - shift_bits + 1023) << 52;
  double scale;
  std::memcpy(&scale, &scale_bits, sizeof scale);
  return underflow ? 0.0 : e * scale;
}

// Weights below e^-345 (1e-150) are set to 0: next to the largest, 1, no sum here can see them
// (nor a quantile or covariance: they are far below the negligible weight), and their squares
// and products would be subnormal, each a microcode assist of a hundred cycles (a filter whose
// position readings are sharp has many such particles).
constexpr double kFlushLogWeight = -345.0;

inline double Weight(double lw) {
  const double e = ExpNonPositiveInline(lw);
  return lw < kFlushLogWeight ? 0.0 : e;
}

// e_i = exp(lw_i) into w, and sum e, sum e^2 in four fixed lanes (lane i % 4).
FLEXBENCH_PARTICLE_LOOP void ExpAndSums(const double* __restrict lw, int n, double* __restrict w,
                                        double* sum, double* sum2) {
  V4 s4 = {0.0, 0.0, 0.0, 0.0};
  V4 q4 = {0.0, 0.0, 0.0, 0.0};
  const int n4 = n & ~3;
  for (int i = 0; i < n4; i += 4) {
    V4 e;
    for (int l = 0; l < 4; ++l) e[l] = Weight(lw[i + l]);
    Store4(w + i, e);
    s4 += e;
    q4 += e * e;
  }
  for (int i = n4; i < n; ++i) {
    const double e = Weight(lw[i]);
    w[i] = e;
    s4[i & 3] += e;
    q4[i & 3] += e * e;
  }
  *sum = LaneSum(s4);
  *sum2 = LaneSum(q4);
}

FLEXBENCH_PARTICLE_LOOP void Scale(double* __restrict w, int n, double f) {
  for (int i = 0; i < n; ++i) w[i] *= f;
}

}  // namespace

double NormalisedWeights(const double* log_w, int n, double* w) {
  double sum = 0.0, sum2 = 0.0;
  ExpAndSums(log_w, n, w, &sum, &sum2);
  Scale(w, n, 1.0 / sum);
  return sum * sum / sum2;
}

FLEXBENCH_PARTICLE_LOOP void WeightedResultant(const double* __restrict c,
                                               const double* __restrict s,
                                               const double* __restrict w, int n, double* sc,
                                               double* ss) {
  V4 c4 = {0.0, 0.0, 0.0, 0.0};
  V4 s4 = {0.0, 0.0, 0.0, 0.0};
  const int n4 = n & ~3;
  for (int i = 0; i < n4; i += 4) {
    const V4 wi = Load4(w + i);
    c4 += wi * Load4(c + i);
    s4 += wi * Load4(s + i);
  }
  for (int i = n4; i < n; ++i) {
    c4[i & 3] += w[i] * c[i];
    s4[i & 3] += w[i] * s[i];
  }
  *sc = LaneSum(c4);
  *ss = LaneSum(s4);
}

KeptParticles::KeptParticles(int capacity) : idx_(capacity + 4, 0), w_(capacity + 4, 0.0) {}

void KeptParticles::Select(const double* w, int n, double negligible) {
  int* idx = idx_.data();
  double* wk = w_.data();
  // Branch-free (which particles are kept is unpredictable): each particle is written at its
  // lane's next position, which only a kept one advances; an unkept one is overwritten by the
  // next kept one of its lane or by the padding. The counts stay in registers.
  int count[4] = {0, 0, 0, 0};
  const auto put = [&](int i, int l, int& c) {
    const int at = 4 * c + l;
    idx[at] = i;
    wk[at] = w[i];
    c += w[i] >= negligible;
  };
  int c0 = 0, c1 = 0, c2 = 0, c3 = 0;
  int i = 0;
  for (; i + 4 <= n; i += 4) {
    put(i, 0, c0);
    put(i + 1, 1, c1);
    put(i + 2, 2, c2);
    put(i + 3, 3, c3);
  }
  if (i < n) put(i, 0, c0);
  if (i + 1 < n) put(i + 1, 1, c1);
  if (i + 2 < n) put(i + 2, 2, c2);
  count[0] = c0;
  count[1] = c1;
  count[2] = c2;
  count[3] = c3;
  const int rows = std::max(std::max(count[0], count[1]), std::max(count[2], count[3]));
  for (int l = 0; l < 4; ++l) {
    for (int r = count[l]; r < rows; ++r) {
      idx[4 * r + l] = 0;
      wk[4 * r + l] = 0.0;
    }
  }
  size_ = 4 * rows;
}

void KeptParticles::Gather(const double* __restrict a, const double* __restrict b,
                           double* __restrict out_a, double* __restrict out_b) const {
  const int* __restrict idx = idx_.data();
  for (int p = 0; p < size_; ++p) {
    out_a[p] = a[idx[p]];
    out_b[p] = b[idx[p]];
  }
}

namespace internal {
double ExpNonPositive(double x) { return ExpNonPositiveInline(x); }
}  // namespace internal

}  // namespace flexbench::pf
