#include "scenarios/runner/kinds/kinds.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

const std::vector<KindEntry>& ScenarioKinds() {
  // One line per kind.
  static const std::vector<KindEntry> kinds = {
      {"smoke", "one rendered frame through every layer: MJCF, OSMesa, libapriltag, truth",
       MakeSmokeKind},
      {"rover_deflection", "rover arm folded to stretched out: plate tilt, EE deflection",
       MakeRoverDeflectionKind},
      {"ppoe_covariance", "PPOE end-effector covariance (2nd, 4th order) against Monte Carlo",
       MakePpoeCovarianceKind},
      {"tag_fusion", "rendered AprilTags fused with kinematics by each estimator (Table I)",
       MakeTagFusionKind},
      {"contact_fusion", "a fingertip's 1-D table contact fused iteratively (Fig. 5)",
       MakeContactFusionKind},
      {"tag_detection_sweep", "one tag swept over distance, view angle and rotation: detection",
       MakeTagDetectionSweepKind},
      {"jsk_sim_deflection",
       "PF paper sec. IV-B: [PF eq. 31] deflection, filters with various sensors",
       MakeJskSimDeflectionKind},
      {"jsk_flexible_arm",
       "PF paper sec. IV-C: gripper of the compliant jsk_arm, fk vs particle filters",
       MakeJskFlexibleArmKind},
      {"jsk_imu_yaw_drift",
       "PF paper sec. IV-E: drifting IMU yaw, unimodal vs axis-symmetric Bingham",
       MakeJskImuYawDriftKind},
      {"jsk_direct_fusion", "PF paper sec. IV-D: direct IMU fusion ('xyz', 'yxz') vs the filter",
       MakeJskDirectFusionKind},
      {"jsk_particle_sweep", "PF paper sec. V-A: number of particles and kappa_v sweep",
       MakeJskParticleSweepKind},
      {"closed_loop", "measured data -> residual -> undeclared effects found, fitted, validated",
       MakeClosedLoopKind},
      {"closed_loop_estimators",
       "estimate -> identify -> estimate with the augmented model, before/after per estimator",
       MakeClosedLoopEstimatorsKind},
      {"mismatch_matrix", "every estimator against every undeclared effect: error and NEES",
       MakeMismatchMatrixKind},
      {"replay", "a recorded log (joints, IMUs, truth) through the estimators", MakeReplayKind},
      {"closed_loop_dynamic",
       "the closed loop on a moving arm: the truth's log, the dynamic effect the model lacks",
       MakeClosedLoopDynamicKind},
  };
  return kinds;
}

}  // namespace flexbench::scenarios
