#include "estimators/ekf/measurement_model.h"

#include "estimators/lie/so3.h"

namespace flexbench::estimators {
namespace {

using Mat36 = Eigen::Matrix<double, 3, 6>;

// d(X Exp(delta) p)/d(delta) at delta = 0, in the base frame: R [I, -[p]x].
Mat36 PointJacobian(const lie::SE3& X, const Vec3& p) {
  Mat36 J;
  J.leftCols<3>() = X.rotation();
  J.rightCols<3>() = -X.rotation() * lie::Skew(p);
  return J;
}

Eigen::Matrix<double, 2, 3> ProjectionJacobian(const PinholeCamera& c, const Vec3& p) {
  const double iz = 1.0 / p.z();
  Eigen::Matrix<double, 2, 3> J;
  J << c.fx * iz, 0.0, -c.fx * p.x() * iz * iz,  //
      0.0, c.fy * iz, -c.fy * p.y() * iz * iz;
  return J;
}

}  // namespace

bool NumericJacobians(const MeasurementModel& model, const lie::SE3& X, MeasJac* J_r_X,
                      NoiseJac* J_r_v, double eps) {
  const int m = model.Dim();
  const int nv = model.NoiseDim();
  J_r_X->resize(m, 6);
  J_r_v->resize(m, nv);
  const NoiseVec zero = NoiseVec::Zero(nv);
  MeasVec rp(m), rm(m);
  for (int j = 0; j < 6; ++j) {
    Vec6 d = Vec6::Zero();
    d[j] = eps;
    if (!model.Residual(X.Plus(d), zero, &rp) || !model.Residual(X.Plus(-d), zero, &rm)) {
      return false;
    }
    J_r_X->col(j) = (rp - rm) / (2.0 * eps);
  }
  for (int j = 0; j < nv; ++j) {
    NoiseVec v = zero;
    v[j] = eps;
    if (!model.Residual(X, v, &rp)) return false;
    v[j] = -eps;
    if (!model.Residual(X, v, &rm)) return false;
    J_r_v->col(j) = (rp - rm) / (2.0 * eps);
  }
  return true;
}

// --- PixelPointModel --------------------------------------------------------------------------

PixelPointModel::PixelPointModel(const PinholeCamera& camera, const lie::SE3& T_base_cam,
                                 const Vec3& p_ee, const Eigen::Vector2d& uv,
                                 const Eigen::Matrix2d& Sigma_uv)
    : camera_(camera), T_cam_base_(T_base_cam.Inverse()), p_ee_(p_ee), uv_(uv), sigma_(Sigma_uv) {}

bool PixelPointModel::Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const {
  const Vec3 p_cam = T_cam_base_ * (X * p_ee_);
  Eigen::Vector2d uv;
  if (!camera_.Project(p_cam, &uv)) return false;
  *r = uv_ - uv - v.head<2>();
  return true;
}

bool PixelPointModel::AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const {
  const Vec3 p_cam = T_cam_base_ * (X * p_ee_);
  if (p_cam.z() <= 1e-9) return false;
  *J_r_X = -ProjectionJacobian(camera_, p_cam) * T_cam_base_.rotation() * PointJacobian(X, p_ee_);
  *J_r_v = -NoiseJac::Identity(2, 2);
  return true;
}

// --- TagCornersModel --------------------------------------------------------------------------

TagCornersModel::TagCornersModel(const PinholeCamera& camera, const lie::SE3& T_base_cam,
                                 const std::array<Vec3, 4>& p_ee,
                                 const std::array<Eigen::Vector2d, 4>& uv,
                                 const Eigen::Matrix<double, 8, 8>& Sigma_uv)
    : camera_(camera), T_cam_base_(T_base_cam.Inverse()), p_ee_(p_ee), uv_(uv), sigma_(Sigma_uv) {}

bool TagCornersModel::Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const {
  r->resize(8);
  for (int k = 0; k < 4; ++k) {
    Eigen::Vector2d uv;
    if (!camera_.Project(T_cam_base_ * (X * p_ee_[k]), &uv)) return false;
    r->segment<2>(2 * k) = uv_[k] - uv - v.segment<2>(2 * k);
  }
  return true;
}

bool TagCornersModel::AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const {
  J_r_X->resize(8, 6);
  for (int k = 0; k < 4; ++k) {
    const Vec3 p_cam = T_cam_base_ * (X * p_ee_[k]);
    if (p_cam.z() <= 1e-9) return false;
    J_r_X->middleRows<2>(2 * k) =
        -ProjectionJacobian(camera_, p_cam) * T_cam_base_.rotation() * PointJacobian(X, p_ee_[k]);
  }
  *J_r_v = -NoiseJac::Identity(8, 8);
  return true;
}

// --- PlaneDistanceModel -----------------------------------------------------------------------

PlaneDistanceModel::PlaneDistanceModel(const lie::SE3& T_base_plane, const Mat6& Sigma_plane,
                                       double sigma_w, const Vec3& p_ee, double distance)
    : T_plane_base_(T_base_plane.Inverse()), p_ee_(p_ee), distance_(distance) {
  sigma_ = NoiseCov::Zero(7, 7);
  sigma_.topLeftCorner<6, 6>() = Sigma_plane;
  sigma_(6, 6) = sigma_w * sigma_w;
}

bool PlaneDistanceModel::Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const {
  const Vec3 q = T_plane_base_ * (X * p_ee_);
  const Vec3 q_true = lie::SE3::Exp(v.head<6>()).Inverse() * q;
  r->resize(1);
  (*r)[0] = distance_ - q_true.z() - v[6];
  return true;
}

bool PlaneDistanceModel::AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X,
                                           NoiseJac* J_r_v) const {
  const Vec3 q = T_plane_base_ * (X * p_ee_);
  *J_r_X = -(T_plane_base_.rotation() * PointJacobian(X, p_ee_)).row(2);
  // Exp(v)^-1 q ~= q - rho - theta x q = q - rho + [q]x theta.
  J_r_v->resize(1, 7);
  J_r_v->leftCols<3>() = Eigen::RowVector3d(0.0, 0.0, 1.0);
  J_r_v->middleCols<3>(3) = -lie::Skew(q).row(2);
  (*J_r_v)(0, 6) = -1.0;
  return true;
}

// --- PositionModel ----------------------------------------------------------------------------

PositionModel::PositionModel(const Vec3& p_ee, const Vec3& p_base, const Mat3& Sigma)
    : p_ee_(p_ee), p_base_(p_base), sigma_(Sigma) {}

bool PositionModel::Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const {
  *r = p_base_ - X * p_ee_ - v.head<3>();
  return true;
}

bool PositionModel::AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const {
  *J_r_X = -PointJacobian(X, p_ee_);
  *J_r_v = -NoiseJac::Identity(3, 3);
  return true;
}

// --- PoseModel --------------------------------------------------------------------------------

PoseModel::PoseModel(const lie::SE3& T_ee_frame, const lie::SE3& Z, const Mat6& Sigma)
    : T_ee_frame_(T_ee_frame), Z_(Z), sigma_(Sigma) {}

bool PoseModel::Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const {
  const lie::SE3 h = (X * T_ee_frame_).Plus(v.head<6>());
  *r = h.Between(Z_).Log();
  return true;
}

bool PoseModel::AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const {
  const Vec6 r0 = (X * T_ee_frame_).Between(Z_).Log();
  const Mat6 Jl_inv = lie::SE3LeftJacobianInverse(r0);
  *J_r_X = -Jl_inv * T_ee_frame_.Inverse().Adjoint();
  *J_r_v = -Jl_inv;
  return true;
}

}  // namespace flexbench::estimators
