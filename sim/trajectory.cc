#include "sim/trajectory.h"

#include <stdexcept>

namespace flexbench::sim {

void JointTrajectory::Add(double t, const Eigen::VectorXd& q) {
  if (!times_.empty() && !(t > times_.back())) {
    throw std::invalid_argument("JointTrajectory: waypoint times must increase");
  }
  if (!points_.empty() && q.size() != points_.front().size()) {
    throw std::invalid_argument("JointTrajectory: waypoints of different sizes");
  }
  times_.push_back(t);
  points_.push_back(q);
}

Eigen::VectorXd JointTrajectory::At(double t) const {
  if (times_.empty()) throw std::logic_error("JointTrajectory: no waypoints");
  if (t <= times_.front()) return points_.front();
  if (t >= times_.back()) return points_.back();
  size_t k = 1;
  while (times_[k] < t) ++k;
  const double s = (t - times_[k - 1]) / (times_[k] - times_[k - 1]);
  const double blend = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));  // minimum jerk
  return points_[k - 1] + blend * (points_[k] - points_[k - 1]);
}

void RunTrajectory(Simulation& sim, const JointTrajectory& traj, double hold_s,
                   SensorSuite* sensors, std::vector<SensorReading>* readings) {
  const double t_end = traj.end() + hold_s;
  const double dt = sim.timestep();
  if (sensors) sensors->Poll(sim, readings);
  while (sim.time() + 0.5 * dt < t_end) {
    sim.SetCommand(traj.At(sim.time()));
    sim.Step(1);
    if (sensors) sensors->Poll(sim, readings);
  }
}

}  // namespace flexbench::sim
