// Compounding uncertain SE(3) poses with right (local) perturbations (PPOE paper sec. III-C).
//
//   X1 Exp(xi1) * X2 Exp(xi2) = X1 X2 Exp(xi1') Exp(xi2) = X1 X2 Exp(xi12),
//   xi1' = Ad_{X2^-1} xi1  ([PPOE eq. 11b], exact)
//   xi12 = BCH(xi1', xi2) = xi1' + xi2 + 1/2 ad(xi1') xi2 + 1/12 ad(xi1')^2 xi2
//          + 1/12 ad(xi2)^2 xi1' - 1/24 ad(xi2) ad(xi1')^2 xi2 + ...  [PPOE eq. 12]
//
// This is Barfoot & Furgale 2014 ("Associating uncertainty with three-dimensional poses for use
// in estimation problems", IEEE T-RO) mirrored to the right convention: in their left form
// Exp(xi1) T1 Exp(xi2) T2 = Exp(xi1) Exp(Ad_T1 xi2) T1 T2 the adjoint moves the *second*
// perturbation forward; here Ad_{X2^-1} moves the *first* one back, and the BCH series is taken
// of (xi1', xi2) in that order. The 4th-order second moment is symmetric in its two arguments
// for independent inputs, so their covariance formula carries over with Sigma1 -> Sigma1',
// Sigma2' -> Sigma2.
//
// The covariance returned is the second moment E[xi12 xi12^T] about the nominal mean X1 X2
// [PPOE eq. 9]. For correlated inputs xi12 has a mean of 1/2 E[ad(xi1') xi2] (second order); it is
// part of the second moment (so the result stays consistent about X1 X2) and available from
// BchMean.
//
// "Order" counts powers of the perturbation in the moment expansion [PPOE eq. 14]: kSecond is [PPOE
// eq. 15], kFourth adds every 4th-order moment term (Barfoot & Furgale's 4th-order form; for
// correlated inputs derived with Isserlis' theorem, see compound.cc).
#pragma once

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"

namespace flexbench::lie {

enum class CompoundOrder { kSecond = 2, kFourth = 4 };

// A pose with a covariance in its local (right) tangent space: X = mean * Exp(xi),
// xi ~ N(0, cov).
struct UncertainPose {
  SE3 mean;
  Mat6 cov = Mat6::Zero();
};

// Second moment of c = BCH(a, b), Exp(c) = Exp(a) Exp(b), for zero-mean Gaussian a, b in the same
// tangent space with E[a a^T] = Sigma_a, E[b b^T] = Sigma_b and independent.
// kSecond: Sigma_a + Sigma_b. kFourth: + 1/4 E[(ad_a b)(ad_a b)^T] + the third-order cross terms.
Mat6 BchSecondMoment(const Mat6& Sigma_a, const Mat6& Sigma_b, CompoundOrder order);

// As above with a cross-covariance C_ab = E[a b^T] (jointly Gaussian; [Sigma_a C_ab; C_ab^T
// Sigma_b] must be PSD).
Mat6 BchSecondMoment(const Mat6& Sigma_a, const Mat6& Sigma_b, const Mat6& C_ab,
                     CompoundOrder order);

// E[BCH(a, b)] to second order: 1/2 E[ad_a b]; zero for independent inputs.
Vec6 BchMean(const Mat6& C_ab);

// [PPOE eq. 15] (kSecond) or its 4th-order extension: covariance of xi12 for independent xi1, xi2.
Mat6 CompoundCovariance(const SE3& X2, const Mat6& Sigma1, const Mat6& Sigma2, CompoundOrder order);
// Correlated inputs, C12 = E[xi1 xi2^T] (at X1 and X2 respectively). The cross-covariance moves
// with xi1' = Ad_{X2^-1} xi1: C1'2 = Ad_{X2^-1} C12.
Mat6 CompoundCovariance(const SE3& X2, const Mat6& Sigma1, const Mat6& Sigma2, const Mat6& C12,
                        CompoundOrder order);

// [X1 X2, CompoundCovariance(...)].
UncertainPose Compound(const UncertainPose& pose1, const UncertainPose& pose2, CompoundOrder order);
UncertainPose Compound(const UncertainPose& pose1, const UncertainPose& pose2, const Mat6& C12,
                       CompoundOrder order);

// The building blocks of the 4th-order terms, exposed for tests. With E[u v^T] = A (6x6):
//   CurlyCongruenceExpectation(A, M) = E[ad(u) M ad(v)^T]
//   CurlySquareExpectation(A)        = E[ad(u) ad(v)]   (Barfoot's <<A>> for symmetric A)
Mat6 CurlyCongruenceExpectation(const Mat6& A, const Mat6& M);
Mat6 CurlySquareExpectation(const Mat6& A);

}  // namespace flexbench::lie
