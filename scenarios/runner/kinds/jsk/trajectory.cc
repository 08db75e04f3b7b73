#include "scenarios/runner/kinds/jsk/trajectory.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace flexbench::scenarios::jsk {

Trajectory ParseTrajectory(const ConfigNode& node, int nq, bool dynamic) {
  Trajectory tr;
  const ConfigNode wps = node.Child("waypoints_deg");
  for (const ConfigNode& item : wps.Items()) {
    const std::vector<double> v = item.AsDoubleList();
    if (static_cast<int>(v.size()) != nq) {
      item.Fail("expected " + std::to_string(nq) + " angles (declared joint order), got " +
                std::to_string(v.size()));
    }
    Eigen::VectorXd q(nq);
    for (int k = 0; k < nq; ++k) {
      if (!std::isfinite(v[k])) item.Fail("angles must be finite");
      q[k] = v[k] * M_PI / 180.0;
    }
    tr.waypoints.push_back(q);
  }
  if (tr.waypoints.size() < 2) wps.Fail("need at least two waypoints");
  if (dynamic) {
    tr.segment_s = node.GetDouble("segment_s");
    tr.hold_s = node.GetDouble("hold_s", 0.0);
    if (!(tr.segment_s > 0.0)) node.Child("segment_s").Fail("must be > 0");
    if (!(tr.hold_s >= 0.0)) node.Child("hold_s").Fail("must be >= 0");
  } else {
    tr.segment_steps = node.GetInt("segment_steps");
    tr.hold_steps = node.GetInt("hold_steps", 0);
    if (tr.segment_steps < 1) node.Child("segment_steps").Fail("must be >= 1");
    if (tr.hold_steps < 0) node.Child("hold_steps").Fail("must be >= 0");
  }
  return tr;
}

int Trajectory::Steps() const {
  return hold_steps + static_cast<int>(waypoints.size() - 1) * (segment_steps + hold_steps);
}

Eigen::VectorXd Trajectory::AtStep(int k) const {
  if (k < hold_steps) return waypoints.front();
  const int period = segment_steps + hold_steps;
  const int kk = k - hold_steps;
  const int seg = std::min(kk / period, static_cast<int>(waypoints.size()) - 2);
  const int r = kk - seg * period;
  if (r >= segment_steps) return waypoints[seg + 1];
  const double a = static_cast<double>(r + 1) / segment_steps;
  return (1.0 - a) * waypoints[seg] + a * waypoints[seg + 1];
}

double Trajectory::Duration() const {
  return hold_s + static_cast<double>(waypoints.size() - 1) * (segment_s + hold_s);
}

Eigen::VectorXd Trajectory::AtTime(double t, int* segment) const {
  if (segment) *segment = 0;
  if (t <= hold_s) return waypoints.front();
  const double period = segment_s + hold_s;
  const double tt = t - hold_s;
  const int seg = std::min(static_cast<int>(tt / period), static_cast<int>(waypoints.size()) - 2);
  const double r = tt - seg * period;
  if (segment) *segment = seg + 1;
  if (r >= segment_s) return waypoints[seg + 1];
  const double x = r / segment_s;
  const double a = x * x * (3.0 - 2.0 * x);  // smooth start and stop
  return (1.0 - a) * waypoints[seg] + a * waypoints[seg + 1];
}

}  // namespace flexbench::scenarios::jsk
