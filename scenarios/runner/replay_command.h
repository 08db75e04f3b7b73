// `flexbench replay`: a recorded log folder (sim/recorded_log.h) through the estimators, as the
// replay scenario kind runs it, configured from the command line in memory.
#pragma once

#include <string>
#include <vector>

namespace flexbench::scenarios {

struct ReplayCliOptions {
  std::string log;       // the log folder
  std::string declared;  // optional: a declared model instead of log.yaml's
  std::vector<std::string> estimators = {"fk", "ppoe_ekf"};
  double step_hz = 0.0;  // 0: a step per joint row
  bool estimate_imu_clock_offset = false;
  std::string out_dir;  // default: out/replay/<log folder's name>
  bool check_gates = false;
  bool force = false;
  bool quiet = false;
  std::vector<std::string> set;  // --set KEY=VALUE on the replay keys
  std::string command;           // the command line as typed, recorded in summary.json
};

// Returns an exit code (2: bad input, one line naming the file or the option).
int ReplayCommand(const ReplayCliOptions& options);

}  // namespace flexbench::scenarios
