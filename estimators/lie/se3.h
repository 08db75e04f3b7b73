// SE(3) as a small value type (rotation + translation, 12 doubles, no alignment requirement).
//
// Conventions (conventions.h, PPOE paper sec. III):
// - Tangent vectors xi = [rho; theta] (translation first), hat(xi) = [[theta]x, rho; 0, 0] (eq. 2).
// - Right (local) perturbations: X = Xbar * Exp(xi); "X (+) xi" = X * Exp(xi) and
//   "Y (-) X" = Log(X^-1 * Y). Covariances live in the tangent space at the mean.
// - Ad_X = [[R, [t]x R], [0, R]] (eq. 7) maps local tangent vectors at X to global ones at the
//   identity: Exp(Ad_X xi) * X = X * Exp(xi) (eqs. 5-6).
// - Jacobians follow manif's naming J_out_in and are right Jacobians:
//   f(X (+) d) = f(X) (+) (J_f_X * d) to first order.
// - An SE3 T_a_b is the pose of frame b in frame a; it maps points p_b to p_a = T_a_b * p_b.
#pragma once

#include "estimators/conventions.h"
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

  // Ad_X = [[R, [t]x R], [0, R]] (eq. 7).
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

// hat(xi) = [[theta]x, rho; 0, 0] (eq. 2) and its inverse.
Mat4 SE3Hat(const Vec6& xi);
Vec6 SE3Vee(const Mat4& xi_hat);

// The 6x6 "curly wedge" ad_xi = [[theta]x, [rho]x], [0, [theta]x]] (eq. 13): the matrix of the
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

// Sigma -> Ad_X Sigma Ad_X^T (eq. 10): a local covariance at X expressed at the identity.
inline Mat6 TransformCovariance(const SE3& X, const Mat6& Sigma) {
  return CongruenceAdjoint(X.rotation(), X.translation(), Sigma);
}

namespace internal {

// [[R^T, 0], [0, R^T]] [[I, -[t]x], [0, I]] Sigma (...)^T for Sigma = [[A, B], [B^T, C]]: the
// congruence by Ad_{(R, t)^-1}, sheared in the input frame and then rotated, so neither R^T t
// nor a copy of R^T is needed. Same ~200 multiplications as CongruenceAdjoint. Forced inline:
// in the FK loop this lets the compiler overlap it with the mean-pose products (~10%).
EIGEN_ALWAYS_INLINE void TransportBlocks(const Mat3& R, const Vec3& t, const Mat3& A, const Mat3& B,
                                         const Mat3& C, Mat6* out) {
  const Vec3 s = -t;
  // Shear: D = B + [s]x C, TL = A + [s]x B^T - D [s]x (see CongruenceAdjoint).
  Mat3 D, G;
  D.row(0) = B.row(0) + s[1] * C.row(2) - s[2] * C.row(1);
  D.row(1) = B.row(1) + s[2] * C.row(0) - s[0] * C.row(2);
  D.row(2) = B.row(2) + s[0] * C.row(1) - s[1] * C.row(0);
  for (int j = 0; j < 3; ++j) G.col(j) = s.cross(Vec3(B.row(j).transpose()));
  for (int i = 0; i < 3; ++i) G.row(i) += s.cross(Vec3(D.row(i).transpose())).transpose();
  G += A;
  // Rotate: R^T M R per block, upper triangles only for the symmetric ones.
  Mat3 RtG, RtD, RtC, D_out;
  RtG.noalias() = R.transpose() * G;
  RtD.noalias() = R.transpose() * D;
  RtC.noalias() = R.transpose() * C;
  D_out.noalias() = RtD * R;
  Mat6& o = *out;
  for (int i = 0; i < 3; ++i) {
    for (int j = i; j < 3; ++j) {
      o(i, j) = o(j, i) = RtG.row(i).dot(R.col(j));
      o(3 + i, 3 + j) = o(3 + j, 3 + i) = RtC.row(i).dot(R.col(j));
    }
  }
  o.topRightCorner<3, 3>() = D_out;
  o.bottomLeftCorner<3, 3>() = D_out.transpose();
}

}  // namespace internal

// Sigma -> Ad_{X^-1} Sigma Ad_{X^-1}^T: moves a local covariance at Y to the local tangent space
// at Y * X, exactly (Y Exp(xi) X = Y X Exp(Ad_{X^-1} xi)); the transport step of eqs. 15, 18.
// Sigma must be symmetric; `out` may alias it.
inline void TransportCovariance(const SE3& X, const Mat6& Sigma, Mat6* out) {
  internal::TransportBlocks(X.rotation(), X.translation(), Sigma.topLeftCorner<3, 3>(),
                            Sigma.topRightCorner<3, 3>(), Sigma.bottomRightCorner<3, 3>(), out);
}
inline Mat6 TransportCovariance(const SE3& X, const Mat6& Sigma) {
  Mat6 out;
  TransportCovariance(X, Sigma, &out);
  return out;
}

// Ad_{X^-1} (Sigma1 + Sigma2) Ad_{X^-1}^T without forming the sum; the hot step of eq. 18.
inline void TransportCovarianceSum(const SE3& X, const Mat6& Sigma1, const Mat6& Sigma2,
                                   Mat6* out) {
  internal::TransportBlocks(
      X.rotation(), X.translation(), Sigma1.topLeftCorner<3, 3>() + Sigma2.topLeftCorner<3, 3>(),
      Sigma1.topRightCorner<3, 3>() + Sigma2.topRightCorner<3, 3>(),
      Sigma1.bottomRightCorner<3, 3>() + Sigma2.bottomRightCorner<3, 3>(), out);
}

}  // namespace flexbench::lie
