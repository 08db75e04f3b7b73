#include "estimators/lie/so3.h"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "estimators/lie/sincos.h"

namespace flexbench::lie {
namespace {

// Below these angles the closed forms lose digits to cancellation; the Taylor series (to x^8,
// remainder below 1e-15 relative at the threshold) are used instead.
constexpr double kTinyAngle = 1e-4;  // a, b: only the 0/0 at x = 0 matters.
constexpr double kSmallAngle = 0.2;  // c, d: cancellation ~ 1e-16 / x^2.

// d(x) = 1/x^2 - cot(x/2) / (2x), the theta^2 coefficient of Jl^-1 and Jr^-1.
double InverseJacobianCoefficient(double x) {
  if (x < kSmallAngle) {
    const double x2 = x * x;
    return 1.0 / 12.0 +
           x2 * (1.0 / 720.0 + x2 * (1.0 / 30240.0 + x2 * (1.0 / 1209600.0 + x2 / 47900160.0)));
  }
  // cot(x/2) = sin(x) / (1 - cos(x)) written with half angles so that x = pi is exact.
  double sh, ch;
  SinCos(0.5 * x, &sh, &ch);
  return 1.0 / (x * x) - ch / (2.0 * x * sh);
}

}  // namespace

SO3Coefficients ComputeSO3Coefficients(double x) {
  SO3Coefficients k;
  const double x2 = x * x;
  if (x < kTinyAngle) {
    k.a = 1.0 - x2 / 6.0 * (1.0 - x2 / 20.0);
    k.b = 0.5 - x2 / 24.0 * (1.0 - x2 / 30.0);
  }
  // One inline sincos of x/2 gives sin x = 2 sin(x/2) cos(x/2) and 1 - cos x = 2 sin^2(x/2)
  // (no cancellation); three libm calls were ~40% of the identification's forward model.
  double s = 0.0;  // sin x, needed from kTinyAngle on (kSmallAngle is larger)
  if (x >= kTinyAngle) {
    double sh, ch;
    SinCos(0.5 * x, &sh, &ch);
    s = 2.0 * sh * ch;
    k.a = s / x;
    k.b = 2.0 * sh * sh / x2;
  }
  if (x < kSmallAngle) {
    k.c = 1.0 / 6.0 +
          x2 * (-1.0 / 120.0 + x2 * (1.0 / 5040.0 + x2 * (-1.0 / 362880.0 + x2 / 39916800.0)));
  } else {
    k.c = (x - s) / (x2 * x);
  }
  return k;
}

Mat3 SO3Exp(const Vec3& theta) {
  const double x = theta.norm();
  double a, b;
  if (x < kTinyAngle) {
    const double x2 = x * x;
    a = 1.0 - x2 / 6.0 * (1.0 - x2 / 20.0);
    b = 0.5 - x2 / 24.0 * (1.0 - x2 / 30.0);
  } else {
    double sh, ch;
    SinCos(0.5 * x, &sh, &ch);
    a = 2.0 * sh * ch / x;
    b = 2.0 * sh * sh / (x * x);
  }
  const Mat3 W = Skew(theta);
  return Mat3::Identity() + a * W + b * W * W;
}

Vec3 SO3Log(const Mat3& R) {
  const Vec3 w = Vee(R);  // sin(x) * u
  const double s = w.norm();
  const double c = std::clamp(0.5 * (R.trace() - 1.0), -1.0, 1.0);
  const double x = std::atan2(s, c);
  if (c > -0.7) {
    // x < ~2.35 rad: sin(x) > 0.7 or x small, the skew part carries the axis accurately.
    const double x_over_s = x < kTinyAngle ? 1.0 + x * x / 6.0 * (1.0 + 7.0 / 60.0 * x * x) : x / s;
    return x_over_s * w;
  }
  // Near pi: (R + R^T)/2 - cos(x) I = (1 - cos x) u u^T. Take the column with the largest
  // diagonal entry (|u_j| >= 1/sqrt(3)), so the division is well conditioned.
  const Mat3 B = 0.5 * (R + R.transpose()) - c * Mat3::Identity();
  int j = 0;
  B.diagonal().maxCoeff(&j);
  Vec3 u = B.col(j) / std::sqrt(std::max(B(j, j), 0.0) * (1.0 - c));
  u.normalize();
  // The skew part is sin(x) u with sin(x) >= 0 and fixes the sign of the axis.
  if (u.dot(w) < 0.0) u = -u;
  return x * u;
}

Mat3 SO3RightJacobian(const Vec3& theta) {
  const SO3Coefficients k = ComputeSO3Coefficients(theta.norm());
  const Mat3 W = Skew(theta);
  return Mat3::Identity() - k.b * W + k.c * W * W;
}

Mat3 SO3LeftJacobian(const Vec3& theta) {
  const SO3Coefficients k = ComputeSO3Coefficients(theta.norm());
  const Mat3 W = Skew(theta);
  return Mat3::Identity() + k.b * W + k.c * W * W;
}

Mat3 SO3RightJacobianInverse(const Vec3& theta) {
  const double d = InverseJacobianCoefficient(theta.norm());
  const Mat3 W = Skew(theta);
  return Mat3::Identity() + 0.5 * W + d * W * W;
}

Vec3 SO3LeftJacobianInverseTimes(const Vec3& theta, const Vec3& v) {
  const double d = InverseJacobianCoefficient(theta.norm());
  const Vec3 wv = theta.cross(v);
  return v - 0.5 * wv + d * theta.cross(wv);
}

Mat3 SO3LeftJacobianInverse(const Vec3& theta) {
  const double d = InverseJacobianCoefficient(theta.norm());
  const Mat3 W = Skew(theta);
  return Mat3::Identity() - 0.5 * W + d * W * W;
}

Mat3 SO3Project(const Mat3& M) {
  Eigen::JacobiSVD<Mat3> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 D = Mat3::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

}  // namespace flexbench::lie
