// Measurement models of an end-effector pose X = T_base_ee for the Lie-group EKF (PPOE paper,
// [PPOE eq. 19]: z = h(X, v), v ~ N(0, Sigma_v)).
//
// A model returns the residual r(X, v) = z (-) h(X, v) (plain difference for Euclidean
// measurements, Log for poses) and, where it has them, the analytic Jacobians
// J_r_X = dr/d(delta) for X (+) delta = X Exp(delta) and J_r_v = dr/dv at v = 0. The paper's
// H and M [PPOE eq. 24] are H = -J_r_X and M = -J_r_v. NumericJacobians gives both by central
// differences on the manifold for any model; a test checks they agree with the analytic ones.
//
// Sizes are bounded (kMaxMeasDim, kMaxNoiseDim) so that no update allocates.
#pragma once

#include <Eigen/Core>
#include <array>

#include "estimators/camera/pinhole.h"
#include "estimators/conventions.h"
#include "estimators/lie/se3.h"

namespace flexbench::estimators {

inline constexpr int kMaxMeasDim = 8;
inline constexpr int kMaxNoiseDim = 8;
using MeasVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasDim, 1>;
using NoiseVec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxNoiseDim, 1>;
using MeasJac = Eigen::Matrix<double, Eigen::Dynamic, 6, 0, kMaxMeasDim, 6>;
using NoiseJac =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasDim, kMaxNoiseDim>;
using NoiseCov =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxNoiseDim, kMaxNoiseDim>;
using MeasCov = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasDim, kMaxMeasDim>;

class MeasurementModel {
 public:
  virtual ~MeasurementModel() = default;
  virtual int Dim() const = 0;
  virtual int NoiseDim() const = 0;
  virtual const NoiseCov& Sigma_v() const = 0;
  // r = z (-) h(X, v). Returns false when h is undefined at X (e.g. a point behind the camera).
  virtual bool Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const = 0;
  // Analytic J_r_X and J_r_v at (X, v = 0); false when the model has none.
  virtual bool AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const {
    return false;
  }
};

// Central differences on the manifold: column j of J_r_X from r(X Exp(+-eps e_j), 0), column j
// of J_r_v from r(X, +-eps e_j). Returns false when a residual is undefined.
bool NumericJacobians(const MeasurementModel& model, const lie::SE3& X, MeasJac* J_r_X,
                      NoiseJac* J_r_v, double eps = 1e-6);

// Pixel projection of a point fixed to the end effector [PPOE eq. 25]:
// h = pi(T_cam_base X p_ee) + v, v ~ N(0, Sigma_uv).
class PixelPointModel : public MeasurementModel {
 public:
  PixelPointModel(const PinholeCamera& camera, const lie::SE3& T_base_cam, const Vec3& p_ee,
                  const Eigen::Vector2d& uv, const Eigen::Matrix2d& Sigma_uv);
  int Dim() const override { return 2; }
  int NoiseDim() const override { return 2; }
  const NoiseCov& Sigma_v() const override { return sigma_; }
  bool Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const override;
  bool AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const override;

 private:
  PinholeCamera camera_;
  lie::SE3 T_cam_base_;
  Vec3 p_ee_;
  Eigen::Vector2d uv_;
  NoiseCov sigma_;
};

// The four corners of a tag fixed to the end effector, stacked [u0 v0 ... u3 v3].
class TagCornersModel : public MeasurementModel {
 public:
  TagCornersModel(const PinholeCamera& camera, const lie::SE3& T_base_cam,
                  const std::array<Vec3, 4>& p_ee, const std::array<Eigen::Vector2d, 4>& uv,
                  const Eigen::Matrix<double, 8, 8>& Sigma_uv);
  int Dim() const override { return 8; }
  int NoiseDim() const override { return 8; }
  const NoiseCov& Sigma_v() const override { return sigma_; }
  bool Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const override;
  bool AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const override;

 private:
  PinholeCamera camera_;
  lie::SE3 T_cam_base_;
  std::array<Vec3, 4> p_ee_;
  std::array<Eigen::Vector2d, 4> uv_;
  NoiseCov sigma_;
};

// Signed distance of a point on the end effector (a fingertip) along the normal (z axis) of a
// plane whose pose is uncertain (PPOE paper sec. V-B): h = e_z^T (Exp(v_p)^-1 Tbar_plane^-1 X p)
// + w, noise [v_p (6, the plane's local pose error); w (the distance sensor)].
class PlaneDistanceModel : public MeasurementModel {
 public:
  PlaneDistanceModel(const lie::SE3& T_base_plane, const Mat6& Sigma_plane, double sigma_w,
                     const Vec3& p_ee, double distance);
  int Dim() const override { return 1; }
  int NoiseDim() const override { return 7; }
  const NoiseCov& Sigma_v() const override { return sigma_; }
  bool Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const override;
  bool AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const override;

 private:
  lie::SE3 T_plane_base_;
  Vec3 p_ee_;
  double distance_;
  NoiseCov sigma_;
};

// 3-D position of a point on the end effector in the base frame: h = X p_ee + v.
class PositionModel : public MeasurementModel {
 public:
  PositionModel(const Vec3& p_ee, const Vec3& p_base, const Mat3& Sigma);
  int Dim() const override { return 3; }
  int NoiseDim() const override { return 3; }
  const NoiseCov& Sigma_v() const override { return sigma_; }
  bool Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const override;
  bool AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const override;

 private:
  Vec3 p_ee_;
  Vec3 p_base_;
  NoiseCov sigma_;
};

// Full pose of a frame rigidly attached to the end effector: Z = X T_ee_frame Exp(v),
// r = Log((X T_ee_frame)^-1 Z).
class PoseModel : public MeasurementModel {
 public:
  PoseModel(const lie::SE3& T_ee_frame, const lie::SE3& Z, const Mat6& Sigma);
  int Dim() const override { return 6; }
  int NoiseDim() const override { return 6; }
  const NoiseCov& Sigma_v() const override { return sigma_; }
  bool Residual(const lie::SE3& X, const NoiseVec& v, MeasVec* r) const override;
  bool AnalyticJacobians(const lie::SE3& X, MeasJac* J_r_X, NoiseJac* J_r_v) const override;

 private:
  lie::SE3 T_ee_frame_;
  lie::SE3 Z_;
  NoiseCov sigma_;
};

}  // namespace flexbench::estimators
