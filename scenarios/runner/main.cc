// flexbench: run scenarios that score pose estimators of flexible arms against MuJoCo's truth.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "estimators/error.h"
#include "scenarios/runner/export_command.h"
#include "scenarios/runner/inspect.h"
#include "scenarios/runner/replay_command.h"
#include "scenarios/runner/report.h"
#include "scenarios/runner/runner.h"
#include "scenarios/runner/summary_command.h"
#include "scenarios/sweep/sweep_command.h"
#include "sim/config.h"
#include "sim/export_model.h"
#include "sim/mujoco_model.h"

namespace {

// The options of each subcommand, filled by CLI11.
struct Options {
  flexbench::scenarios::RunOptions run;
  std::string seed;
  CLI::Option* seed_opt = nullptr;
  std::string frames = "key";
  std::string list_dir;
  std::string inspect_path;
  flexbench::scenarios::IdentifyCliOptions id;
  flexbench::scenarios::sweep::SweepCliOptions sw;
  flexbench::scenarios::ExportCliOptions ex;
  flexbench::scenarios::ConvertCliOptions cv;
  flexbench::scenarios::ReplayCliOptions rp;
  bool no_wait = false;
  // The --out options, to tell `--out ''` from no --out (both leave the string empty).
  std::vector<std::pair<CLI::Option*, const std::string*>> outs;
  std::string report_dir;
  std::vector<std::string> summary_dirs;
  bool summary_tsv = false;
};

CLI::App* AddRun(CLI::App& app, Options& o) {
  CLI::App* run_cmd = app.add_subcommand("run", "run a scenario file");
  run_cmd->add_option("scenario", o.run.scenario_path, "scenario YAML file")->required();
  o.outs.emplace_back(
      run_cmd->add_option("--out", o.run.out_dir, "output folder (default: out/<scenario>)"),
      &o.run.out_dir);
  o.seed_opt = run_cmd->add_option("--seed", o.seed,
                                   "override the scenario's seed (0 to 2147483647, as in the "
                                   "file)");
  run_cmd->add_flag("--check-gates", o.run.check_gates, "exit 3 when a gate fails");
  run_cmd->add_flag("--quiet", o.run.quiet,
                    "no progress and no informational lines (errors and failed gates remain)");
  run_cmd
      ->add_option("--set", o.run.set,
                   "override a scenario key: KEY=VALUE, KEY a dotted path, VALUE YAML "
                   "(repeatable; recorded in summary.json)")
      ->allow_extra_args(false);  // one KEY=VALUE per --set: never the scenario path after it
  run_cmd->add_option("--frames", o.frames,
                      "images written: all (every rendered camera frame), key (default: a few "
                      "frames and every figure) or none");
  run_cmd->add_flag("--force", o.run.force,
                    "let --out replace an existing folder that is not a flexbench result");
  run_cmd->add_option("--export-log", o.run.export_log,
                      "also write the run's readings and truth as a recorded-log folder (a new "
                      "folder) that `flexbench replay` reads");
  return run_cmd;
}

// identify: the closed_loop kind on a user's own model, declared model and CSV files.
CLI::App* AddIdentify(CLI::App& app, Options& o) {
  flexbench::scenarios::IdentifyCliOptions& id = o.id;
  CLI::App* identify_cmd = app.add_subcommand(
      "identify", "find the effects a declared model lacks from measured data (closed_loop)");
  identify_cmd->add_option("--model", id.model,
                           "MJCF or URDF of the robot (optional; must be the model the "
                           "declared file names)");
  identify_cmd->add_option("--declared", id.declared, "declared-model YAML")->required();
  identify_cmd->add_option("--calibration", id.calibration_csv, "calibration CSV (README format)")
      ->required();
  identify_cmd->add_option("--validation", id.validation_csv, "validation CSV (README format)")
      ->required();
  identify_cmd->add_option("--candidates", id.candidates,
                           "effect types or type@location to test (default: all)");
  identify_cmd->add_option("--frame", id.frames,
                           "a measurement frame of unknown pose (a tracker) the CSVs' 'frame' "
                           "column names (repeatable; priors: --set frames.NAME.prior_std_m=...)");
  identify_cmd->add_option("--marker", id.markers,
                           "an observed frame of the declared model the CSVs' 'marker' column "
                           "names beside the end effector (repeatable)");
  identify_cmd->add_option("--unknown-marker-offset", id.unknown_marker_offsets,
                           "a marker (or the end effector) whose offset on its link is unknown: "
                           "3 parameters fitted with the effects (repeatable)");
  identify_cmd->add_option("--point-std", id.point_std_m, "point noise [m] (default 1e-4)");
  identify_cmd->add_option("--reading-std-deg", id.reading_std_deg,
                           "the joint readings' noise [deg]: sizes the augmented model's sources "
                           "on the validation rows with it");
  identify_cmd->add_option("--max-effects", id.max_effects,
                           "most effects to choose (default: no cap; selection stops "
                           "where the held-out error stops falling)");
  identify_cmd->add_option("--time-budget", id.time_budget_s,
                           "seconds the selection may take (default: none); a budget that ends "
                           "it is reported and the verdict is at most partly_explained");
  identify_cmd->add_option("--bic-threshold", id.bic_threshold,
                           "BIC drop a candidate must bring to be tried (default 10)");
  identify_cmd->add_option("--folds-by", id.folds_by,
                           "cross-validation folds: auto, set, group or row (default auto)");
  identify_cmd->add_option("--outlier-iqr", id.outlier_iqr,
                           "reject rows beyond Q3 + k IQR (default 3; 0: off)");
  identify_cmd->add_flag("--no-cross-validation", id.no_cross_validation,
                         "select by BIC alone (no held-out folds)");
  identify_cmd
      ->add_option("--set", id.set,
                   "override a closed_loop key: KEY=VALUE (repeatable; e.g. "
                   "--set cv_min_gain=0.05)")
      ->allow_extra_args(false);
  o.outs.emplace_back(
      identify_cmd->add_option("--out", id.out_dir, "output folder (default: out/identify)"),
      &id.out_dir);
  identify_cmd->add_flag("--quiet", id.quiet, "no progress and no informational lines");
  identify_cmd->add_flag("--force", id.force,
                         "let --out replace an existing folder that is not a flexbench result");
  return identify_cmd;
}

// export: the calibrated model (a declared file with identified effects) as MJCF and URDF.
CLI::App* AddExport(CLI::App& app, Options& o) {
  CLI::App* cmd = app.add_subcommand(
      "export",
      "write a declared model with its identified effects as MJCF / URDF (geometry folded in)");
  cmd->add_option("declared", o.ex.declared, "declared-model YAML (e.g. declared_augmented.yaml)")
      ->required();
  // Checked by ExportCommand: one line naming the option (CLI11 adds a second).
  cmd->add_option("--mjcf", o.ex.mjcf, "output MJCF file");
  cmd->add_option("--urdf", o.ex.urdf, "output URDF file");
  cmd->add_flag("--force", o.ex.force, "replace an existing output file");
  return cmd;
}

// convert: a URDF as the MJCF with position servos the truth loads it as.
CLI::App* AddConvert(CLI::App& app, Options& o) {
  CLI::App* cmd = app.add_subcommand(
      "convert", "write a URDF as MJCF with a position servo per joint (how the truth loads it)");
  cmd->add_option("urdf", o.cv.urdf, "URDF file")->required();
  // Checked by ConvertCommand: one line naming the option (CLI11 adds a second).
  cmd->add_option("--actuators", o.cv.actuators, "the actuators to add: position (required)");
  char kp[32];
  std::snprintf(kp, sizeof(kp), "%g", flexbench::sim::kDefaultServoKp);
  cmd->add_option(
      "--kp", o.cv.kp,
      std::string("servo stiffness, N m/rad (N/m on a prismatic joint; default ") + kp + ")");
  cmd->add_option("-o,--out", o.cv.out, "output MJCF (default: the URDF's name with .xml)");
  cmd->add_flag("--force", o.cv.force, "replace an existing output file");
  return cmd;
}

// replay: a recorded log folder through the estimators.
CLI::App* AddReplay(CLI::App& app, Options& o) {
  flexbench::scenarios::ReplayCliOptions& rp = o.rp;
  CLI::App* cmd = app.add_subcommand(
      "replay", "run estimators over a recorded log folder (joints, IMUs, truth)");
  cmd->add_option("log", rp.log, "log folder (holds log.yaml)")->required();
  cmd->add_option("--declared", rp.declared,
                  "declared model instead of log.yaml's (e.g. a declared_augmented.yaml)");
  cmd->add_option("--estimators", rp.estimators,
                  "estimators by registry name (default: fk ppoe_ekf)")
      ->delimiter(',');
  cmd->add_option(
      "--step-hz", rp.step_hz,
      "estimator steps per second, each at the latest joint row (default 0: every row)");
  cmd->add_flag("--estimate-imu-clock-offset", rp.estimate_imu_clock_offset,
                "estimate the IMU stream's clock offset against the joints from the data");
  o.outs.emplace_back(
      cmd->add_option("--out", rp.out_dir, "output folder (default: out/replay/<log folder>)"),
      &rp.out_dir);
  cmd->add_flag("--check-gates", rp.check_gates, "exit 3 when a gate fails (with --set gates)");
  cmd->add_flag("--quiet", rp.quiet, "no progress and no informational lines");
  cmd->add_option("--set", rp.set, "override a replay key: KEY=VALUE (repeatable)")
      ->allow_extra_args(false);
  cmd->add_flag("--force", rp.force,
                "let --out replace an existing folder that is not a flexbench result");
  return cmd;
}

CLI::App* AddSweep(CLI::App& app, Options& o) {
  flexbench::scenarios::sweep::SweepCliOptions& sw = o.sw;
  CLI::App* sweep_cmd = app.add_subcommand(
      "sweep", "run a scenario over seeds and a grid of overrides; statistics and gates");
  sweep_cmd->add_option("sweep", sw.sweep_path, "sweep YAML file")->required();
  o.outs.emplace_back(
      sweep_cmd->add_option("--out", sw.out_dir, "output folder (default: out/sweeps/<sweep>)"),
      &sw.out_dir);
  sweep_cmd->add_option("-j,--jobs", sw.jobs, "local worker processes (default: cores)");
  sweep_cmd->add_option("--executor", sw.executor, "local (default) or slurm");
  sweep_cmd->add_option("--shard", sw.shard, "run only shard i/n of the runs, no collect");
  sweep_cmd->add_option("--run-files", sw.run_files,
                        "all (default: each run keeps its CSVs and trajectories) or summary "
                        "(summary.json and report.html only; the aggregate is the same)");
  sweep_cmd->add_flag("--collect", sw.collect,
                      "merge the runs in --out into sweep.csv and aggregate.json, gate");
  sweep_cmd->add_option("--tasks", sw.slurm.tasks,
                        "slurm: array tasks (shards; default one per run, at most 64)");
  sweep_cmd->add_option("--partition", sw.slurm.partition, "slurm: sbatch --partition");
  sweep_cmd->add_option("--time", sw.slurm.time, "slurm: sbatch --time");
  sweep_cmd->add_option("--mem", sw.slurm.mem, "slurm: sbatch --mem");
  sweep_cmd->add_option("--array", sw.slurm.array,
                        "slurm: submit only these task indices (resubmit failed ones: 3,5)");
  sweep_cmd->add_flag("--no-wait", o.no_wait, "slurm: submit and return; --collect later");
  return sweep_cmd;
}

// The seed as the scenario file allows it: a whole number from 0 to INT_MAX. CLI11 would wrap
// "-1" or 2^64 into a uint64.
std::uint64_t ParseSeed(const std::string& text) {
  const auto fail = [&]() -> std::uint64_t {
    throw flexbench::InputError("--seed '" + flexbench::CapForMessage(text) +
                                "': expected a whole number from 0 to 2147483647");
  };
  if (text.empty() || text.size() > 10 ||
      text.find_first_not_of("0123456789") != std::string::npos) {
    return fail();
  }
  const std::uint64_t v = std::stoull(text);
  return v > 2147483647u ? fail() : v;
}

// CLI11 answers an unknown first word with "A subcommand is required"; name the word instead.
void CheckSubcommand(int argc, char** argv, const CLI::App& app) {
  if (argc < 2 || argv[1][0] == '-') return;
  const std::string word = argv[1];
  std::string known;
  for (const CLI::App* sub : app.get_subcommands({})) {
    if (sub->get_name() == word) return;
    known += (known.empty() ? "" : ", ") + sub->get_name();
  }
  throw flexbench::InputError("unknown command '" + flexbench::CapForMessage(word) +
                              "' (expected one of: " + known + "; see flexbench --help)");
}

// `list` without --dir: ./scenarios, else the source tree's.
std::string DefaultListDir() {
  std::error_code ec;
  std::string dir = "scenarios";
  if (!std::filesystem::is_directory(dir, ec) &&
      std::filesystem::is_directory(std::string(FLEXBENCH_SOURCE_DIR) + "/scenarios", ec)) {
    dir = std::string(FLEXBENCH_SOURCE_DIR) + "/scenarios";
  }
  return dir;
}

int Main(int argc, char** argv) {
  // MuJoCo's fatal errors and warnings: one line on stderr, never a prompt on stdin or a log
  // file in the working folder.
  flexbench::sim::InstallMujocoHandlers();
  CLI::App app{"flexbench: pose estimation of flexible robot arms, scored against MuJoCo"};
  app.set_version_flag("--version", std::string("flexbench ") + FLEXBENCH_VERSION);
  app.require_subcommand(1);
  Options o;
  CLI::App* run_cmd = AddRun(app, o);
  CLI::App* list_cmd = app.add_subcommand("list", "list scenario kinds and scenario files");
  list_cmd->add_option("--dir", o.list_dir, "folder with scenario files (default: scenarios)");
  CLI::App* inspect_cmd = app.add_subcommand(
      "inspect", "print a model's joints, sensors, cameras, tags and effects as JSON");
  inspect_cmd->add_option("model", o.inspect_path, "MJCF or URDF model, or declared-model YAML")
      ->required();
  CLI::App* identify_cmd = AddIdentify(app, o);
  CLI::App* sweep_cmd = AddSweep(app, o);
  CLI::App* export_cmd = AddExport(app, o);
  CLI::App* convert_cmd = AddConvert(app, o);
  CLI::App* replay_cmd = AddReplay(app, o);
  CLI::App* report_cmd = app.add_subcommand(
      "report", "write report.html in a run's or a sweep's result folder (again)");
  report_cmd
      ->add_option("dir", o.report_dir, "result folder (holds summary.json or aggregate.json)")
      ->required();
  CLI::App* summary_cmd = app.add_subcommand(
      "summary", "one table row per result folder: gates passed, headline metric, time, size");
  summary_cmd->add_option("dirs", o.summary_dirs, "result folders (runs or sweeps)")->required();
  summary_cmd->add_flag("--tsv", o.summary_tsv,
                        "tab-separated: scenario, gates passed, gates, headline");
  CheckSubcommand(argc, argv, app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : flexbench::scenarios::kExitBadInput;
  }
  if (*o.seed_opt) o.run.seed = ParseSeed(o.seed);
  try {
    o.run.frames = flexbench::scenarios::ParseFrameOutput(o.frames, "--frames");
  } catch (const std::exception& e) {
    return flexbench::scenarios::ReportError(e);
  }
  // An empty --out (an unset shell variable) would silently write the default folder.
  for (const auto& [option, value] : o.outs) {
    if (option->count() > 0 && value->empty()) {
      return flexbench::scenarios::ReportError(flexbench::InputError(
          "--out '': an empty folder name; name a folder, or omit --out for the default"));
    }
  }
  // The command line as typed, recorded with the results.
  const std::string command =
      flexbench::scenarios::CommandLine(std::vector<std::string>(argv, argv + argc));
  o.run.command = command;
  o.id.command = command;
  o.sw.command = command;
  o.rp.command = command;
  if (*summary_cmd) return flexbench::scenarios::SummaryCommand(o.summary_dirs, o.summary_tsv);
  if (*report_cmd) return flexbench::scenarios::ReportCommand(o.report_dir);
  if (*run_cmd) return flexbench::scenarios::RunScenario(o.run);
  if (*sweep_cmd) {
    o.sw.slurm.wait = !o.no_wait;
    o.sw.slurm.tasks_given = sweep_cmd->get_option("--tasks")->count() > 0;
    return flexbench::scenarios::sweep::SweepCommand(o.sw);
  }
  if (*inspect_cmd) return flexbench::scenarios::InspectCommand(o.inspect_path);
  if (*export_cmd) return flexbench::scenarios::ExportCommand(o.ex);
  if (*convert_cmd) return flexbench::scenarios::ConvertCommand(o.cv);
  if (*replay_cmd) return flexbench::scenarios::ReplayCommand(o.rp);
  if (*identify_cmd) {
    if (o.id.out_dir.empty()) o.id.out_dir = "out/identify";
    return flexbench::scenarios::IdentifyCommand(o.id);
  }
  if (*list_cmd) {
    return flexbench::scenarios::ListScenarios(o.list_dir.empty() ? DefaultListDir() : o.list_dir);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // Nothing escapes as an abort: every error is one line and an exit code of the contract.
  try {
    return Main(argc, argv);
  } catch (const std::exception& e) {
    return flexbench::scenarios::ReportError(e);
  } catch (...) {
    std::cerr << "flexbench: internal error: unknown exception\n";
    return flexbench::scenarios::kExitInternal;
  }
}
