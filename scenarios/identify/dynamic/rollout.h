// Rollouts of the declared model's MJCF over a recorded log (multiple shooting): each segment
// starts from the recorded encoder angles and speeds, the logged commands drive the servos, and
// the joints no encoder sees (bending, base plate) carry their state from the segment before.
// A fold's rollout starts from the static state four segments before it, those rolled and not
// scored, so that it reaches the fold with about the state the segments before carry.
// The residual is each prediction minus its reading over the reading's noise: encoder angles,
// each IMU's gyro and accelerometer, and the tags' corner pixels (the model's tag frame seen from
// its camera frame through the pinhole).
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "scenarios/identify/dynamic/motion_data.h"
#include "sim/dynamic_effects.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"

namespace flexbench::identify::dynamic {

// A dynamic row's values at one location (sim::ApplyDynamic).
struct DynamicTerm {
  sim::DynamicKind kind = sim::DynamicKind::kJointDamping;
  std::string location;
  double values[2] = {0.0, 0.0};
};

// The declared model's MJCF, loaded once, with the dynamic terms the declared model has.
class RolloutModel {
 public:
  RolloutModel(sim::MjModelPtr model, std::string name, std::vector<DynamicTerm> declared);
  // A simulation of the model with `terms` beside the declared ones. Thread-safe.
  std::unique_ptr<sim::Simulation> Make(const std::vector<DynamicTerm>& terms) const;
  const sim::Simulation& nominal() const { return *nominal_; }

 private:
  sim::MjModelPtr model_;
  std::string name_;
  std::vector<DynamicTerm> declared_;
  std::unique_ptr<sim::Simulation> nominal_;
};

enum class Stream { kEncoder = 0, kGyro = 1, kAccel = 2, kTagPixel = 3 };
inline constexpr int kStreams = 4;

// A tag pixel entry's channel: (camera * tags + tag) * 8 + corner * 2 + axis (0 u, 1 v).
inline int TagChannel(int camera, int tag, int tags, int corner, int axis) {
  return ((camera * tags + tag) * 4 + corner) * 2 + axis;
}
inline int TagPairOf(int channel) { return channel / 8; }  // camera * tags + tag
inline int TagCornerOf(int channel) { return (channel % 8) / 2; }
inline int TagAxisOf(int channel) { return channel % 2; }

// Where each residual entry comes from.
struct ResidualLayout {
  std::vector<int> segment;   // per entry
  std::vector<char> stream;   // Stream
  std::vector<int> channel;   // joint (encoders), IMU * 3 + axis (gyro, accel), TagChannel
  std::vector<double> t;      // its reading's time
  std::vector<double> value;  // the reading
  int size() const { return static_cast<int>(segment.size()); }
};
ResidualLayout MakeLayout(const MotionData& data);

struct Prediction {
  Eigen::VectorXd error;       // prediction - reading, per layout entry
  Eigen::VectorXd residual;    // error / the stream's std (1 while unknown)
  std::vector<char> diverged;  // per segment
  int num_diverged = 0;
  std::string first_divergence;  // the simulation's message
};

// A prediction of nothing yet: zero entries, no segment diverged.
Prediction NewPrediction(const MotionData& data, const ResidualLayout& layout);

// Rolls the model with `terms` over the segments of fold `fold` into their entries of `p` (made
// by NewPrediction; other entries are left alone, so folds may be rolled side by side into one
// prediction). A fold starts from the static state four segments before its first (those
// rolled, not scored): no fold's rollout depends on another's, so a held-out fold is rolled
// alone and the folds of one rollout in parallel.
// `start_qd` replaces data.start_qd when given. Returns the message of the fold's first
// divergence ("" if none).
std::string RolloutFold(const RolloutModel& model, const std::vector<DynamicTerm>& terms,
                        const MotionData& data, const ResidualLayout& layout, int fold,
                        Prediction* p, const Eigen::MatrixXd* start_qd = nullptr);
// num_diverged and first_divergence (the first fold's that has one) once the folds are rolled.
void FinishPrediction(const std::vector<std::string>& fold_divergence, Prediction* p);

// Rolls the model with `terms` over every fold of `data`, one after the other.
Prediction Rollout(const RolloutModel& model, const std::vector<DynamicTerm>& terms,
                   const MotionData& data, const ResidualLayout& layout);

// The noise of each stream the log does not give: the spread of the residual's first
// differences over sqrt(2) (white noise's; a model's smooth error hardly changes from one
// reading to the next).
void SetUnknownNoise(const ResidualLayout& layout, const Eigen::VectorXd& raw_error,
                     MotionData* data);

}  // namespace flexbench::identify::dynamic
