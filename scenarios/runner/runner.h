// The `flexbench` runner: scenario file -> kind -> results -> gates -> output folder.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "scenarios/runner/gates.h"
#include "scenarios/runner/output.h"
#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"

namespace flexbench::scenarios {

// Exit codes of the runner contract (docs/design.md).
inline constexpr int kExitOk = 0;
inline constexpr int kExitInternal = 1;
inline constexpr int kExitBadInput = 2;
inline constexpr int kExitGateFailed = 3;

struct RunOptions {
  std::string scenario_path;
  std::string out_dir;                // default: out/<scenario name>
  std::optional<std::uint64_t> seed;  // overrides the file's seed
  bool check_gates = false;
  bool force = false;            // --out may replace a folder that is not a previous result
  std::vector<std::string> set;  // --set KEY=VALUE overrides, in order
  bool quiet = false;  // no progress, no informational lines (errors and failed gates remain)
  // --export-log DIR: the run's sensor readings and truth written as a recorded-log folder
  // (sim/recorded_log.h), for `flexbench replay`; empty: none.
  std::string export_log;
  // --frames: which images the run writes (default: the key frames and every figure).
  FrameOutput frames = FrameOutput::kKey;
  // false: the run keeps only its summary.json and report.html (a sweep's --run-files summary).
  bool data_files = true;
  // The command line as typed (shell-quoted), recorded in summary.json and the report; empty
  // (a sweep's run): the equivalent `flexbench run` line is recorded.
  std::string command;
};

// The --set KEY=VALUE arguments as overrides (InputError naming a malformed one).
std::vector<ConfigOverride> ParseOverrides(const std::vector<std::string>& args);

// Runs one scenario; prints one line on stderr for bad input. Returns an exit code.
int RunScenario(const RunOptions& options);

// Runs a scenario loaded or built in memory (a command's own, as replay's):
// `shown_path` is what messages call it, `inputs` the files it reads (never replaced by --out).
// Returns an exit code; bad input is thrown (InputError).
int RunLoaded(const ConfigNode& root, const RunOptions& options, const std::string& shown_path,
              const std::vector<std::filesystem::path>& inputs);

// A scenario ready to run: its kind configured, every input checked.
struct PreparedRun {
  std::string name;
  std::string description;
  std::string kind_name;
  std::uint64_t seed = 0;
  std::unique_ptr<ScenarioKind> kind;
  std::vector<GateSpec> gates;
};
// A run's `scenario` (its name, checked to be a plain name), `description` and `seed` (>= 0;
// options.seed replaces it) from root; with a default name, root may hold neither name nor
// seed (a command's own run: `default_name`, seed 0).
void ReadRunHeader(const ConfigNode& root, const RunOptions& options,
                   const std::string& default_name, PreparedRun* p);

// Runs one prepared in memory (a command's own kind, configured without a scenario file).
int RunPrepared(PreparedRun prepared, const RunOptions& options, const std::string& shown_path,
                const std::vector<std::filesystem::path>& inputs);

struct IdentifyCliOptions {
  std::string model;  // optional: must be the model the declared file names
  std::string declared;
  std::string calibration_csv;
  std::string validation_csv;
  std::vector<std::string> candidates;
  // Measurement frames (a tracker) of unknown pose the CSVs' `frame` column may name.
  std::vector<std::string> frames;
  // Observed frames of the declared model the CSVs' `marker` column may name.
  std::vector<std::string> markers;
  std::vector<std::string> unknown_marker_offsets;
  double point_std_m = 1e-4;
  std::optional<double> reading_std_deg;  // the joint readings' noise, when stated
  // Selection options (closed_loop keys of the same names); unset: the kind's defaults.
  std::optional<int> max_effects;
  std::optional<double> time_budget_s;
  std::optional<double> bic_threshold;
  std::optional<std::string> folds_by;
  std::optional<double> outlier_iqr;
  bool no_cross_validation = false;
  std::string out_dir = "out/identify";
  bool force = false;
  std::vector<std::string> set;  // --set KEY=VALUE on the closed_loop keys it configures
  bool quiet = false;
  std::string command;  // the command line as typed, recorded in summary.json
};

// `flexbench identify`: a closed_loop run on a user's files (paths as given on the command
// line), configured in memory (no scenario file is written); errors name the option.
// Returns an exit code.
int IdentifyCommand(const IdentifyCliOptions& options);

// What a sweep needs to know of a scenario before it runs it.
struct ScenarioCheck {
  std::string name;
  std::vector<std::string> gate_names;
};
// Loads `path` with the `set` overrides (KEY=VALUE) and configures its kind without running it:
// every input error a run would report before working is thrown here (InputError).
ScenarioCheck CheckScenario(const std::string& path, const std::vector<std::string>& set);

// Prints the scenario kinds and the scenario files found under `scenarios_dir`.
int ListScenarios(const std::string& scenarios_dir);

// Prints `e` as one line on stderr ("flexbench: error: ..." for bad input, "flexbench:
// internal error: ..." otherwise; newlines folded, capped) and returns its exit code: 2 for
// InputError, SimulationError and filesystem errors (a path the system refused), 1 otherwise.
int ReportError(const std::exception& e);

}  // namespace flexbench::scenarios
