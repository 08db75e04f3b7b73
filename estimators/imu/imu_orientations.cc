#include "estimators/imu/imu_orientations.h"

#include <cmath>
#include <string>

#include "estimators/error.h"

namespace flexbench::imu {

ImuOrientations::ImuOrientations(const std::vector<estimators::ImuSetup>& imus)
    : imus_(imus), state_(imus.size()) {
  for (size_t k = 0; k < imus.size(); ++k) {
    filters_.emplace_back(imus[k].filter_beta);                                // checks the gain
    if (imus[k].has_initial) filters_[k].Reset(imus[k].q_base_frame_initial);  // and this
  }
}

void ImuOrientations::Reset() {
  for (State& s : state_) s = State{};
}

estimators::UpdateStatus ImuOrientations::Feed(const estimators::ImuReading& z) {
  using estimators::UpdateStatus;
  if (z.imu < 0 || z.imu >= size()) {
    throw InputError("IMU reading for IMU " + std::to_string(z.imu) + ": the set-up has " +
                     std::to_string(size()));
  }
  if (!std::isfinite(z.t) || !z.gyro.allFinite() || !z.accel.allFinite()) {
    return UpdateStatus::kRejectedNonFinite;
  }
  State& s = state_[z.imu];
  Madgwick& f = filters_[z.imu];
  if (!s.started) {
    const estimators::ImuSetup& setup = imus_[z.imu];
    if (setup.has_initial) {
      f.Reset(setup.q_base_frame_initial);
    } else {
      if (!(z.accel.norm() > 0.0)) return UpdateStatus::kRejectedOutside;
      f.InitFromAccel(z.accel);
    }
    s.started = true;
  } else {
    if (z.t < s.last_t) return UpdateStatus::kRejectedOutside;
    f.Update(z.gyro, z.accel, z.t - s.last_t);
  }
  s.last_t = z.t;
  s.fresh = true;
  return UpdateStatus::kAccepted;
}

estimators::OrientationReading ImuOrientations::Take(int k) {
  state_[k].fresh = false;
  estimators::OrientationReading o;
  o.t = state_[k].last_t;
  o.frame = imus_[k].frame;
  o.q_base_frame = filters_[k].orientation();
  return o;
}

}  // namespace flexbench::imu
