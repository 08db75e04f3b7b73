// The Bingham distribution on S^3, for unit quaternions, in the particle-filter paper's
// conventions (sec. II-C):
//
//   B(M, lambda)(x) = exp(x^T M diag(lambda) M^T x) / C(lambda),   x in S^3 in R^4     (7)
//
// - Quaternions are (x, y, z, w) ("xyzw", the paper's choice), so that with M = I4 the mode is
//   the identity rotation. Convert from Eigen with QuatToXyzwPositive (conventions.h).
// - lambda is sorted ascending, lambda1 <= lambda2 <= lambda3 <= lambda4, and shifted so that its
//   largest entry is 0 ([PF eqs. 8-9]: adding a constant to every entry does not change the
//   density). Column k of the orthogonal M is the axis of lambda_k; the last column is the mode.
// - Axis-symmetric case: lambda3 = lambda4 = 0. The density is then constant on the great circle
//   spanned by the last two columns of M; with M = I4 and lambda = (l, l, 0, 0) (the paper's
//   Table I) that circle is every rotation about the z axis, which is how the filter stops caring
//   about an IMU's drifting yaw (sec. IV-E).
//
// The normaliser C(lambda) is the integral over S^3 (surface measure, |S^3| = 2 pi^2). It is
// computed from an exact one-dimensional representation: writing x = (cos e cos a, cos e sin a,
// sin e cos b, sin e sin b), integrating a and b in closed form (each gives 2 pi e^{..} I0(..))
// and substituting u = cos^2 e (uniform on [0, 1] for uniform x),
//
//   C(lambda) = 2 pi^2 int_0^1 exp(u l2 + (1-u) l4) I0e(u (l2 - l1)/2) I0e((1-u)(l4 - l3)/2) du
//
// for sorted lambda, with the scaled I0e = e^{-x} I0(x) (bessel.h), so the integrand lies in
// (0, 1]. The integral is computed by adaptive Gauss-Kronrod (7/15) to relative accuracy 1e-13,
// which resolves the sharp peak at u = 0 of concentrated distributions (lambda ~ -1e6).
// tests/unit/pf/ checks it against a direct three-dimensional quadrature over S^3, closed forms
// and the concentrated (Gaussian) limit.
//
// Bad input (non-finite, unsorted or unshifted lambda, non-orthogonal M, a quaternion that is not
// unit length) throws InputError.
#pragma once

#include <Eigen/Core>
#include <random>
#include <string>

#include "estimators/conventions.h"

namespace flexbench::pf {

// Tolerance of the unit-length check of quaternions given to the density functions.
inline constexpr double kUnitQuaternionTol = 1e-6;

// Throws InputError naming `what` unless lambda is finite, sorted ascending and shifted so that
// lambda(3) == 0.
void ValidateBinghamLambda(const Vec4& lambda, const std::string& what);
// Throws InputError naming `what` unless x is finite and |x| = 1 within kUnitQuaternionTol.
// (`what` is a C string so that the check costs no allocation on the filter's hot path.)
void ValidateUnitQuaternion(const Vec4& x, const char* what);

// log C(lambda) for any finite lambda (sorted or not, shifted or not; C is invariant under a
// permutation of lambda together with M, and C(lambda + c) = e^c C(lambda)).
double BinghamLogNormaliser(const Vec4& lambda);

// log p(q_obs (.) q_pred^-1) up to the normaliser, as an affine function of the predicted
// rotation matrix: c0 + sum_ij C(i,j) R_pred(i,j). The squares and products of a quaternion's
// entries are linear in its rotation matrix, and R(q_obs q_pred^-1) = R_obs R_pred^T, so the
// Bingham term of [PF eq. 27] costs nine multiply-adds per particle, needs no quaternion of the
// particle, and is automatically antipodally symmetric.
struct BinghamRotationForm {
  double c0 = 0.0;
  Mat3 C = Mat3::Zero();
  double Evaluate(const Mat3& R_pred) const { return c0 + C.cwiseProduct(R_pred).sum(); }
};

class Bingham {
 public:
  // lambda as in [PF eq. 9] (validated); M orthogonal (validated to 1e-9).
  explicit Bingham(const Vec4& lambda, const Mat4& M = Mat4::Identity());
  // The axis-symmetric distribution of rotations about `axis` (unit after normalisation):
  // lambda = (l, l, 0, 0) with l < 0, the symmetric circle being the rotations about axis.
  static Bingham AxisSymmetric(double l, const Vec3& axis = Vec3::UnitZ());

  const Vec4& lambda() const { return lambda_; }
  const Mat4& M() const { return M_; }
  // A = M diag(lambda) M^T.
  const Mat4& A() const { return A_; }
  // The mode (last column of M); for axis-symmetric distributions one point of the mode circle.
  Vec4 Mode() const { return M_.col(3); }
  bool IsAxisSymmetric() const { return lambda_(2) == 0.0; }

  // x^T A x for a unit quaternion in xyzw order (checked).
  double UnnormalisedLogDensity(const Vec4& x) const;
  double LogNormaliser() const { return log_c_; }
  double LogDensity(const Vec4& x) const { return UnnormalisedLogDensity(x) - log_c_; }

  // The likelihood form of [PF eq. 27] for an observed orientation (Eigen quaternion, any sign;
  // must be unit length within kUnitQuaternionTol).
  BinghamRotationForm RotationForm(const Quat& q_obs) const;

 private:
  Vec4 lambda_;
  Mat4 M_;
  Mat4 A_;
  double log_c_ = 0.0;
};

// Exact rejection sampler with an angular central Gaussian envelope (Kent, Ganeiber and Mardia,
// "A new unified approach for the simulation of a wide class of directional distributions",
// 2018): y ~ N(0, Omega^-1), Omega = I + 2 A'/b with A' = -A, x = y/|y|, accepted with
// probability exp(-x^T A' x) (x^T Omega x)^2 e^{(4-b)/2} (b/4)^2, where b solves
// sum_i 1 / (b + 2 a_i) = 1 for the eigenvalues a_i = -lambda_i. Returns xyzw with w >= 0.
// Normal deviates come from a polar Box-Muller on 53-bit uniforms (std::normal_distribution's
// algorithm differs between standard libraries).
class BinghamSampler {
 public:
  explicit BinghamSampler(const Bingham& dist);
  Vec4 Sample(std::mt19937_64& rng);
  double b() const { return b_; }
  // Accepted / proposed so far.
  double AcceptanceRate() const { return proposed_ ? double(accepted_) / double(proposed_) : 0.0; }

 private:
  double Normal(std::mt19937_64& rng);

  Mat4 M_;
  Vec4 a_;       // -lambda >= 0
  Vec4 omega_;   // 1 + 2 a / b
  Vec4 stddev_;  // 1 / sqrt(omega)
  double b_ = 4.0;
  double log_bound_ = 0.0;  // (4 - b)/2 - 2 log(4 / b)
  bool has_spare_ = false;
  double spare_ = 0.0;
  long accepted_ = 0;
  long proposed_ = 0;
};

}  // namespace flexbench::pf
