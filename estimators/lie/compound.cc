// Derivation of the 4th-order terms (a = xi1', b = xi2, zero-mean jointly Gaussian, Sa = E[aa^T],
// Sb = E[bb^T], C = E[ab^T]; ad(.) is the curly wedge of [PPOE eq. 13]):
//
//   E[c c^T] = E[(a+b)(a+b)^T]                                   (2nd order)
//            + 1/4 E[(ad_a b)(ad_a b)^T]                          (2nd x 2nd)
//            + 1/12 (E[(ad_a^2 b + ad_b^2 a)(a+b)^T] + transpose)  (3rd x 1st)
//            + O(6)
// Odd moments vanish, so 1st x 2nd, 1st x 4th and 2nd x 3rd contribute nothing. With
// ad_u = sum_i u_i G_i and Isserlis' theorem for the 4th moments:
//   E[(ad_a b)(ad_a b)^T] = m m^T + K(Sa, Sb) - K(C, C^T),            m = E[ad_a b]
//   E[ad_a^2 b c^T]       = Q(Sa) E[bc^T] - (Q(C) + ad_m) E[ac^T]
//   E[ad_b^2 a c^T]       = Q(Sb) E[ac^T] - (Q(C^T) - ad_m) E[bc^T]
// where K(A, M) = E[ad_u M ad_v^T] and Q(A) = E[ad_u ad_v] for E[uv^T] = A. For C = 0 this is
// Barfoot & Furgale's 4th-order formula, 1/4 K(Sa, Sb) + 1/12 (Q(Sa) Sb + Q(Sb) Sa + transp.).
// Both K and Q reduce to the 3x3 identity
//   E[[x]x M [y]x^T] = (tr A tr M - tr(AM)) I - tr(M) A^T - tr(A) M^T + (AM)^T + (MA)^T,
// E[x y^T] = A, evaluated blockwise.
#include "estimators/lie/compound.h"

