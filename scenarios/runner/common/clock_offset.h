// The clock offset between a log's IMU stream and its joints, from the data: the gyros' angular
// speed against the speed the encoders give each IMU's frame through the declared kinematics,
// cross-correlated over a range of lags. Angular speed |omega| does not depend on the frame it is
// written in, so the IMUs' mounting and yaw do not enter.
#pragma once

#include <vector>

#include "estimators/kinematics/ppoe_model.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {

struct ClockOffset {
  double offset_s = 0.0;   // to add to the IMU times (their clock_offset_s)
  double std_s = 0.0;      // its standard error, from the spread over the log's segments
  int segments = 0;        // of them, those with a peak (std_s needs two)
  double correlation = 0;  // the normalised correlation at the offset (1: the same shape)
};

// `column[k]`: the joints.csv column of the model's joint k; `frames[i]`: the model frame of the
// log's IMU i. Lags within +-max_offset_s, on a grid of a quarter of the joints' median step,
// refined by a parabola through the peak. InputError when the log has no IMU readings or too
// little motion to correlate.
ClockOffset EstimateImuClockOffset(const sim::RecordedLog& log, const kinematics::PpoeModel& model,
                                   const std::vector<int>& column,
                                   const std::vector<kinematics::FrameId>& frames,
                                   double max_offset_s);

}  // namespace flexbench::scenarios
