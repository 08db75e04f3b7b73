// The logs of this suite's pendulums: actuated joint "j" following amplitude sin(2 pi hz t),
// its encoder rows and servo commands at 500 Hz for `seconds`, the readings the commands
// themselves (noise stated as 1e-3 rad).
#pragma once

#include <cmath>

#include "sim/recorded_log.h"

namespace flexbench::identify::dynamic {

inline sim::RecordedLog SineLog(double amplitude, double seconds = 1.0, double hz = 1.0) {
  sim::RecordedLog log;
  log.dir = "/tmp/pendulum_log";
  log.joints = log.command_joints = {"j"};
  log.joint_is_slide = log.command_is_slide = {0};
  log.joint_std = 1e-3;
  const int rows = static_cast<int>(std::lround(seconds * 500.0));
  for (int k = 0; k <= rows; ++k) {
    const double t = 0.002 * k, q = amplitude * std::sin(2 * M_PI * hz * t);
    log.joint_t.push_back(t);
    log.joint_q.push_back(q);
    log.command_t.push_back(t);
    log.command_q.push_back(q);
  }
  return log;
}

}  // namespace flexbench::identify::dynamic