namespace flexbench::lie {
namespace {

// E[[x]x M [y]x^T] for E[x y^T] = A.
Mat3 SkewCongruenceExpectation(const Mat3& A, const Mat3& M) {
  const Mat3 AM = A * M;
  const double trA = A.trace();
  const double trM = M.trace();
  return (trA * trM - AM.trace()) * Mat3::Identity() - trM * A.transpose() - trA * M.transpose() +
         AM.transpose() + (M * A).transpose();
}

// E[[x]x [y]x] = E[y x^T - (x.y) I] for E[x y^T] = D.
Mat3 SkewSquareExpectation(const Mat3& D) { return D.transpose() - D.trace() * Mat3::Identity(); }

// E[x cross y] for E[x y^T] = D.
Vec3 CrossExpectation(const Mat3& D) {
  return Vec3(D(1, 2) - D(2, 1), D(2, 0) - D(0, 2), D(0, 1) - D(1, 0));
}

// Products of the block upper-triangular Q(A) = [[P, U], [0, P]] with a dense M, in blocks.
Mat6 UpperBlockTimes(const Mat6& Q, const Mat6& M) {
  const Mat3 P = Q.topLeftCorner<3, 3>();
  const Mat3 U = Q.topRightCorner<3, 3>();
  Mat6 out;
  out.topRows<3>().noalias() = P * M.topRows<3>() + U * M.bottomRows<3>();
  out.bottomRows<3>().noalias() = P * M.bottomRows<3>();
  return out;
}

}  // namespace

Mat6 CurlyCongruenceExpectation(const Mat6& A, const Mat6& M) {
  // ad_u = [[th_u]x, [rho_u]x], [0, [th_u]x]]; expand ad_u M ad_v^T blockwise.
  const Mat3 A_rr = A.topLeftCorner<3, 3>();
  const Mat3 A_rt = A.topRightCorner<3, 3>();
  const Mat3 A_tr = A.bottomLeftCorner<3, 3>();
  const Mat3 A_tt = A.bottomRightCorner<3, 3>();
  const Mat3 M11 = M.topLeftCorner<3, 3>();
  const Mat3 M12 = M.topRightCorner<3, 3>();
  const Mat3 M21 = M.bottomLeftCorner<3, 3>();
  const Mat3 M22 = M.bottomRightCorner<3, 3>();
  Mat6 out;
  out.topLeftCorner<3, 3>() =
      SkewCongruenceExpectation(A_tt, M11) + SkewCongruenceExpectation(A_rt, M21) +
      SkewCongruenceExpectation(A_tr, M12) + SkewCongruenceExpectation(A_rr, M22);
  out.topRightCorner<3, 3>() =
      SkewCongruenceExpectation(A_tt, M12) + SkewCongruenceExpectation(A_rt, M22);
  out.bottomLeftCorner<3, 3>() =
      SkewCongruenceExpectation(A_tt, M21) + SkewCongruenceExpectation(A_tr, M22);
  out.bottomRightCorner<3, 3>() = SkewCongruenceExpectation(A_tt, M22);
  return out;
}

Mat6 CurlySquareExpectation(const Mat6& A) {
  const Mat3 P = SkewSquareExpectation(A.bottomRightCorner<3, 3>());
  Mat6 out;
  out.topLeftCorner<3, 3>() = P;
  out.topRightCorner<3, 3>() = SkewSquareExpectation(A.bottomLeftCorner<3, 3>()) +
                               SkewSquareExpectation(A.topRightCorner<3, 3>());
  out.bottomLeftCorner<3, 3>().setZero();
  out.bottomRightCorner<3, 3>() = P;
  return out;
}

Vec6 BchMean(const Mat6& C_ab) {
  // ad_a b = [[th_a]x rho_b + [rho_a]x th_b; [th_a]x th_b].
  Vec6 m;
  m.segment<3>(kTransIdx) = CrossExpectation(C_ab.bottomLeftCorner<3, 3>()) +
                            CrossExpectation(C_ab.topRightCorner<3, 3>());
  m.segment<3>(kRotIdx) = CrossExpectation(C_ab.bottomRightCorner<3, 3>());
  return 0.5 * m;
}

Mat6 BchSecondMoment(const Mat6& Sigma_a, const Mat6& Sigma_b, CompoundOrder order) {
  Mat6 out = Sigma_a + Sigma_b;
  if (order == CompoundOrder::kSecond) return out;
  const Mat6 M = UpperBlockTimes(CurlySquareExpectation(Sigma_a), Sigma_b) +
                 UpperBlockTimes(CurlySquareExpectation(Sigma_b), Sigma_a);
  out += 0.25 * CurlyCongruenceExpectation(Sigma_a, Sigma_b) + (M + M.transpose()) / 12.0;
  return out;
}

Mat6 BchSecondMoment(const Mat6& Sigma_a, const Mat6& Sigma_b, const Mat6& C_ab,
                     CompoundOrder order) {
  Mat6 out = Sigma_a + Sigma_b + C_ab + C_ab.transpose();
  if (order == CompoundOrder::kSecond) return out;
  const Vec6 m = 2.0 * BchMean(C_ab);
  const Mat6 ad_m = CurlyWedge(m);
  const Mat6 Ct = C_ab.transpose();
  const Mat6 E_a_sum = Sigma_a + C_ab;  // E[a (a + b)^T]
  const Mat6 E_b_sum = Ct + Sigma_b;    // E[b (a + b)^T]
  const Mat6 M = UpperBlockTimes(CurlySquareExpectation(Sigma_a), E_b_sum) -
                 UpperBlockTimes(CurlySquareExpectation(C_ab) + ad_m, E_a_sum) +
                 UpperBlockTimes(CurlySquareExpectation(Sigma_b), E_a_sum) -
                 UpperBlockTimes(CurlySquareExpectation(Ct) - ad_m, E_b_sum);
  out += 0.25 * (m * m.transpose() + CurlyCongruenceExpectation(Sigma_a, Sigma_b) -
                 CurlyCongruenceExpectation(C_ab, Ct)) +
         (M + M.transpose()) / 12.0;
  return out;
}

Mat6 CompoundCovariance(const SE3& X2, const Mat6& Sigma1, const Mat6& Sigma2,
                        CompoundOrder order) {
  return BchSecondMoment(TransportCovariance(X2, Sigma1), Sigma2, order);
}

Mat6 CompoundCovariance(const SE3& X2, const Mat6& Sigma1, const Mat6& Sigma2, const Mat6& C12,
                        CompoundOrder order) {
  const Mat6 Ad_X2inv = X2.Inverse().Adjoint();
  return BchSecondMoment(TransportCovariance(X2, Sigma1), Sigma2, Ad_X2inv * C12, order);
}

UncertainPose Compound(const UncertainPose& pose1, const UncertainPose& pose2,
                       CompoundOrder order) {
  return {pose1.mean * pose2.mean, CompoundCovariance(pose2.mean, pose1.cov, pose2.cov, order)};
}

UncertainPose Compound(const UncertainPose& pose1, const UncertainPose& pose2, const Mat6& C12,
                       CompoundOrder order) {
  return {pose1.mean * pose2.mean,
          CompoundCovariance(pose2.mean, pose1.cov, pose2.cov, C12, order)};
}

}  // namespace flexbench::lie
