// A recorded log (sim/recorded_log.h) through one estimator in time order: the steps the replay
// kind and the closed loop's held-out replay share. A step: the IMU readings up to its time (in
// time order), Predict, the joint reading of its row, the estimate.
#pragma once

#include <functional>
#include <limits>
#include <vector>

#include "estimators/estimator.h"
#include "sim/declared_chain.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {

// What the estimators know of the log on `chain`: its model and identified effects, the end
// effector, and the log's IMUs at their declared frames (InputError naming log.yaml's key when a
// frame is not an observed frame of the chain, or when the truth is of another frame than the
// end effector).
estimators::EstimatorSetup LogEstimatorSetup(const sim::RecordedLog& log,
                                             const sim::DeclaredChain& chain,
                                             const std::string& end_effector);

// sim::JointColumns of the chain's joint variables (`declared_file` for messages).
std::vector<int> LogJointColumns(const sim::RecordedLog& log, const sim::DeclaredChain& chain,
                                 const std::string& declared_file);

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

// Runs `est` over `steps` (joint values through `column`: sim::JointColumns; the IMU readings
// at imu_from and later, through `imu_order`), calling on_step(step index, belief) after each
// step. Returns the readings the estimator did not accept (rejected now or deferred).
int ReplayLog(const sim::RecordedLog& log, const std::vector<int>& column,
              const std::vector<LogStep>& steps, const std::vector<size_t>& imu_order,
              estimators::Estimator& est,
              const std::function<void(size_t, const estimators::Belief&)>& on_step,
              double imu_from = -std::numeric_limits<double>::infinity());

}  // namespace flexbench::scenarios
