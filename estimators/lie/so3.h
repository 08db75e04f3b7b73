// SO(3) on plain Eigen 3x3 matrices: hat/vee, Exp/Log and the left/right Jacobians.
//
// Rotations are Mat3 (no wrapper type): Eigen's own fixed-size matrix is already a value type,
// and the SE(3) code below builds on these free functions. Rotation vectors theta are Vec3 with
// angle |theta| and the right-hand rule about theta/|theta|.
//
// Right (local) perturbations, as everywhere in flexbench (conventions.h):
//   Exp(theta + d) ~= Exp(theta) * Exp(Jr(theta) * d)
//   Exp(theta + d) ~= Exp(Jl(theta) * d) * Exp(theta)
// with Jl(theta) = Jr(-theta) = R * Jr(theta).
#pragma once

#include "estimators/conventions.h"

namespace flexbench::lie {

// [v]x, the skew-symmetric matrix with [v]x w = v x w (the so(3) hat operator of [PPOE eq. 2]).
inline Mat3 Skew(const Vec3& v) {
  Mat3 S;
  S << 0.0, -v.z(), v.y(),  //
      v.z(), 0.0, -v.x(),   //
      -v.y(), v.x(), 0.0;
  return S;
}

// Inverse of Skew for an exactly skew-symmetric matrix. For a general matrix this returns the
// vee of its skew-symmetric part, which is what Log needs.
inline Vec3 Vee(const Mat3& S) {
  return 0.5 * Vec3(S(2, 1) - S(1, 2), S(0, 2) - S(2, 0), S(1, 0) - S(0, 1));
}

// Coefficients of the Rodrigues-type series in |theta|, each with a Taylor branch where the
// closed form cancels catastrophically. Exposed because SE(3) and the kinematics reuse them.
struct SO3Coefficients {
  double a;  // sin(x)/x
  double b;  // (1 - cos x)/x^2
  double c;  // (x - sin x)/x^3
};
SO3Coefficients ComputeSO3Coefficients(double angle);

// Exp: R = I + a [theta]x + b [theta]x^2 (Rodrigues). Exact to rounding for any |theta|.
Mat3 SO3Exp(const Vec3& theta);

// Log: the rotation vector with |theta| in [0, pi]. The angle comes from atan2(sin, cos), which
// keeps full precision at both ends; near pi the axis is read from the symmetric part
// (R + R^T)/2 = cos(x) I + (1 - cos x) u u^T, because the skew part vanishes like sin(x) there.
// At exactly pi either sign is a valid answer.
Vec3 SO3Log(const Mat3& R);

// Jr(theta) = I - b [theta]x + c [theta]x^2.
Mat3 SO3RightJacobian(const Vec3& theta);
// Jl(theta) = I + b [theta]x + c [theta]x^2.
Mat3 SO3LeftJacobian(const Vec3& theta);
// Jr^-1(theta) = I + 1/2 [theta]x + d [theta]x^2, d = 1/x^2 - cot(x/2)/(2x); singular at
// |theta| = 2 pi, well conditioned on the range of SO3Log.
Mat3 SO3RightJacobianInverse(const Vec3& theta);
// Jl^-1(theta) = I - 1/2 [theta]x + d [theta]x^2.
Mat3 SO3LeftJacobianInverse(const Vec3& theta);
// SO3LeftJacobianInverse(theta) * v without forming the matrix (two cross products).
Vec3 SO3LeftJacobianInverseTimes(const Vec3& theta, const Vec3& v);

// Projects a nearly orthonormal matrix onto SO(3) (SVD); for data read from files or after long
// products of rotations.
Mat3 SO3Project(const Mat3& M);

}  // namespace flexbench::lie
