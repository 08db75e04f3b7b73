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
  };
  return kinds;
}

}  // namespace flexbench::scenarios
