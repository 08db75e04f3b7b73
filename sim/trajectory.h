// Dynamic runs: timed joint-space waypoints joined by minimum-jerk segments (zero velocity and
// acceleration at every waypoint), and a loop that steps the truth along them while sensors
// sample at their own rates.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::sim {

class JointTrajectory {
 public:
  // Waypoints in increasing time (s); q in the simulation's command order.
  void Add(double t, const Eigen::VectorXd& q);
  // Commanded angles at time t (held at the ends).
  Eigen::VectorXd At(double t) const;
  double start() const { return times_.empty() ? 0.0 : times_.front(); }
  double end() const { return times_.empty() ? 0.0 : times_.back(); }
  bool empty() const { return times_.empty(); }

 private:
  std::vector<double> times_;
  std::vector<Eigen::VectorXd> points_;
};

// Steps `sim` from its current time to traj.end() (+ `hold_s`), commanding traj.At(t) before
// every step and polling `sensors` (may be null) after it. Throws SimulationError on divergence.
void RunTrajectory(Simulation& sim, const JointTrajectory& traj, double hold_s,
                   SensorSuite* sensors, std::vector<SensorReading>* readings);

}  // namespace flexbench::sim
