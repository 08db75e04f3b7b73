// SE(3) as a small value type (rotation + translation, 12 doubles, no alignment requirement).
//
// Conventions (conventions.h, PPOE paper sec. III):
// - Tangent vectors xi = [rho; theta] (translation first), hat(xi) = [[theta]x, rho; 0, 0] [PPOE
// eq. 2].
// - Right (local) perturbations: X = Xbar * Exp(xi); "X (+) xi" = X * Exp(xi) and
//   "Y (-) X" = Log(X^-1 * Y). Covariances live in the tangent space at the mean.
// - Ad_X = [[R, [t]x R], [0, R]] [PPOE eq. 7] maps local tangent vectors at X to global ones at the
//   identity: Exp(Ad_X xi) * X = X * Exp(xi) [PPOE eqs. 5-6].
// - Jacobians follow manif's naming J_out_in and are right Jacobians:
//   f(X (+) d) = f(X) (+) (J_f_X * d) to first order.
// - An SE3 T_a_b is the pose of frame b in frame a; it maps points p_b to p_a = T_a_b * p_b.
#pragma once

#include <cstring>

#include "estimators/conventions.h"
#include "estimators/lie/sincos.h"
#include "estimators/lie/so3.h"

namespace flexbench::lie {

class SE3 {
 public:
  // Identity.
  SE3() : R_(Mat3::Identity()), t_(Vec3::Zero()) {}
  // R must be a rotation matrix; it is not re-orthonormalised here (see SO3Project).
  SE3(const Mat3& R, const Vec3& t) : R_(R), t_(t) {}
  SE3(const Quat& q, const Vec3& t) : R_(q.normalized().toRotationMatrix()), t_(t) {}

  static SE3 Identity() { return SE3(); }
  static SE3 Translation(const Vec3& t) { return SE3(Mat3::Identity(), t); }
  static SE3 Rotation(const Mat3& R) { return SE3(R, Vec3::Zero()); }
  // From a 4x4 homogeneous matrix [[R, t], [0, 1]]; the bottom row is not checked.
  static SE3 FromMatrix(const Mat4& T) {
    return SE3(T.topLeftCorner<3, 3>(), T.topRightCorner<3, 1>());
  }

  // Exp(xi) = [[Exp(theta), Jl(theta) rho], [0, 1]]; J_X_xi = Jr(xi) if requested.
  static SE3 Exp(const Vec6& xi, Mat6* J_X_xi = nullptr);
  // Log(X) with |theta| in [0, pi]; J_xi_X = Jr^-1(xi) if requested.
  Vec6 Log(Mat6* J_xi_X = nullptr) const;

  const Mat3& rotation() const { return R_; }
  const Vec3& translation() const { return t_; }
  Mat3& rotation() { return R_; }
  Vec3& translation() { return t_; }
  Quat quaternion() const { return Quat(R_); }
  Mat4 Matrix() const { return MakeTransform(R_, t_); }

  // X^-1. J_Xinv_X = -Ad_X.
  SE3 Inverse(Mat6* J_Xinv_X = nullptr) const;
  // X * Y. J_XY_X = Ad_{Y^-1}, J_XY_Y = I.
  SE3 Compose(const SE3& Y, Mat6* J_XY_X = nullptr, Mat6* J_XY_Y = nullptr) const;
  SE3 operator*(const SE3& Y) const { return SE3(R_ * Y.R_, R_ * Y.t_ + t_); }
  // X^-1 * Y without forming X^-1. J_out_X = -Ad_{Y^-1 X}, J_out_Y = I.
  SE3 Between(const SE3& Y, Mat6* J_out_X = nullptr, Mat6* J_out_Y = nullptr) const;
  // Transforms a point: p_a = T_a_b * p_b. J_pa_X = [R, -R [p_b]x], J_pa_pb = R.
  Vec3 Act(const Vec3& p_b, Eigen::Matrix<double, 3, 6>* J_pa_X = nullptr,
           Mat3* J_pa_pb = nullptr) const;
  Vec3 operator*(const Vec3& p_b) const { return R_ * p_b + t_; }

