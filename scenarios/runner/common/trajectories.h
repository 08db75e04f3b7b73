// Trajectories in the TUM format that evo and most SLAM tools read: one pose a line,
// "timestamp tx ty tz qx qy qz qw", space separated, metres and seconds, written with 17
// significant digits so that a reader recomputes the scenario's own errors from the files. The
// TUM format has no covariance, so each estimator's is written beside it.
//
//   trajectories/<frame>/truth.tum          the true pose of the end effector in <frame>
//   trajectories/<frame>/ESTIMATOR.tum      each estimator's mean
//   trajectories/<frame>/ESTIMATOR.cov.csv  timestamp, then the 21 upper-triangle entries (row
//                                           by row) of its 6x6 covariance in the estimate's
//                                           local tangent [rho; theta] (estimators/conventions.h)
#pragma once

#include <map>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"
#include "scenarios/runner/output.h"

namespace flexbench::scenarios {

class TrajectoryRecorder {
 public:
  void AddTruth(double t, const lie::SE3& T_frame_ee);
  void Add(const std::string& estimator, double t, const lie::SE3& T_frame_ee, const Mat6& cov);
  // Writes the files under trajectories/<frame>/ (`frame` names the coordinates), or under
  // trajectories/<frame>/<part>/ when a run has several trajectories (before / after).
  void Write(const OutputDir& out, const std::string& frame, const std::string& part = "") const;

 private:
  struct Pose {
    double t;
    lie::SE3 T;
    Mat6 cov;
  };
  std::vector<Pose> truth_;
  std::map<std::string, std::vector<Pose>> estimates_;
};

// One TUM line (no newline).
std::string TumLine(double t, const lie::SE3& T);

}  // namespace flexbench::scenarios
