// A recorded log (sim/recorded_log.h) through one estimator in time order: the steps the replay
// kind and the closed loop's held-out replay share. A step: the IMU readings up to its time (in
// time order), Predict, the joint reading of its row, the tag detections and then the contact
// readings up to its time (after the joint reading, which sets the kinematic prior they
// correct), the estimate.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "estimators/estimator.h"
#include "scenarios/runner/common/truth_rig.h"
#include "sim/declared_chain.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {

// What the estimators know of the log on `chain`: its model and identified effects, the end
// effector, the log's IMUs and cameras at their declared frames (InputError naming log.yaml's
// key when a frame is not an observed frame of the chain, or when the truth is of another frame
// than the end effector).
estimators::EstimatorSetup LogEstimatorSetup(const sim::RecordedLog& log,
                                             const sim::DeclaredChain& chain,
                                             const std::string& end_effector);

// The log's streams bound to a chain.
struct LogIndex {
  std::vector<int> column;                         // sim::JointColumns of the chain's joints
  std::vector<kinematics::FrameId> tag_frame;      // per log tag, its frame on the chain
  std::vector<size_t> tag_order;                   // tags.csv's rows in time order
  std::vector<kinematics::FrameId> contact_frame;  // per log contact point, its frame
  std::vector<size_t> contact_order;               // contacts.csv's rows in time order
  std::vector<kinematics::FrameId> sensed_frame;   // per RecordedLog::sensed_frames entry
  std::vector<size_t> orientation_order;           // orientations.csv's rows in time order
  std::vector<size_t> position_order;              // positions.csv's rows in time order
};

// InputError naming joints.csv's header or log.yaml's key (`declared_file` for messages).
LogIndex IndexLog(const sim::RecordedLog& log, const sim::DeclaredChain& chain,
                  const std::string& declared_file);

// The declared rig of `declared` on `nominal` (BuildDeclaredRig) with the log's sensors in its
// set-up (LogEstimatorSetup), and the log's streams bound to its chain (IndexLog, checked
// first): what replaying the log under that model needs.
DeclaredRig BuildLogRig(const sim::RecordedLog& log, const mjModel* nominal,
                        sim::DeclaredModel declared, LogIndex* index);

struct LogStep {
  double t;
  size_t row;  // the joints.csv row it reads
};

// step_hz 0: a step at each joint row; else a step at the latest row at or before each tick of
// that rate (from the first row), at its row's time. Only rows with t_from <= t <= t_to.
std::vector<LogStep> LogSteps(const sim::RecordedLog& log, double step_hz,
                              double t_from = -std::numeric_limits<double>::infinity(),
                              double t_to = std::numeric_limits<double>::infinity());

// The log's IMU readings in time order (a sensor's own order where times are equal).
std::vector<size_t> ImuTimeOrder(const sim::RecordedLog& log);

// Runs `est` over `steps` (the IMU readings through `imu_order`, the tag detections through
// `index`): at each step the IMU readings up to its time, the joint row, then the
// orientations, positions, tag detections and contacts up to its time; calling
// on_step(step index, belief) after each step; a step that begins a posture (every step of a log
// of static postures; the first at or after each of postures.csv's times) starts from Reset.
// Returns the readings the estimator did not accept (rejected now or deferred).
int ReplayLog(const sim::RecordedLog& log, const LogIndex& index, const std::vector<LogStep>& steps,
              const std::vector<size_t>& imu_order, estimators::Estimator& est,
              const std::function<void(size_t, const estimators::Belief&)>& on_step);

}  // namespace flexbench::scenarios
