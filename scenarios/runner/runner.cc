#include "scenarios/runner/runner.h"

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "estimators/error.h"
#include "scenarios/runner/gates.h"
#include "scenarios/runner/output.h"
#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios {
namespace {

std::unique_ptr<ScenarioKind> MakeKind(const ConfigNode& kind_node) {
  const std::string name = kind_node.AsString();
  std::string known;
  for (const KindEntry& e : ScenarioKinds()) {
    if (name == e.name) return e.make();
    known += std::string(known.empty() ? "" : ", ") + e.name;
  }
  kind_node.Fail("unknown scenario kind '" + name + "' (known: " + known + ")");
}

void Log(const std::string& line) { std::cerr << "[flexbench] " << line << "\n"; }

}  // namespace

int RunScenario(const RunOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  try {
    // Everything that can be wrong with the input is checked before any work is done.
    const ConfigNode root = ConfigNode::LoadFile(options.scenario_path);
    const std::string name = root.GetString("scenario");
    const std::string description = root.GetString("description", "");
    const ConfigNode seed_node = root.Child("seed");
    if (seed_node.AsInt() < 0) seed_node.Fail("seed must be >= 0");
    const std::uint64_t seed =
        options.seed ? *options.seed : static_cast<std::uint64_t>(seed_node.AsInt());
    std::unique_ptr<ScenarioKind> kind = MakeKind(root.Child("kind"));
    const std::vector<GateSpec> gates = ParseGates(root);
    kind->Configure(root);
    root.CheckNoUnknownKeys();

    const fs::path out_dir =
        options.out_dir.empty() ? fs::path("out") / name : fs::path(options.out_dir);
    OutputDir out(out_dir);

    Json summary;
    summary["scenario"] = name;
    summary["kind"] = root.GetString("kind");
    if (!description.empty()) summary["description"] = description;
    summary["seed"] = seed;
    summary["metrics"] = Json::object();
    summary["estimators"] = Json::object();
    Json timing = Json::object();

    const bool tty = isatty(fileno(stderr));
    RunContext ctx;
    ctx.seed = seed;
    ctx.out = &out;
    ctx.summary = &summary;
    ctx.timing = &timing;
    ctx.log = Log;
    ctx.progress = [tty](const std::string& stage, int done, int total) {
      if (!tty) return;
      std::fprintf(stderr, "\r[flexbench] %s %d/%d%s", stage.c_str(), done, total,
                   done == total ? "\n" : "");
      std::fflush(stderr);
    };
    Log("scenario " + name + " (" + options.scenario_path + "), seed " + std::to_string(seed));
    kind->Run(ctx);

    bool all_passed = true;
    summary["gates"] = EvaluateGates(gates, summary, &all_passed);
    timing["total_s"] =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
    summary["timing"] = timing;
    WriteFileAtomic(out.File("summary.json"), summary.dump(2) + "\n");
    out.Commit();

    for (const Json& g : summary["gates"]) {
      Log(std::string(g["passed"].get<bool>() ? "PASS" : "FAIL") + " gate " +
          g["name"].get<std::string>() + ": " + g["metric"].get<std::string>() + " = " +
          g["value"].dump() + " " + g["op"].get<std::string>() + " " + g["threshold"].dump());
    }
    Log("results in " + out.final_dir().string());
    if (options.check_gates && !all_passed) return kExitGateFailed;
    return kExitOk;
  } catch (const InputError& e) {
    std::cerr << "flexbench: error: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const SimulationError& e) {
    std::cerr << "flexbench: simulation error: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "flexbench: internal error: " << e.what() << "\n";
    return kExitInternal;
  }
}

int ListScenarios(const std::string& scenarios_dir) {
  std::cout << "scenario kinds:\n";
  for (const KindEntry& e : ScenarioKinds()) {
    std::printf("  %-24s %s\n", e.name, e.description);
  }
  std::error_code ec;
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(scenarios_dir, ec)) {
    if (entry.path().extension() == ".yaml") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  std::cout << "scenarios in " << scenarios_dir << ":\n";
  for (const fs::path& f : files) {
    std::string kind = "?";
    std::string description;
    try {
      const ConfigNode root = ConfigNode::LoadFile(f.string());
      kind = root.GetString("kind", "?");
      description = root.GetString("description", "");
    } catch (const std::exception&) {
      kind = "(unreadable)";
    }
    std::printf("  %-32s %-20s %s\n", f.filename().string().c_str(), kind.c_str(),
                description.c_str());
  }
  return kExitOk;
}

}  // namespace flexbench::scenarios

namespace flexbench::scenarios {
namespace {

std::string Quoted(const std::string& s) {
  std::string q = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') q += '\\';
    q += c;
  }
  return q + "\"";
}

}  // namespace

int IdentifyCommand(const std::string& model, const std::string& declared,
                    const std::string& calibration_csv, const std::string& validation_csv,
                    const std::vector<std::string>& candidates, double point_std_m,
                    const std::string& out_dir) {
  namespace fs = std::filesystem;
  for (const auto& [what, path] :
       {std::pair{"--model", model}, std::pair{"--declared", declared},
        std::pair{"--calibration", calibration_csv}, std::pair{"--validation", validation_csv}}) {
    if (!fs::exists(path)) {
      std::cerr << "flexbench: error: " << what << " " << path << ": not found\n";
      return kExitBadInput;
    }
  }
  // The command line becomes a closed_loop scenario file (absolute paths), run as any other.
  std::ostringstream y;
  y << "scenario: identify\nkind: closed_loop\nseed: 0\n"
    << "model: " << Quoted(fs::absolute(model).string()) << "\n"
    << "declared: " << Quoted(fs::absolute(declared).string()) << "\n"
    << "calibration: {csv: " << Quoted(fs::absolute(calibration_csv).string()) << "}\n"
    << "validation: {csv: " << Quoted(fs::absolute(validation_csv).string()) << "}\n"
    << "point_std_m: " << point_std_m << "\n";
  if (!candidates.empty()) {
    y << "candidates: [";
    for (size_t i = 0; i < candidates.size(); ++i) y << (i ? ", " : "") << Quoted(candidates[i]);
    y << "]\n";
  }
  const fs::path file =
      fs::temp_directory_path() / ("flexbench_identify_" + std::to_string(::getpid()) + ".yaml");
  {
    std::ofstream out(file);
    out << y.str();
    if (!out) {
      std::cerr << "flexbench: error: cannot write " << file.string() << "\n";
      return kExitInternal;
    }
  }
  RunOptions o;
  o.scenario_path = file.string();
  o.out_dir = out_dir;
  const int code = RunScenario(o);
  std::error_code ec;
  fs::remove(file, ec);
  return code;
}

}  // namespace flexbench::scenarios
