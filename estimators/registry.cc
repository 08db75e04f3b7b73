// The explicit list of estimators: one line each, chosen by name from scenario files.
#include "estimators/baselines/fk_estimator.h"
#include "estimators/ekf/ekf_estimator.h"
#include "estimators/estimator.h"

namespace flexbench::estimators {

const std::vector<EstimatorEntry>& EstimatorRegistry() {
  static const std::vector<EstimatorEntry> entries = {
      {"fk", "forward kinematics of the declared model, with its PPOE covariance",
       MakeFkEstimator},
      {"ppoe_ekf", "Lie-group EKF with the configuration-dependent PPOE prior", MakePpoeEkf},
      {"naive_ekf", "Lie-group EKF with a static diagonal end-effector prior", MakeNaiveEkf},
  };
  return entries;
}

}  // namespace flexbench::estimators
