// EKF estimators of the end-effector pose (PPOE paper, sec. V): the prior comes from forward
// kinematics at the encoder reading, measurements correct it through LgEkfUpdate.
//   ppoe_ekf:  prior covariance from the PPOE model [PPOE eq. 18], so it changes with the
//              configuration and carries the correlations of the chain.
//   naive_ekf: a static diagonal covariance attached to the end effector (the paper's 'naive'
//              baseline of sec. V-C; params std_trans_m, std_rot_deg in the end-effector
//              frame), or with ppoe_diagonal: 1 the PPOE covariance without its off-diagonal
//              entries (the naive baseline of sec. V-B).
#pragma once

#include <memory>

#include "estimators/estimator.h"

namespace flexbench::estimators {

std::unique_ptr<Estimator> MakePpoeEkf(const EstimatorSetup& setup);
std::unique_ptr<Estimator> MakeNaiveEkf(const EstimatorSetup& setup);

}  // namespace flexbench::estimators
