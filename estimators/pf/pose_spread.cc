#include "estimators/pf/pose_spread.h"

#include <algorithm>
#include <cmath>

#include "estimators/pf/particle_loop.h"

namespace flexbench::pf {
namespace {

// Kept positions per pass (their logs stay in L1 cache).
constexpr int kChunk = 256;
// Past this cosine the skew part no longer carries the axis accurately (as lie::SO3Log).
constexpr double kNearPiCos = -0.7;
constexpr double kTinyAngle = 1e-4;  // lie/so3.cc: theta / sin(theta) by its series below
constexpr double kSmallAngle = 0.2;  // lie/so3.cc: Jl^-1's coefficient by its series below

// Below pi/4 atan(y / x); above, pi/2 - atan(x / y), the ratio t in (-1, 1] either way (y and x
// are never both zero for a rotation's sin and cos). Cephes' atan: t + t z P(z) / Q(z), z = t^2,
// on |t| <= 0.66; above, pi/4 + atan((|t| - 1) / (|t| + 1)), that argument formed from y and x
// directly: one division, not two (a 4-wide division occupies the divider for about 8 cycles).
// Both branches are computed and one selected, never a branch: the particle loops vectorise.
inline double Atan2Upper(double y, double x) {
  constexpr double kP[5] = {-8.750608600031904122785e-1, -1.615753718733365076637e1,
                            -7.500855792314704667340e1, -1.228866684490136173410e2,
                            -6.485021904942025371773e1};
  constexpr double kQ[5] = {2.485846490142306297962e1, 1.650270098316988542046e2,
                            4.328810604912902668951e2, 4.853903996359136964868e2,
                            1.945506571482613964425e2};
  constexpr double kMoreBits = 6.123233995736765886130e-17;  // pi/2 - double(pi/2)
  const bool steep = y > x;
  const double num = steep ? x : y;
  const double den = steep ? y : x;  // > 0
  const double an = std::abs(num);
  const bool reduce = an > 0.66 * den;
  const double xr = (reduce ? an - den : an) / (reduce ? an + den : den);
  const double z = xr * xr;
  const double p = (((kP[0] * z + kP[1]) * z + kP[2]) * z + kP[3]) * z + kP[4];
  const double q = ((((z + kQ[0]) * z + kQ[1]) * z + kQ[2]) * z + kQ[3]) * z + kQ[4];
  const double r = xr * (z * p / q) + xr;
  const double shifted = M_PI_4 + (r + 0.5 * kMoreBits);
  const double a = std::copysign(reduce ? shifted : r, num);
  const double complement = M_PI_2 - a;
  return steep ? complement : a;
}

// xi = Log(T_mean^-1 T_i) of the particles idx[0, m) into xi[6][] (0 for padding, weight 0:
// never 0 * inf), and the cosine of each
// one's rotation angle into cos_angle (1 for padding; those at or below kNearPiCos are the
// caller's to fix). Every alternative is computed and selected, no branch and no call: the loop
// vectorises.
FLEXBENCH_PARTICLE_LOOP void LogBlock(const BatchKinematics& fk, int k, const int* __restrict idx,
                                      const Mat3& Rm, const Vec3& tm, const double* __restrict w,
                                      int m, double (*__restrict xi)[kChunk],
                                      double* __restrict cos_angle) {
  // Plain locals, not arrays of pointers: the vectoriser needs to see every load's address.
  const double* __restrict R00 = fk.R(k, 0, 0);
  const double* __restrict R01 = fk.R(k, 0, 1);
  const double* __restrict R02 = fk.R(k, 0, 2);
  const double* __restrict R10 = fk.R(k, 1, 0);
  const double* __restrict R11 = fk.R(k, 1, 1);
  const double* __restrict R12 = fk.R(k, 1, 2);
  const double* __restrict R20 = fk.R(k, 2, 0);
  const double* __restrict R21 = fk.R(k, 2, 1);
  const double* __restrict R22 = fk.R(k, 2, 2);
  const double* __restrict t0 = fk.t(k, 0);
  const double* __restrict t1 = fk.t(k, 1);
  const double* __restrict t2 = fk.t(k, 2);
  // M = Rm^T.
  const double M00 = Rm(0, 0), M01 = Rm(1, 0), M02 = Rm(2, 0);
  const double M10 = Rm(0, 1), M11 = Rm(1, 1), M12 = Rm(2, 1);
  const double M20 = Rm(0, 2), M21 = Rm(1, 2), M22 = Rm(2, 2);
  const double tm0 = tm[0], tm1 = tm[1], tm2 = tm[2];
  for (int p = 0; p < m; ++p) {
    const int i = idx[p];
    // dR = Rm^T R_i (only the entries the log needs), dt = Rm^T (t_i - tm).
    const double d00 = M00 * R00[i] + M01 * R10[i] + M02 * R20[i];
    const double d11 = M10 * R01[i] + M11 * R11[i] + M12 * R21[i];
    const double d22 = M20 * R02[i] + M21 * R12[i] + M22 * R22[i];
    const double d01 = M00 * R01[i] + M01 * R11[i] + M02 * R21[i];
    const double d10 = M10 * R00[i] + M11 * R10[i] + M12 * R20[i];
    const double d02 = M00 * R02[i] + M01 * R12[i] + M02 * R22[i];
    const double d20 = M20 * R00[i] + M21 * R10[i] + M22 * R20[i];
    const double d12 = M10 * R02[i] + M11 * R12[i] + M12 * R22[i];
    const double d21 = M20 * R01[i] + M21 * R11[i] + M22 * R21[i];
    const double p0 = t0[i] - tm0, p1 = t1[i] - tm1, p2 = t2[i] - tm2;
    const double v0 = M00 * p0 + M01 * p1 + M02 * p2;
    const double v1 = M10 * p0 + M11 * p1 + M12 * p2;
    const double v2 = M20 * p0 + M21 * p1 + M22 * p2;
    // SO3Log: w = sin(x) u, x = atan2(|w|, cos x).
    const double w0 = 0.5 * (d21 - d12);
    const double w1 = 0.5 * (d02 - d20);
    const double w2 = 0.5 * (d10 - d01);
    const double s = std::sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    const double c = std::min(1.0, std::max(-1.0, 0.5 * (d00 + d11 + d22 - 1.0)));
    const double x = Atan2Upper(s, std::max(c, kNearPiCos));
    const double x2 = x * x;
    const double s_safe = std::max(s, 1e-300), x_safe = std::max(x, 1e-150);
    // Products, not quotients: inv_xs = 1 / (x s) gives x / s, 1 / x and cot(x/2) / x below
    // with one division (LogBlock had nine; with three it is bound by its ~200 other operations).
    const double tiny_series = 1.0 + x2 * (1.0 / 6.0) * (1.0 + 7.0 / 60.0 * x2);
    const double inv_xs = 1.0 / (x_safe * s_safe);
    const double ratio = x2 * inv_xs;
    const double x_over_s = x < kTinyAngle ? tiny_series : ratio;
    const double o0 = x_over_s * w0, o1 = x_over_s * w1, o2 = x_over_s * w2;
    // Jl^-1(o) v = v - o x v / 2 + dcoef o x (o x v); dcoef = 1/x^2 - cot(x/2) / (2x) with
    // cot(x/2) = (1 + cos x) / sin x.
    const double small_series =
        1.0 / 12.0 + x2 * (1.0 / 720.0 +
                           x2 * (1.0 / 30240.0 + x2 * (1.0 / 1209600.0 + x2 * (1.0 / 47900160.0))));
    const double inv_x = s_safe * inv_xs;
    const double closed = inv_x * inv_x - 0.5 * (1.0 + c) * inv_xs;
    const double dcoef = x < kSmallAngle ? small_series : closed;
    const double a0 = o1 * v2 - o2 * v1, a1 = o2 * v0 - o0 * v2, a2 = o0 * v1 - o1 * v0;
    const double b0 = o1 * a2 - o2 * a1, b1 = o2 * a0 - o0 * a2, b2 = o0 * a1 - o1 * a0;
    const bool keep = w[p] > 0.0;  // not a lane's padding
    cos_angle[p] = keep ? c : 1.0;
    xi[kTransIdx][p] = keep ? v0 - 0.5 * a0 + dcoef * b0 : 0.0;
    xi[kTransIdx + 1][p] = keep ? v1 - 0.5 * a1 + dcoef * b1 : 0.0;
    xi[kTransIdx + 2][p] = keep ? v2 - 0.5 * a2 + dcoef * b2 : 0.0;
    xi[kRotIdx][p] = keep ? o0 : 0.0;
    xi[kRotIdx + 1][p] = keep ? o1 : 0.0;
    xi[kRotIdx + 2][p] = keep ? o2 : 0.0;
  }
}

// acc[e][l] += w_i xi_a xi_b over the block, entry e = (a, b) of the upper triangle, particle i
// in lane l = i % 4: four fixed partial sums, so the vector and the scalar clone add in the same
// order. m is a multiple of 4 (KeptParticles pads with zero weights).
FLEXBENCH_PARTICLE_LOOP void AccumulateBlock(const double (*__restrict xi)[kChunk],
                                             const double* __restrict w, int m,
                                             double (*__restrict acc)[4]) {
  for (int i = 0; i < m; i += 4) {
    double wx[6][4];
    for (int a = 0; a < 6; ++a) {
      for (int l = 0; l < 4; ++l) wx[a][l] = w[i + l] * xi[a][i + l];
    }
    int e = 0;
    for (int a = 0; a < 6; ++a) {
      for (int b = a; b < 6; ++b, ++e) {
        for (int l = 0; l < 4; ++l) acc[e][l] += wx[a][l] * xi[b][i + l];
      }
    }
  }
}

}  // namespace

namespace internal {

double Atan2UpperHalf(double y, double x) { return Atan2Upper(y, x); }

}  // namespace internal

void PoseSpread(const BatchKinematics& fk, int k, const lie::SE3& T_mean, const KeptParticles& kept,
                Mat6* cov) {
  const Mat3& Rm = T_mean.rotation();
  const Vec3& tm = T_mean.translation();
  const lie::SE3 T_mean_inv = T_mean.Inverse();
  alignas(64) double xi[6][kChunk];
  alignas(64) double cos_angle[kChunk];
  double acc[21][4] = {};
  for (int b = 0; b < kept.size(); b += kChunk) {
    const int m = std::min(kChunk, kept.size() - b);  // a multiple of 4
    const int* idx = kept.index() + b;
    const double* w = kept.weight() + b;
    LogBlock(fk, k, idx, Rm, tm, w, m, xi, cos_angle);
    for (int p = 0; p < m; ++p) {
      if (cos_angle[p] <= kNearPiCos) {
        const Vec6 x = (T_mean_inv * fk.Pose(k, idx[p])).Log();
        for (int r = 0; r < 6; ++r) xi[r][p] = x[r];
      }
    }
    AccumulateBlock(xi, w, m, acc);
  }
  int e = 0;
  for (int a = 0; a < 6; ++a) {
    for (int b = a; b < 6; ++b, ++e) {
      const double sum = (acc[e][0] + acc[e][1]) + (acc[e][2] + acc[e][3]);
      (*cov)(a, b) = sum;
      (*cov)(b, a) = sum;
    }
  }
}

}  // namespace flexbench::pf
