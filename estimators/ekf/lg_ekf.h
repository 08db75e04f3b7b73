// The Lie-group EKF update on SE(3) [PPOE sec. V-A, eqs. 20-24], iterated.
//
// State: X = T_base_ee with covariance P in its local tangent space (X_true = X Exp(xi)).
// One update with measurement model r(X, v) = z (-) h(X, v) (measurement_model.h) runs a
// Gauss-Newton (iterated EKF) on the manifold. The first iteration is exactly [PPOE eqs. 20-23]:
//   K = P H^T (H P H^T + M Sigma_v M^T)^-1,  m = K r(X, 0),  X+ = X Exp(m),  P+ = (I - K H) P,
// with H = -dr/d(delta) and M = -dr/dv [PPOE eq. 24]. Later iterations relinearise at X_i and carry
// the prior residual e_i = Log(X^-1 X_i) with P_i = Jr(e_i) P Jr(e_i)^T, until |m| < tol. The
// covariance uses the Joseph form, is symmetrised, and the innovation covariance is solved by
// LDLT (no explicit inverse). No heap allocation.
#pragma once

#include "estimators/ekf/measurement_model.h"
#include "estimators/estimator.h"

namespace flexbench::estimators {

struct LgEkfOptions {
  int max_iterations = 10;
  double tolerance = 1e-10;        // on |m|, the tangent-space correction
  bool numeric_jacobians = false;  // force numeric H and M even where analytic ones exist
  double gate_nis = 0.0;           // reject when the NIS exceeds this (0: no gate)
};

struct LgEkfResult {
  UpdateStatus status = UpdateStatus::kAccepted;
  int iterations = 0;
  double nis = 0.0;  // r^T S^-1 r at the prior
};

LgEkfResult LgEkfUpdate(const MeasurementModel& model, const LgEkfOptions& options, lie::SE3* X,
                        Mat6* P);

// Makes P symmetric positive definite: symmetrises and clamps eigenvalues below `floor`.
// Returns true when it had to change more than rounding (a repair to be counted).
bool RepairCovariance(Mat6* P, double floor = 1e-12);

}  // namespace flexbench::estimators
