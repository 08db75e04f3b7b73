#include "estimators/ekf/lg_ekf.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace flexbench::estimators {
namespace {

bool Jacobians(const MeasurementModel& model, const LgEkfOptions& options, const lie::SE3& X,
               MeasJac* J_r_X, NoiseJac* J_r_v) {
  if (!options.numeric_jacobians && model.AnalyticJacobians(X, J_r_X, J_r_v)) return true;
  return NumericJacobians(model, X, J_r_X, J_r_v);
}

}  // namespace

bool RepairCovariance(Mat6* P, double floor) {
  if (!P->allFinite()) {
    *P = Mat6::Identity() * floor;
    return true;
  }
  const Mat6 sym = 0.5 * (*P + P->transpose());
  Eigen::SelfAdjointEigenSolver<Mat6> eig(sym);
  if (eig.eigenvalues().minCoeff() >= floor) {
    *P = sym;
    return false;
  }
  const Vec6 clamped = eig.eigenvalues().cwiseMax(floor);
  *P = eig.eigenvectors() * clamped.asDiagonal() * eig.eigenvectors().transpose();
  return true;
}

LgEkfResult LgEkfUpdate(const MeasurementModel& model, const LgEkfOptions& options, lie::SE3* X,
                        Mat6* P) {
  LgEkfResult result;
  const int m = model.Dim();
  const NoiseVec zero = NoiseVec::Zero(model.NoiseDim());
  const lie::SE3 X_prior = *X;
  const Mat6 P_prior = *P;

  MeasVec r(m);
  MeasJac J_r_X(m, 6);
  NoiseJac J_r_v(m, model.NoiseDim());
  MeasCov R(m, m), S(m, m);
  Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, kMaxMeasDim> K(6, m);
  MeasJac H(m, 6);
  lie::SE3 X_i = X_prior;
  Mat6 P_i = P_prior;

  for (int it = 0; it < options.max_iterations; ++it) {
    if (!model.Residual(X_i, zero, &r)) {
      result.status = UpdateStatus::kRejectedOutside;
      return result;
    }
    if (!r.allFinite()) {
      result.status = UpdateStatus::kRejectedNonFinite;
      return result;
    }
    if (!Jacobians(model, options, X_i, &J_r_X, &J_r_v)) {
      result.status = UpdateStatus::kRejectedOutside;
      return result;
    }
    H = -J_r_X;
    R = J_r_v * model.Sigma_v() * J_r_v.transpose();
    // Prior residual at the linearisation point and the prior covariance moved there.
    const Vec6 e = X_prior.Between(X_i).Log();
    const Mat6 Jr = lie::SE3RightJacobian(e);
    P_i = Jr * P_prior * Jr.transpose();
    S = H * P_i * H.transpose() + R;
    const Eigen::LDLT<MeasCov> ldlt(S);
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
      result.status = UpdateStatus::kRejectedNonFinite;
      return result;
    }
    if (it == 0) result.nis = r.dot(ldlt.solve(r));
    if (options.gate_nis > 0.0 && it == 0 && result.nis > options.gate_nis) {
      result.status = UpdateStatus::kRejectedGating;
      return result;
    }
    K = ldlt.solve(H * P_i).transpose();
    // Gauss-Newton step in Kalman form: pull back to the prior by -Jr e, then correct.
    const Vec6 pull = -Jr * e;
    const Vec6 step = pull + K * (r - H * pull);
    X_i = X_i.Plus(step);
    result.iterations = it + 1;
    if (!step.allFinite()) {
      result.status = UpdateStatus::kRejectedNonFinite;
      return result;
    }
    if (step.norm() < options.tolerance) break;
  }
  // Joseph form at the final linearisation.
  const Mat6 IKH = Mat6::Identity() - K * H;
  Mat6 P_new = IKH * P_i * IKH.transpose() + K * R * K.transpose();
  P_new = 0.5 * (P_new + P_new.transpose());
  if (!P_new.allFinite() || !X_i.rotation().allFinite() || !X_i.translation().allFinite()) {
    result.status = UpdateStatus::kRejectedNonFinite;
    return result;
  }
  *X = X_i;
  *P = P_new;
  return result;
}

}  // namespace flexbench::estimators