  // X (+) xi = X * Exp(xi). J_out_X = Ad_{Exp(xi)^-1}, J_out_xi = Jr(xi).
  SE3 Plus(const Vec6& xi, Mat6* J_out_X = nullptr, Mat6* J_out_xi = nullptr) const;
  // this (-) X = Log(X^-1 * this). J_out_this = Jr^-1(out), J_out_X = -Jl^-1(out).
  Vec6 Minus(const SE3& X, Mat6* J_out_this = nullptr, Mat6* J_out_X = nullptr) const;

  // Ad_X = [[R, [t]x R], [0, R]] [PPOE eq. 7].
  Mat6 Adjoint() const;
  // Ad_X * xi without forming the 6x6 matrix.
  Vec6 AdjointTimes(const Vec6& xi) const;

  bool IsApprox(const SE3& other, double tol = 1e-12) const {
    return R_.isApprox(other.R_, tol) && (t_ - other.t_).norm() <= tol * (1.0 + t_.norm());
  }

 private:
  Mat3 R_;
  Vec3 t_;
};

// hat(xi) = [[theta]x, rho; 0, 0] [PPOE eq. 2] and its inverse.
Mat4 SE3Hat(const Vec6& xi);
Vec6 SE3Vee(const Mat4& xi_hat);

// The 6x6 "curly wedge" ad_xi = [[theta]x, [rho]x], [0, [theta]x]] [PPOE eq. 13]: the matrix of the
// Lie bracket, ad_a b = [a, b], with Ad_{Exp(xi)} = exp(ad_xi).
Mat6 CurlyWedge(const Vec6& xi);

// Barfoot's Q(rho, theta) block of the SE(3) left Jacobian; Jl = [[Jl3, Q], [0, Jl3]].
Mat3 SE3LeftJacobianQ(const Vec3& rho, const Vec3& theta);

// Exp(xi + d) ~= Exp(xi) * Exp(Jr(xi) d); Jr(xi) = Jl(-xi).
Mat6 SE3RightJacobian(const Vec6& xi);
// Exp(xi + d) ~= Exp(Jl(xi) d) * Exp(xi); Jl = [[Jl3, Q], [0, Jl3]], translation first.
Mat6 SE3LeftJacobian(const Vec6& xi);
// Inverses in closed form: [[J3^-1, -J3^-1 Q J3^-1], [0, J3^-1]].
Mat6 SE3RightJacobianInverse(const Vec6& xi);
Mat6 SE3LeftJacobianInverse(const Vec6& xi);

// Ad Sigma Ad^T for Ad = Ad_{(R, t)} and a symmetric Sigma, in 3x3 blocks: Ad = [[I, [t]x],
// [0, I]] diag(R, R), so the congruence is three block rotations (two of them symmetric) and a
// shear done with cross products: ~200 multiplications instead of ~430 for two dense 6x6
// products. Sigma must be symmetric (its lower-left block is not read); only the upper triangles
// of the symmetric blocks are computed and mirrored, so the result is exactly symmetric. `out`
// may alias Sigma. Inline because the kinematics calls it once per frame.
inline void CongruenceAdjoint(const Mat3& R, const Vec3& t, const Mat6& Sigma, Mat6* out) {
  Mat3 RA, RB, RC, B, C, D;
  RA.noalias() = R * Sigma.topLeftCorner<3, 3>();
  RB.noalias() = R * Sigma.topRightCorner<3, 3>();
  RC.noalias() = R * Sigma.bottomRightCorner<3, 3>();
  B.noalias() = RB * R.transpose();
  for (int i = 0; i < 3; ++i) {
    for (int j = i; j < 3; ++j) C(i, j) = C(j, i) = RC.row(i).dot(R.row(j));
  }
  // D = B + [t]x C, row by row.
  D.row(0) = B.row(0) + t[1] * C.row(2) - t[2] * C.row(1);
  D.row(1) = B.row(1) + t[2] * C.row(0) - t[0] * C.row(2);
  D.row(2) = B.row(2) + t[0] * C.row(1) - t[1] * C.row(0);
  // Top-left: R A R^T + [t]x B^T - D [t]x; column j of [t]x B^T is t x B.row(j), row i of
  // -D [t]x is t x D.row(i).
  Mat3 G;
  for (int j = 0; j < 3; ++j) G.col(j) = t.cross(Vec3(B.row(j).transpose()));
  for (int i = 0; i < 3; ++i) G.row(i) += t.cross(Vec3(D.row(i).transpose())).transpose();
  Mat6& o = *out;
  for (int i = 0; i < 3; ++i) {
    for (int j = i; j < 3; ++j) o(i, j) = o(j, i) = RA.row(i).dot(R.row(j)) + G(i, j);
  }
  o.topRightCorner<3, 3>() = D;
  o.bottomLeftCorner<3, 3>() = D.transpose();
  o.bottomRightCorner<3, 3>() = C;
}

inline Mat6 CongruenceAdjoint(const Mat3& R, const Vec3& t, const Mat6& Sigma) {
  Mat6 out;
  CongruenceAdjoint(R, t, Sigma, &out);
  return out;
}

// Sigma -> Ad_X Sigma Ad_X^T [PPOE eq. 10]: a local covariance at X expressed at the identity.
inline Mat6 TransformCovariance(const SE3& X, const Mat6& Sigma) {
  return CongruenceAdjoint(X.rotation(), X.translation(), Sigma);
}

namespace internal {

// V4 and V4i (lie/sincos.h): a 3x3 block is three V4 columns with lane 3 unused.

// The helpers below return 32-byte vectors; they are always inlined, so no call passes one
// (hence -Wno-psabi in CMakeLists.txt).

EIGEN_ALWAYS_INLINE V4 LoadV4(const double* p) {
  V4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
EIGEN_ALWAYS_INLINE void StoreV4(double* p, V4 v) { std::memcpy(p, &v, sizeof v); }
EIGEN_ALWAYS_INLINE V4 SplatV4(double x) { return V4{x, x, x, x}; }
// s x v in lanes 0..2 (the s vectors are zero in lane 3).
EIGEN_ALWAYS_INLINE V4 CrossV4(V4 s_yzx, V4 s_zxy, V4 v) {
  return s_yzx * __builtin_shuffle(v, V4i{2, 0, 1, 3}) -
         s_zxy * __builtin_shuffle(v, V4i{1, 2, 0, 3});
}
// R^T M R for a 3x3 M given by columns, R column-major in memory, Rt0..2 the rows of R.
EIGEN_ALWAYS_INLINE void RotateBlockV4(const double* R, V4 Rt0, V4 Rt1, V4 Rt2, const V4* M,
                                       V4* out) {
  V4 P[3];
  for (int j = 0; j < 3; ++j) {
    P[j] = M[0] * SplatV4(R[3 * j]) + M[1] * SplatV4(R[3 * j + 1]) + M[2] * SplatV4(R[3 * j + 2]);
  }
  for (int j = 0; j < 3; ++j) {
    out[j] = Rt0 * SplatV4(P[j][0]) + Rt1 * SplatV4(P[j][1]) + Rt2 * SplatV4(P[j][2]);
  }
}

// [[R^T, 0], [0, R^T]] [[I, -[t]x], [0, I]] (Sigma1 + Sigma2) (...)^T, Sigma2 optional, both
// symmetric with Sigma = [[A, B], [B^T, C]]: the congruence by Ad_{(R, t)^-1}, sheared in the
// input frame and then rotated, so neither R^T t nor a copy of R^T is needed. ~200
// multiplications instead of ~430 for two dense 6x6 products, done on 3-column blocks in 4-wide
// vectors; B^T is read from the lower-left block (hence "symmetric"). The output is exactly
// symmetric (the upper triangles are mirrored). `out` may alias either input: all of it is read
// before anything is written. Forced inline so that the kinematics' clones (x86-64-v3 and
// baseline) each get their own vector width.
EIGEN_ALWAYS_INLINE void TransportBlocks(const Mat3& R_in, const Vec3& t, const Mat6& Sigma1,
                                         const Mat6* Sigma2, Mat6* out) {
  const double* S1 = Sigma1.data();
  // Columns of A, B, B^T, C (C's last column is read one row early and shifted, so no load
  // runs past the end of the matrix).
  V4 A[3], B[3], Bt[3], C[3];
  for (int j = 0; j < 3; ++j) {
    A[j] = LoadV4(S1 + 6 * j);
    B[j] = LoadV4(S1 + 6 * (3 + j));
    Bt[j] = LoadV4(S1 + 6 * j + 3);
  }
  C[0] = LoadV4(S1 + 21);
  C[1] = LoadV4(S1 + 27);
  C[2] = __builtin_shuffle(LoadV4(S1 + 32), V4i{1, 2, 3, 0});
  if (Sigma2 != nullptr) {
    const double* S2 = Sigma2->data();
    for (int j = 0; j < 3; ++j) {
      A[j] += LoadV4(S2 + 6 * j);
      B[j] += LoadV4(S2 + 6 * (3 + j));
      Bt[j] += LoadV4(S2 + 6 * j + 3);
    }
    C[0] += LoadV4(S2 + 21);
    C[1] += LoadV4(S2 + 27);
    C[2] += __builtin_shuffle(LoadV4(S2 + 32), V4i{1, 2, 3, 0});
  }
  const double* R = R_in.data();
  const V4 Rt0{R[0], R[3], R[6], 0.0};
  const V4 Rt1{R[1], R[4], R[7], 0.0};
  const V4 Rt2{R[2], R[5], R[8], 0.0};
  // Shear with s = -t: D = B + [s]x C, G = A + [s]x B^T - D [s]x.
  const double s0 = -t[0], s1 = -t[1], s2 = -t[2];
  const V4 s_yzx{s1, s2, s0, 0.0};
  const V4 s_zxy{s2, s0, s1, 0.0};
  V4 D[3], G[3];
  for (int j = 0; j < 3; ++j) D[j] = B[j] + CrossV4(s_yzx, s_zxy, C[j]);
  G[0] = A[0] + CrossV4(s_yzx, s_zxy, Bt[0]) - (D[1] * SplatV4(s2) - D[2] * SplatV4(s1));
  G[1] = A[1] + CrossV4(s_yzx, s_zxy, Bt[1]) - (D[2] * SplatV4(s0) - D[0] * SplatV4(s2));
  G[2] = A[2] + CrossV4(s_yzx, s_zxy, Bt[2]) - (D[0] * SplatV4(s1) - D[1] * SplatV4(s0));
  V4 TL[3], TR[3], BR[3];
  RotateBlockV4(R, Rt0, Rt1, Rt2, G, TL);
  RotateBlockV4(R, Rt0, Rt1, Rt2, D, TR);
  RotateBlockV4(R, Rt0, Rt1, Rt2, C, BR);
  // Write column by column; each 4-lane store spills one double into the next rows, which a
  // later store overwrites.
  double* o = out->data();
  for (int j = 0; j < 3; ++j) {
    StoreV4(o + 6 * j, TL[j]);
    o[6 * j + 3] = TR[0][j];
    o[6 * j + 4] = TR[1][j];
    o[6 * j + 5] = TR[2][j];
  }
  StoreV4(o + 18, TR[0]);
  StoreV4(o + 21, BR[0]);
  StoreV4(o + 24, TR[1]);
  StoreV4(o + 27, BR[1]);
  StoreV4(o + 30, TR[2]);
  StoreV4(o + 32, __builtin_shuffle(BR[2], TR[2], V4i{6, 0, 1, 2}));
  // Mirror the upper triangles of the two symmetric blocks.
  o[1] = o[6];
  o[2] = o[12];
  o[8] = o[13];
  o[22] = o[27];
  o[23] = o[33];
  o[29] = o[34];
}

// TransportBlocks for CPUs without AVX2, in two-double (SSE2) vectors, every element by the same
// operations in the same order as its lane in the 4-wide code, so the bits agree (tested): a
// column of a 3x3 block is rows 0-1 in a V2 and row 2 alone, the lane shuffles are explicit
// unpacks. GCC's own split of the 4-wide code lowers those shuffles through memory, and a scalar
// twin is slower than these two lanes (bench_kinematics, ForwardKinematicsWithCovarianceBaseline).
// `out` may alias either input.
typedef double V2 __attribute__((vector_size(16)));

struct Col3 {
  V2 lo;      // rows 0, 1
  double hi;  // row 2
};

EIGEN_ALWAYS_INLINE Col3 LoadCol3(const double* p) {
  Col3 c;
  std::memcpy(&c.lo, p, sizeof c.lo);
  c.hi = p[2];
  return c;
}
EIGEN_ALWAYS_INLINE Col3 operator+(const Col3& a, const Col3& b) {
  return {a.lo + b.lo, a.hi + b.hi};
}
EIGEN_ALWAYS_INLINE Col3 operator-(const Col3& a, const Col3& b) {
  return {a.lo - b.lo, a.hi - b.hi};
}
EIGEN_ALWAYS_INLINE Col3 operator*(const Col3& a, double k) { return {a.lo * k, a.hi * k}; }
EIGEN_ALWAYS_INLINE double Row(const Col3& c, int i) { return i < 2 ? c.lo[i] : c.hi; }

// s x v, lane by lane as CrossV4: (s1 v2 - s2 v1, s2 v0 - s0 v2, s0 v1 - s1 v0).
EIGEN_ALWAYS_INLINE Col3 CrossCol3(V2 s_yz, V2 s_zx, double s0, double s1, const Col3& v) {
  const V2 v_zx = {v.hi, v.lo[0]};
  const V2 v_yz = {v.lo[1], v.hi};
  return {s_yz * v_zx - s_zx * v_yz, s0 * v.lo[1] - s1 * v.lo[0]};
}

// R^T M R as RotateBlockV4: P_j = M r_j by rows, then out_j = R^T P_j. Columns 0 and 1 of the
// second product are formed side by side ({out_0, out_1} row by row, R's entries broadcast as
// in the first), which needs 3 shuffles for the pair instead of 3 broadcasts per column.
// Returns out_0 and out_1 by rows (rows01[i] = {out_0[i], out_1[i]}) and out_2 as a column.
EIGEN_ALWAYS_INLINE void RotateBlockCol3(const double* R, const Col3* M, V2* rows01, Col3* out2) {
  Col3 P[3];
  for (int j = 0; j < 3; ++j) {
    const double r0 = R[3 * j], r1 = R[3 * j + 1], r2 = R[3 * j + 2];
    P[j] = {M[0].lo * r0 + M[1].lo * r1 + M[2].lo * r2, M[0].hi * r0 + M[1].hi * r1 + M[2].hi * r2};
  }
  // {P_0[k], P_1[k]} for k = 0, 1, 2.
  const V2 q0 = {P[0].lo[0], P[1].lo[0]};
  const V2 q1 = {P[0].lo[1], P[1].lo[1]};
  const V2 q2 = {P[0].hi, P[1].hi};
  for (int i = 0; i < 3; ++i) rows01[i] = q0 * R[3 * i] + q1 * R[3 * i + 1] + q2 * R[3 * i + 2];
  const V2 Rr0 = {R[0], R[3]}, Rr1 = {R[1], R[4]}, Rr2 = {R[2], R[5]};
  const double p0 = P[2].lo[0], p1 = P[2].lo[1], p2 = P[2].hi;
  *out2 = {Rr0 * p0 + Rr1 * p1 + Rr2 * p2, R[6] * p0 + R[7] * p1 + R[8] * p2};
}

EIGEN_ALWAYS_INLINE void TransportBlocksSse2(const Mat3& R_in, const Vec3& t, const Mat6& Sigma1,
                                             const Mat6* Sigma2, Mat6* out) {
  const double* S1 = Sigma1.data();
  Col3 A[3], B[3], Bt[3], C[3];
  for (int j = 0; j < 3; ++j) {
    A[j] = LoadCol3(S1 + 6 * j);
    B[j] = LoadCol3(S1 + 6 * (3 + j));
    Bt[j] = LoadCol3(S1 + 6 * j + 3);
    C[j] = LoadCol3(S1 + 6 * (3 + j) + 3);
  }
  if (Sigma2 != nullptr) {
    const double* S2 = Sigma2->data();
    for (int j = 0; j < 3; ++j) {
      A[j] = A[j] + LoadCol3(S2 + 6 * j);
      B[j] = B[j] + LoadCol3(S2 + 6 * (3 + j));
      Bt[j] = Bt[j] + LoadCol3(S2 + 6 * j + 3);
      C[j] = C[j] + LoadCol3(S2 + 6 * (3 + j) + 3);
    }
  }
  const double s0 = -t[0], s1 = -t[1], s2 = -t[2];
  const V2 s_yz = {s1, s2}, s_zx = {s2, s0};
  Col3 D[3], G[3];
  for (int j = 0; j < 3; ++j) D[j] = B[j] + CrossCol3(s_yz, s_zx, s0, s1, C[j]);
  G[0] = A[0] + CrossCol3(s_yz, s_zx, s0, s1, Bt[0]) - (D[1] * s2 - D[2] * s1);
  G[1] = A[1] + CrossCol3(s_yz, s_zx, s0, s1, Bt[1]) - (D[2] * s0 - D[0] * s2);
  G[2] = A[2] + CrossCol3(s_yz, s_zx, s0, s1, Bt[2]) - (D[0] * s1 - D[1] * s0);
  const double* R = R_in.data();
  V2 TL01[3], TR01[3], BR01[3];
  Col3 TL2, TR2, BR2;
  RotateBlockCol3(R, G, TL01, &TL2);
  RotateBlockCol3(R, D, TR01, &TR2);
  RotateBlockCol3(R, C, BR01, &BR2);
  // The upper triangles of the symmetric blocks, mirrored, as the vector code does; the
  // top-right block's rows 0-1 pairs are its transpose's contiguous (row 3 + j, columns i..).
  Mat6& o = *out;
  o(0, 0) = TL01[0][0];
  o(0, 1) = o(1, 0) = TL01[0][1];
  o(1, 1) = TL01[1][1];
  o(3, 3) = BR01[0][0];
  o(3, 4) = o(4, 3) = BR01[0][1];
  o(4, 4) = BR01[1][1];
  for (int i = 0; i < 3; ++i) {
    o(i, 2) = o(2, i) = Row(TL2, i);
    o(3 + i, 5) = o(5, 3 + i) = Row(BR2, i);
    // TR_j[i] -> o(i, 3 + j) and o(3 + j, i).
    o(i, 3) = o(3, i) = TR01[i][0];
    o(i, 4) = o(4, i) = TR01[i][1];
    o(i, 5) = o(5, i) = Row(TR2, i);
  }
}

}  // namespace internal

// Sigma -> Ad_{X^-1} Sigma Ad_{X^-1}^T: moves a local covariance at Y to the local tangent space
// at Y * X, exactly (Y Exp(xi) X = Y X Exp(Ad_{X^-1} xi)); the transport step of [PPOE eqs. 15,
// 18]. Sigma must be symmetric; `out` may alias it.
EIGEN_ALWAYS_INLINE void TransportCovariance(const SE3& X, const Mat6& Sigma, Mat6* out) {
  internal::TransportBlocks(X.rotation(), X.translation(), Sigma, nullptr, out);
}
inline Mat6 TransportCovariance(const SE3& X, const Mat6& Sigma) {
  Mat6 out;
  TransportCovariance(X, Sigma, &out);
  return out;
}

// Ad_{X^-1} (Sigma1 + Sigma2) Ad_{X^-1}^T without forming the sum; the hot step of [PPOE eq. 18].
EIGEN_ALWAYS_INLINE void TransportCovarianceSum(const SE3& X, const Mat6& Sigma1,
                                                const Mat6& Sigma2, Mat6* out) {
  internal::TransportBlocks(X.rotation(), X.translation(), Sigma1, &Sigma2, out);
}

}  // namespace flexbench::lie
