// flexbench: run scenarios that score pose estimators of flexible arms against MuJoCo's truth.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <iostream>

#include "scenarios/runner/inspect.h"
#include "scenarios/runner/runner.h"

int main(int argc, char** argv) {
  using flexbench::scenarios::RunOptions;
  CLI::App app{"flexbench: pose estimation of flexible robot arms, scored against MuJoCo"};
  app.set_version_flag("--version", std::string("flexbench ") + FLEXBENCH_VERSION);
  app.require_subcommand(1);

  RunOptions run;
  std::uint64_t seed = 0;
  CLI::App* run_cmd = app.add_subcommand("run", "run a scenario file");
  run_cmd->add_option("scenario", run.scenario_path, "scenario YAML file")->required();
  run_cmd->add_option("--out", run.out_dir, "output folder (default: out/<scenario>)");
  CLI::Option* seed_opt = run_cmd->add_option("--seed", seed, "override the scenario's seed");
  run_cmd->add_flag("--check-gates", run.check_gates, "exit 3 when a gate fails");

  std::string list_dir = "scenarios";
  CLI::App* list_cmd = app.add_subcommand("list", "list scenario kinds and scenario files");
  list_cmd->add_option("--dir", list_dir, "folder with scenario files");

  std::string inspect_path;
  CLI::App* inspect_cmd = app.add_subcommand(
      "inspect", "print a model's joints, sensors, cameras, tags and effects as JSON");
  inspect_cmd->add_option("model", inspect_path, "MJCF model or declared-model YAML")->required();

  // identify: the closed_loop kind on a user's own model, declared model and CSV files.
  std::string id_model, id_declared, id_cal, id_val, id_out;
  std::vector<std::string> id_candidates;
  double id_point_std = 1e-4;
  CLI::App* identify_cmd = app.add_subcommand(
      "identify", "find the effects a declared model lacks from measured data (closed_loop)");
  identify_cmd->add_option("--model", id_model, "MJCF or URDF of the robot")->required();
  identify_cmd->add_option("--declared", id_declared, "declared-model YAML")->required();
  identify_cmd->add_option("--calibration", id_cal, "calibration CSV (README format)")->required();
  identify_cmd->add_option("--validation", id_val, "validation CSV (README format)")->required();
  identify_cmd->add_option("--candidates", id_candidates,
                           "effect types or type@location to test (default: all)");
  identify_cmd->add_option("--point-std", id_point_std, "point noise [m] (default 1e-4)");
  identify_cmd->add_option("--out", id_out, "output folder (default: out/identify)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : flexbench::scenarios::kExitBadInput;
  }
  if (*seed_opt) run.seed = seed;
  if (*run_cmd) return flexbench::scenarios::RunScenario(run);
  if (*inspect_cmd) return flexbench::scenarios::InspectCommand(inspect_path);
  if (*identify_cmd) {
    return flexbench::scenarios::IdentifyCommand(id_model, id_declared, id_cal, id_val,
                                                 id_candidates, id_point_std,
                                                 id_out.empty() ? "out/identify" : id_out);
  }
  if (*list_cmd) {
    if (!std::filesystem::is_directory(list_dir) &&
        std::filesystem::is_directory(std::string(FLEXBENCH_SOURCE_DIR) + "/scenarios")) {
      list_dir = std::string(FLEXBENCH_SOURCE_DIR) + "/scenarios";
    }
    return flexbench::scenarios::ListScenarios(list_dir);
  }
  return 0;
}
