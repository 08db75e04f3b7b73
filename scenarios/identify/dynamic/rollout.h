// Rollouts of the declared model's MJCF over a recorded log (multiple shooting): each segment
// starts from the recorded encoder angles and speeds, the logged commands drive the servos, and
// the joints no encoder sees (bending, base plate) carry their state from the segment before.
// The residual is each prediction minus its reading over the reading's noise: encoder angles,
// then each IMU's gyro and accelerometer.
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

enum class Stream { kEncoder = 0, kGyro = 1, kAccel = 2 };

// Where each residual entry comes from.
struct ResidualLayout {
  std::vector<int> segment;   // per entry
  std::vector<char> stream;   // Stream
  std::vector<int> channel;   // joint (encoders), IMU * 3 + axis (gyro, accel)
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

// Rolls the model with `terms` over every segment of `data`.
Prediction Rollout(const RolloutModel& model, const std::vector<DynamicTerm>& terms,
                   const MotionData& data, const ResidualLayout& layout);

// The noise of each stream the log does not give: the spread of the residual's first
// differences over sqrt(2) (white noise's; a model's smooth error hardly changes from one
// reading to the next).
void SetUnknownNoise(const ResidualLayout& layout, const Eigen::VectorXd& raw_error,
                     MotionData* data);

}  // namespace flexbench::identify::dynamic
