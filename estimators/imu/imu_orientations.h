// The orientation of each IMU of the set-up from its raw readings: one Madgwick filter per IMU
// (madgwick.h), fed with ImuReadings, as the particle-filter paper runs one per link IMU (Fig. 5).
// The estimators that use IMU orientations hold one, so that raw gyro and accelerometer
// readings reach them alike from a simulation, a recorded log or Python.
//
// The filter's earth frame is the declared model's base frame, z up (the base of an arm mounted
// upright). Its first reading of an IMU starts that IMU's filter: at ImuSetup's initial
// orientation when one is given (a calibrated yaw), else at the accelerometer's "up" with no
// yaw about the vertical. Each later reading is one filter step over the time since the last.
#pragma once

#include <vector>

#include "estimators/estimator.h"
#include "estimators/imu/madgwick.h"

namespace flexbench::imu {

class ImuOrientations {
 public:
  // One filter per entry (InputError for a gain that is not positive and finite, or an initial
  // orientation that is not a finite, non-zero quaternion).
  explicit ImuOrientations(const std::vector<estimators::ImuSetup>& imus);

  // Every filter back to "no reading yet".
  void Reset();
  // One reading of IMU z.imu (InputError when the set-up has no such IMU): kAccepted; or
  // kRejectedNonFinite (a NaN or infinite value), kRejectedOutside (a time before that IMU's last
  // reading, or a first reading without initial orientation whose accelerometer reads zero),
  // both leaving the filter as it was.
  estimators::UpdateStatus Feed(const estimators::ImuReading& z);

  int size() const { return static_cast<int>(filters_.size()); }
  // Whether IMU k has had its first reading (it has an orientation).
  bool ready(int k) const { return state_[k].started; }
  // Whether IMU k has had a reading since its orientation was last taken.
  bool fresh(int k) const { return state_[k].fresh; }
  // IMU k's orientation as the reading of its frame, at its last reading's time (k ready);
  // clears fresh(k).
  estimators::OrientationReading Take(int k);

 private:
  struct State {
    bool started = false;
    bool fresh = false;
    double last_t = 0.0;
  };
  std::vector<estimators::ImuSetup> imus_;
  std::vector<Madgwick> filters_;
  std::vector<State> state_;
};

}  // namespace flexbench::imu
