// Inline sine and cosine of one argument, for the per-joint trigonometry of the kinematics.
//
// Why not std::sin/std::cos: the libm call is opaque to the optimiser, so in the forward
// kinematics (one sincos per joint, then small matrix products) it splits the loop into pieces
// that cannot overlap, a cost bench_kinematics shows in a 7-DoF FK with covariance. This is
// fdlibm's kernel (FreeBSD k_sin.c / k_cos.c, minimax polynomials on
// [-pi/4, pi/4], error < 1 ulp there) after a Cody-Waite reduction by pi/2 with a 33-bit split of
// pi/2 (e_rem_pio2.c's first step; the product n * pi/2_hi is exact for |n| < 2^20). The tail of
// the reduced argument is dropped, so outside [-pi/4, pi/4] the error is absolute, <= 2^-52, not
// relative (sin(pi) comes out ~1e-16 away from libm's 1.2246e-16; the kinematics adds it to
// terms of order 1). tests/unit/lie/sincos_test.cc checks both bounds. Beyond kSinCosMaxArg (or
// for NaN/inf) it falls back to libm.
#pragma once

#include <cmath>
#include <cstring>

namespace flexbench::lie {

namespace internal {
// Four doubles in one GCC vector (and its 64-bit integer lanes). Plain vector-extension
// arithmetic is lane-wise IEEE, so a 4-wide (AVX2) and a 2x2-wide (SSE2) build of the same source
// give the same bits (-ffp-contract=off keeps multiplies and adds apart).
typedef double V4 __attribute__((vector_size(32)));
typedef long long V4i __attribute__((vector_size(32)));
}  // namespace internal

inline constexpr double kSinCosMaxArg = 1.0e5;

inline void SinCos(double x, double* s, double* c) {
  if (!(std::fabs(x) < kSinCosMaxArg)) {
    *s = std::sin(x);
    *c = std::cos(x);
    return;
  }
  constexpr double kInvPio2 = 6.36619772367581382433e-01;
  constexpr double kPio2Hi = 1.57079632673412561417e+00;  // first 33 bits of pi/2
  constexpr double kPio2Lo = 6.07710050650619224932e-11;  // pi/2 - kPio2Hi
  // Round to nearest with the 1.5 * 2^52 shift: exact for |x * 2/pi| < 2^51, no SSE4.1 needed.
  constexpr double kShift = 6755399441055744.0;
  const double fn = (x * kInvPio2 + kShift) - kShift;
  const int n = static_cast<int>(fn);
  const double r = (x - fn * kPio2Hi) - fn * kPio2Lo;

  const double z = r * r;
  // k_sin.c
  constexpr double S1 = -1.66666666666666324348e-01;
  constexpr double S2 = 8.33333333332248946124e-03;
  constexpr double S3 = -1.98412698298579493134e-04;
  constexpr double S4 = 2.75573137070700676789e-06;
  constexpr double S5 = -2.50507602534068634195e-08;
  constexpr double S6 = 1.58969099521155010221e-10;
  const double sr = S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)));
  const double sin_r = r + (z * r) * (S1 + z * sr);
  // k_cos.c
  constexpr double C1 = 4.16666666666666019037e-02;
  constexpr double C2 = -1.38888888888741095749e-03;
  constexpr double C3 = 2.48015872894767294178e-05;
  constexpr double C4 = -2.75573143513906633035e-07;
  constexpr double C5 = 2.08757232129817482790e-09;
  constexpr double C6 = -1.13596475577881948265e-11;
  const double w = z * z;
  const double cr = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
  const double hz = 0.5 * z;
  const double one_minus_hz = 1.0 - hz;
  const double cos_r = one_minus_hz + (((1.0 - one_minus_hz) - hz) + z * cr);

  switch (n & 3) {
    case 0:
      *s = sin_r;
      *c = cos_r;
      break;
    case 1:
      *s = cos_r;
      *c = -sin_r;
      break;
    case 2:
      *s = -sin_r;
      *c = -cos_r;
      break;
    default:
      *s = -cos_r;
      *c = sin_r;
      break;
  }
}

namespace internal {

// SinCos of four arguments, lane by lane the same operations (so the same bits) as SinCos: for
// the kinematics' joints, whose scalar calls are ~70 cycles of dependent arithmetic each (a
// seventh of a 7-DoF FK with covariance on the baseline build). The quadrant's switch becomes
// bit selects on the rounding shift's low mantissa bits (n mod 4), which SSE2 can do; lanes at or
// beyond kSinCosMaxArg (or NaN) take the scalar SinCos and its libm fallback.
inline __attribute__((always_inline)) void SinCos4(V4 x, V4* s, V4* c) {
  constexpr double kInvPio2 = 6.36619772367581382433e-01;
  constexpr double kPio2Hi = 1.57079632673412561417e+00;
  constexpr double kPio2Lo = 6.07710050650619224932e-11;
  constexpr double kShift = 6755399441055744.0;
  const V4 shifted = x * kInvPio2 + kShift;
  const V4 fn = shifted - kShift;
  const V4 r = (x - fn * kPio2Hi) - fn * kPio2Lo;
  const V4 z = r * r;
  constexpr double S1 = -1.66666666666666324348e-01;
  constexpr double S2 = 8.33333333332248946124e-03;
  constexpr double S3 = -1.98412698298579493134e-04;
  constexpr double S4 = 2.75573137070700676789e-06;
  constexpr double S5 = -2.50507602534068634195e-08;
  constexpr double S6 = 1.58969099521155010221e-10;
  const V4 sr = S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)));
  const V4 sin_r = r + (z * r) * (S1 + z * sr);
  constexpr double C1 = 4.16666666666666019037e-02;
  constexpr double C2 = -1.38888888888741095749e-03;
  constexpr double C3 = 2.48015872894767294178e-05;
  constexpr double C4 = -2.75573143513906633035e-07;
  constexpr double C5 = 2.08757232129817482790e-09;
  constexpr double C6 = -1.13596475577881948265e-11;
  const V4 w = z * z;
  const V4 cr = z * (C1 + z * (C2 + z * C3)) + w * w * (C4 + z * (C5 + z * C6));
  const V4 hz = 0.5 * z;
  const V4 one_minus_hz = 1.0 - hz;
  const V4 cos_r = one_minus_hz + (((1.0 - one_minus_hz) - hz) + z * cr);
  // n mod 4 sits in the shifted value's low mantissa bits (1.5 * 2^52 is a multiple of 4).
  V4i n, sb, cb;
  std::memcpy(&n, &shifted, sizeof n);
  std::memcpy(&sb, &sin_r, sizeof sb);
  std::memcpy(&cb, &cos_r, sizeof cb);
  const V4i odd = -(n & 1);  // all ones in quadrants 1 and 3: sine and cosine swap
  const V4i s_bits = ((odd & cb) | (~odd & sb)) ^ ((n & 2) << 62);        // negative in 2, 3
  const V4i c_bits = ((odd & sb) | (~odd & cb)) ^ (((n + 1) & 2) << 62);  // negative in 1, 2
  std::memcpy(s, &s_bits, sizeof *s);
  std::memcpy(c, &c_bits, sizeof *c);
  for (int l = 0; l < 4; ++l) {
    if (!(std::fabs(x[l]) < kSinCosMaxArg)) {
      double sl, cl;
      SinCos(x[l], &sl, &cl);
      (*s)[l] = sl;
      (*c)[l] = cl;
    }
  }
}

}  // namespace internal

}  // namespace flexbench::lie
