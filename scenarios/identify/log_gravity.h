// Gravity rows from a recorded log's IMUs: where the arm rests, an accelerometer's mean reading
// is the up direction in its frame (specific force, +g up at rest), which the declared model
// predicts from the encoders. A joint offset, a bending link, a compliant base plate or a base
// mounted off level turn it; the identification compares the two (ObservationType::kGravity;
// AppendLogGravity in calibration_data.h makes the rows).
#pragma once
#include <Eigen/Core>
#include <vector>

#include "scenarios/identify/identify.h"
#include "sim/recorded_log.h"

namespace flexbench::identify {

// When a stretch of a log counts as the arm at rest.
struct StaticWindowOptions {
  double min_s = 0.5;             // the shortest window
  double gyro_max_rad_s = 0.05;   // every reading's angular rate at most this
  double joint_span_rad = 0.005;  // every joint's readings within this span (m for a slide)
};

// One IMU at rest over [t_begin, t_end].
struct StaticWindow {
  int sensor = 0;  // index into RecordedLog::imus
  double t_begin = 0.0, t_end = 0.0;
  int readings = 0;
  Eigen::VectorXd q;        // the mean joint readings (declared order) at its readings' times
  Vec3 up = Vec3::Zero();   // the mean accelerometer reading, normalised (sensor frame)
  double accel_norm = 0.0;  // the mean reading's length (m/s^2; 9.81 when the units are right)
  // The standard error of up's direction from the readings' scatter (rad, about each axis
  // normal to it): noise alone; an accelerometer's bias is not in it.
  double std_rad = 0.0;
};

// Each IMU's longest stretches in [t_from, t_to], inside the joints' span, over which every
// reading's angular rate and every joint's spread stay within `opt`, at least opt.min_s long
// and of 10 readings (`column`: sim::JointColumns). In time order per sensor, sensors in
// their order.
std::vector<StaticWindow> FindStaticWindows(const sim::RecordedLog& log,
                                            const std::vector<int>& column, double t_from,
                                            double t_to, const StaticWindowOptions& opt = {});

// Each declared joint's smallest step between consecutive different readings in joints.csv (its
// encoder's count where the readings are quantised; 0 when it never moves): a reading's
// rounding error is then up to half of it, count / sqrt(12) rms.
std::vector<double> ReadingSteps(const sim::RecordedLog& log, const std::vector<int>& column);

}  // namespace flexbench::identify
