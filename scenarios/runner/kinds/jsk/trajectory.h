// The reference trajectory of the jsk kinds: waypoints in the declared joint order and their
// timing, in filter steps (synthetic kinds) or seconds (dynamic kinds).
//
//   trajectory:                           # reference angles, declared joint order, degrees
//     waypoints_deg: [[0, 0, 0, 0], [30, 60, 30, 10]]
//     segment_steps: 30                   # synthetic scenarios: filter steps per segment
//     hold_steps: 10                      #                      steps at rest at each waypoint
//     segment_s: 2.0                      # dynamic scenarios: motion time per segment
//     hold_s: 1.0                         #                    rest at each waypoint
#pragma once

#include <Eigen/Core>
#include <vector>

#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"

namespace flexbench::scenarios::jsk {

// Reference waypoints (declared order, radians) and the per-segment timing.
struct Trajectory {
  std::vector<Eigen::VectorXd> waypoints;
  int segment_steps = 0;
  int hold_steps = 0;
  double segment_s = 0.0;
  double hold_s = 0.0;
  // Synthetic: the reference at filter step k (hold_steps at the first waypoint, then per
  // segment a linear move of segment_steps and a hold of hold_steps), k < Steps().
  int Steps() const;
  Eigen::VectorXd AtStep(int k) const;
  // Dynamic: the reference at time t (smooth-step between waypoints, holds at each), t <=
  // Duration(); `segment` returns the index of the waypoint being approached or held.
  double Duration() const;
  Eigen::VectorXd AtTime(double t, int* segment = nullptr) const;
};
Trajectory ParseTrajectory(const ConfigNode& node, int nq, bool dynamic);

}  // namespace flexbench::scenarios::jsk
