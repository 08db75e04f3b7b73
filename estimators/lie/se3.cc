#include "estimators/lie/se3.h"

#include <cmath>

namespace flexbench::lie {
namespace {

// The higher coefficients of Q cancel like x^4 and x^5; below this angle their Taylor series
// (to x^8, remainder < 1e-14 relative) beat the closed forms (rounding ~1e-16 / x^5).
constexpr double kQSeriesAngle = 0.5;

Vec3 Rho(const Vec6& xi) { return xi.segment<3>(kTransIdx); }
Vec3 Theta(const Vec6& xi) { return xi.segment<3>(kRotIdx); }

Mat6 BlockUpperTriangular(const Mat3& diag, const Mat3& upper) {
  Mat6 J;
  J.topLeftCorner<3, 3>() = diag;
  J.topRightCorner<3, 3>() = upper;
  J.bottomLeftCorner<3, 3>().setZero();
  J.bottomRightCorner<3, 3>() = diag;
  return J;
}

}  // namespace

SE3 SE3::Exp(const Vec6& xi, Mat6* J_X_xi) {
  const Vec3 theta = Theta(xi);
  const SO3Coefficients k = ComputeSO3Coefficients(theta.norm());
  const Mat3 W = Skew(theta);
  const Mat3 W2 = W * W;
  const Mat3 R = Mat3::Identity() + k.a * W + k.b * W2;
  const Mat3 Jl = Mat3::Identity() + k.b * W + k.c * W2;
  if (J_X_xi != nullptr) *J_X_xi = SE3RightJacobian(xi);
  return SE3(R, Jl * Rho(xi));
}

Vec6 SE3::Log(Mat6* J_xi_X) const {
  Vec6 xi;
  const Vec3 theta = SO3Log(R_);
  xi.segment<3>(kRotIdx) = theta;
  xi.segment<3>(kTransIdx) = SO3LeftJacobianInverseTimes(theta, t_);
  if (J_xi_X != nullptr) *J_xi_X = SE3RightJacobianInverse(xi);
  return xi;
}

SE3 SE3::Inverse(Mat6* J_Xinv_X) const {
  if (J_Xinv_X != nullptr) *J_Xinv_X = -Adjoint();
  const Mat3 Rt = R_.transpose();
  return SE3(Rt, -(Rt * t_));
}

SE3 SE3::Compose(const SE3& Y, Mat6* J_XY_X, Mat6* J_XY_Y) const {
  if (J_XY_X != nullptr) *J_XY_X = Y.Inverse().Adjoint();
  if (J_XY_Y != nullptr) J_XY_Y->setIdentity();
  return *this * Y;
}

SE3 SE3::Between(const SE3& Y, Mat6* J_out_X, Mat6* J_out_Y) const {
  const SE3 out(R_.transpose() * Y.R_, R_.transpose() * (Y.t_ - t_));
  if (J_out_X != nullptr) *J_out_X = -out.Inverse().Adjoint();
  if (J_out_Y != nullptr) J_out_Y->setIdentity();
  return out;
}

Vec3 SE3::Act(const Vec3& p_b, Eigen::Matrix<double, 3, 6>* J_pa_X, Mat3* J_pa_pb) const {
  if (J_pa_X != nullptr) {
    J_pa_X->block<3, 3>(0, kTransIdx) = R_;
    J_pa_X->block<3, 3>(0, kRotIdx) = -R_ * Skew(p_b);
  }
  if (J_pa_pb != nullptr) *J_pa_pb = R_;
  return R_ * p_b + t_;
}

SE3 SE3::Plus(const Vec6& xi, Mat6* J_out_X, Mat6* J_out_xi) const {
  const SE3 E = Exp(xi, J_out_xi);
  if (J_out_X != nullptr) *J_out_X = E.Inverse().Adjoint();
  return *this * E;
}

Vec6 SE3::Minus(const SE3& X, Mat6* J_out_this, Mat6* J_out_X) const {
  const Vec6 out = X.Between(*this).Log();
  if (J_out_this != nullptr) *J_out_this = SE3RightJacobianInverse(out);
  if (J_out_X != nullptr) *J_out_X = -SE3LeftJacobianInverse(out);
  return out;
}

Mat6 SE3::Adjoint() const { return BlockUpperTriangular(R_, Skew(t_) * R_); }

Vec6 SE3::AdjointTimes(const Vec6& xi) const {
  Vec6 out;
  const Vec3 R_theta = R_ * Theta(xi);
  out.segment<3>(kRotIdx) = R_theta;
  out.segment<3>(kTransIdx) = R_ * Rho(xi) + t_.cross(R_theta);
  return out;
}

Mat4 SE3Hat(const Vec6& xi) {
  Mat4 H = Mat4::Zero();
  H.topLeftCorner<3, 3>() = Skew(Theta(xi));
  H.topRightCorner<3, 1>() = Rho(xi);
  return H;
}

Vec6 SE3Vee(const Mat4& xi_hat) {
  Vec6 xi;
  xi.segment<3>(kTransIdx) = xi_hat.topRightCorner<3, 1>();
  xi.segment<3>(kRotIdx) = Vee(xi_hat.topLeftCorner<3, 3>());
  return xi;
}

Mat6 CurlyWedge(const Vec6& xi) { return BlockUpperTriangular(Skew(Theta(xi)), Skew(Rho(xi))); }

Mat3 SE3LeftJacobianQ(const Vec3& rho, const Vec3& theta) {
  // Barfoot & Furgale 2014, eq. (102), for xi = [rho; theta].
  const double x = theta.norm();
  const double x2 = x * x;
  const SO3Coefficients k = ComputeSO3Coefficients(x);
  double c2;  // (x^2 + 2 cos x - 2) / (2 x^4)
  double c3;  // (2x - 3 sin x + x cos x) / (2 x^5)
  if (x < kQSeriesAngle) {
    c2 = 1.0 / 24.0 +
         x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (-1.0 / 3628800.0 + x2 / 479001600.0)));
    c3 = 1.0 / 120.0 +
         x2 * (-1.0 / 2520.0 + x2 * (1.0 / 120960.0 + x2 * (-1.0 / 9979200.0 + x2 / 1245404160.0)));
  } else {
    const double s = std::sin(x);
    const double c = std::cos(x);
    c2 = (x2 + 2.0 * c - 2.0) / (2.0 * x2 * x2);
    c3 = (2.0 * x - 3.0 * s + x * c) / (2.0 * x2 * x2 * x);
  }
  const Mat3 P = Skew(rho);
  const Mat3 W = Skew(theta);
  const Mat3 WP = W * P;
  const Mat3 PW = P * W;
  const Mat3 WPW = WP * W;
  return 0.5 * P + k.c * (WP + PW + WPW) + c2 * (W * WP + PW * W - 3.0 * WPW) +
         c3 * (WPW * W + W * WPW);
}

Mat6 SE3LeftJacobian(const Vec6& xi) {
  return BlockUpperTriangular(SO3LeftJacobian(Theta(xi)), SE3LeftJacobianQ(Rho(xi), Theta(xi)));
}

Mat6 SE3RightJacobian(const Vec6& xi) { return SE3LeftJacobian(-xi); }

Mat6 SE3LeftJacobianInverse(const Vec6& xi) {
  const Mat3 J_inv = SO3LeftJacobianInverse(Theta(xi));
  const Mat3 Q = SE3LeftJacobianQ(Rho(xi), Theta(xi));
  return BlockUpperTriangular(J_inv, -J_inv * Q * J_inv);
}

Mat6 SE3RightJacobianInverse(const Vec6& xi) { return SE3LeftJacobianInverse(-xi); }

}  // namespace flexbench::lie
