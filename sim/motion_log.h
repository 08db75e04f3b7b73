// A moving arm's log from the truth: its servos driven through a multi-sine, its sensors polled
// at their rates, the commands, the encoder rows and every IMU reading gathered as a recorded log
// (sim/recorded_log.h) that dynamic identification reads as a user's.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "sim/recorded_log.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::sim {

// Per actuated joint: center + amplitude * (sum of sines, each joint its own permutation of the
// frequencies, scaled by 1 + 0.07 joint so the joints' motions differ) / count, faded in over the
// first second so the servos start at rest.
struct MultiSine {
  std::vector<double> center, amplitude;  // rad (m), per actuated joint
  std::vector<double> frequencies;        // Hz
  std::vector<double> phase;              // per joint and frequency (DrawPhases)
  // Phases uniform in [0, 2 pi) from the seed's stream `name`.
  void DrawPhases(std::uint64_t seed, const std::string& name, int joints);
  double At(int joint, double t) const;
};

struct MotionLogOptions {
  double duration_s = 12.0;
  double command_rate_hz = 500.0;
  // What the log states as its readings' noise (0: unknown).
  double encoder_std = 0.0, gyro_std = 0.0, accel_std = 0.0;
  std::string declared_path;  // the log's declared model
  // The truth's pose of this frame in the base body's (truth.tum) at each encoder row; none
  // when empty. The base body "world" (or empty) is the world.
  std::string truth_frame, base_body;
  // The log's commands: the position targets sent (false), or the torque each motor applied
  // at its joint in each step (true: commands.csv type torque, a row per step).
  bool torque_commands = false;
  // Called after each step's sensors are polled (the state of their readings): a camera of a
  // higher layer renders and detects here.
  std::function<void(const Simulation&)> after_poll;
};

// Settles `truth` at the motion's start, then steps it for the duration, sending the motion's
// command at the command rate (in force from its time on) and polling `sensors` after each
// command: encoders become joint rows, IMUs their readings, the truth frame's pose truth rows.
RecordedLog SimulateMotionLog(Simulation& truth, SensorSuite& sensors, const MultiSine& motion,
                              const MotionLogOptions& options);

}  // namespace flexbench::sim
