// MuJoCo-side poses (Eigen::Isometry3d from sim::Simulation) as the estimators' SE3.
#pragma once
#include <Eigen/Geometry>

#include "estimators/lie/se3.h"

namespace flexbench::scenarios {

inline lie::SE3 ToSE3(const Eigen::Isometry3d& T) { return lie::SE3(T.linear(), T.translation()); }

}  // namespace flexbench::scenarios
