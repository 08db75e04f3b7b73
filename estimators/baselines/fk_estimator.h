// `fk`: forward kinematics of the declared model alone ([PPOE eq. 17] with xi = 0), with
// the PPOE covariance it declares [PPOE eq. 18] so its NEES says whether that declaration is
// honest.
#pragma once

#include <memory>

#include "estimators/estimator.h"

namespace flexbench::estimators {

std::unique_ptr<Estimator> MakeFkEstimator(const EstimatorSetup& setup);

}  // namespace flexbench::estimators
