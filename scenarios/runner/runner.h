// The `flexbench` runner: scenario file -> kind -> results -> gates -> output folder.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace flexbench::scenarios {

// Exit codes of the runner contract (DESIGN.md).
inline constexpr int kExitOk = 0;
inline constexpr int kExitInternal = 1;
inline constexpr int kExitBadInput = 2;
inline constexpr int kExitGateFailed = 3;

struct RunOptions {
  std::string scenario_path;
  std::string out_dir;                 // default: out/<scenario name>
  std::optional<std::uint64_t> seed;   // overrides the file's seed
  bool check_gates = false;
};

// Runs one scenario; prints one line on stderr for bad input. Returns an exit code.
int RunScenario(const RunOptions& options);

// `flexbench identify`: a closed_loop run on a user's files (paths as given on the command
// line). Returns an exit code.
int IdentifyCommand(const std::string& model, const std::string& declared,
                    const std::string& calibration_csv, const std::string& validation_csv,
                    const std::vector<std::string>& candidates, double point_std_m,
                    const std::string& out_dir);

// Prints the scenario kinds and the scenario files found under `scenarios_dir`.
int ListScenarios(const std::string& scenarios_dir);

}  // namespace flexbench::scenarios
