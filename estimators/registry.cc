// The explicit list of estimators: one line each, chosen by name from scenario files.
#include "estimators/baselines/fk_estimator.h"
#include "estimators/ekf/ekf_estimator.h"
#include "estimators/estimator.h"
#include "estimators/imu/direct_fusion.h"
#include "estimators/pf/pf_estimator.h"

namespace flexbench::estimators {

const std::vector<EstimatorEntry>& EstimatorRegistry() {
  static const std::vector<EstimatorEntry> entries = {
      {"fk", "forward kinematics of the declared model, with its PPOE covariance", MakeFkEstimator},
      {"ppoe_ekf", "Lie-group EKF with the configuration-dependent PPOE prior", MakePpoeEkf},
      {"naive_ekf", "Lie-group EKF with a static diagonal end-effector prior", MakeNaiveEkf},
      {"pf_encoders", "von Mises particle filter: reference angles only [PF eq. 28]",
       MakePfEncoders},
      {"pf_encoders_ee", "von Mises particle filter: reference angles + end-effector position",
       MakePfEncodersEe},
      {"pf_encoders_imu",
       "von Mises particle filter: reference angles + axis-symmetric Bingham IMUs",
       MakePfEncodersImu},
      {"pf_all", "von Mises particle filter: reference angles + end-effector position + IMUs",
       MakePfAll},
      {"pf_bingham_unimodal", "particle filter, IMUs with a unimodal Bingham (yaw penalised)",
       MakePfBinghamUnimodal},
      {"pf_bingham_axisym", "particle filter, IMUs with an axis-symmetric Bingham (yaw free)",
       MakePfBinghamAxisym},
      {"direct_fusion_xyz", "PF paper's direct IMU fusion, Euler order xyz, yaw zeroed",
       MakeDirectFusionXyz},
      {"direct_fusion_yxz", "PF paper's direct IMU fusion, Euler order yxz, yaw zeroed",
       MakeDirectFusionYxz},
  };
  return entries;
}

}  // namespace flexbench::estimators
