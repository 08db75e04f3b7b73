#include "scenarios/runner/runner.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

#include "estimators/error.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/runner/gates.h"
#include "scenarios/runner/output.h"
#include "scenarios/runner/progress.h"
#include "scenarios/runner/report.h"
#include "scenarios/runner/scenario_kind.h"
#include "sim/config.h"
#include "sim/declared_model.h"

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

// A scenario name becomes the default output folder out/<name>: one plain path element.
void CheckScenarioName(const ConfigNode& node, const std::string& name) {
  if (name.empty() || name == "." || name == ".." || name.size() > 200 ||
      name.find_first_of("/\\") != std::string::npos ||
      std::any_of(name.begin(), name.end(),
                  [](char c) { return static_cast<unsigned char>(c) < 0x20; })) {
    node.Fail("must be a plain name (no '/', not '.' or '..', at most 200 characters)");
  }
}

PreparedRun Prepare(const ConfigNode& root, const RunOptions& options) {
  PreparedRun p;
  ReadRunHeader(root, options, "", &p);
  p.kind = MakeKind(root.Child("kind"));
  p.kind_name = root.GetString("kind");
  p.gates = ParseGates(root);
  if (options.check_gates && p.gates.empty()) {
    throw InputError(root.file() + ": --check-gates, but the scenario has no gates");
  }
  p.kind->Configure(root);
  root.CheckNoUnknownKeys();
  return p;
}

// The `flexbench run` line that repeats a run given without its command line (a sweep's).
std::string EquivalentCommand(const RunOptions& options, const fs::path& out_dir) {
  std::vector<std::string> args = {"flexbench", "run", options.scenario_path, "--out",
                                   out_dir.string()};
  if (options.seed) {
    args.push_back("--seed");
    args.push_back(std::to_string(*options.seed));
  }
  for (const std::string& s : options.set) {
    args.push_back("--set");
    args.push_back(s);
  }
  if (options.check_gates) args.push_back("--check-gates");
  if (options.frames != FrameOutput::kKey) {
    args.push_back("--frames");
    args.push_back(FrameOutputName(options.frames));
  }
  return CommandLine(args);
}

// A metric that is NaN or infinite would be written as null, like a metric the kind had no
// value for: inputs that pass their checks yet overflow a computation (an absurd value in the
// scenario, a --set or the model) must not end as a quiet success. Explicit nulls pass.
void CheckMetricsFinite(const Json& j, const std::string& path) {
  if (j.is_number_float() && !std::isfinite(j.get<double>())) {
    throw InputError("metric '" + CapForMessage(path) + "' is " +
                     (std::isnan(j.get<double>()) ? "NaN" : "infinite") +
                     ": not finite; check the inputs (the scenario's values, --set, the model)");
  }
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) {
      CheckMetricsFinite(it.value(), path.empty() ? it.key() : path + "." + it.key());
    }
  } else if (j.is_array()) {
    for (size_t i = 0; i < j.size(); ++i) {
      CheckMetricsFinite(j[i], path + "[" + std::to_string(i) + "]");
    }
  }
}

std::string OneLine(std::string m) {
  while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
  for (char& c : m) {
    if (c == '\n' || c == '\r') c = ' ';
  }
  return CapForMessage(m, 1000);
}

}  // namespace

std::vector<ConfigOverride> ParseOverrides(const std::vector<std::string>& args) {
  std::vector<ConfigOverride> out;
  for (const std::string& a : args) out.push_back(ParseOverride(a));
  return out;
}

void ReadRunHeader(const ConfigNode& root, const RunOptions& options,
                   const std::string& default_name, PreparedRun* p) {
  if (default_name.empty() || root.Has("scenario")) {
    const ConfigNode name_node = root.Child("scenario");
    p->name = name_node.AsString();
    CheckScenarioName(name_node, p->name);
  } else {
    p->name = default_name;
  }
  p->description = root.GetString("description", "");
  int seed = 0;
  if (default_name.empty() || root.Has("seed")) {
    const ConfigNode seed_node = root.Child("seed");
    if (seed_node.AsInt() < 0) seed_node.Fail("seed must be >= 0");
    seed = seed_node.AsInt();
  }
  p->seed = options.seed ? *options.seed : static_cast<std::uint64_t>(seed);
}

int RunLoaded(const ConfigNode& root, const RunOptions& options, const std::string& shown_path,
              const std::vector<fs::path>& inputs) {
  return RunPrepared(Prepare(root, options), options, shown_path, inputs);
}

int RunPrepared(PreparedRun prepared, const RunOptions& options, const std::string& shown_path,
                const std::vector<fs::path>& inputs) {
  const auto t_start = std::chrono::steady_clock::now();
  const std::string& name = prepared.name;
  const std::string& description = prepared.description;
  const std::uint64_t seed = prepared.seed;
  std::unique_ptr<ScenarioKind>& kind = prepared.kind;
  const std::vector<GateSpec>& gates = prepared.gates;

  if (!options.export_log.empty()) {
    if (!kind->ExportsLog()) {
      std::string exporting;
      for (const KindEntry& e : ScenarioKinds()) {
        if (e.make()->ExportsLog())
          exporting += (exporting.empty() ? "" : ", ") + std::string(e.name);
      }
      throw InputError("--export-log: scenario kind '" + prepared.kind_name +
                       "' does not export its readings (these do: " + exporting + ")");
    }
    std::error_code ec;
    if (fs::exists(options.export_log, ec)) {
      throw InputError("--export-log " + CapForMessage(options.export_log) +
                       ": exists; a log is written into a new folder");
    }
  }
  const fs::path out_dir =
      options.out_dir.empty() ? fs::path("out") / name : fs::path(options.out_dir);
  if (!options.export_log.empty()) {
    const auto normal = [](const fs::path& p) {  // absolute, no "." or "..", no trailing '/'
      fs::path n = fs::absolute(p).lexically_normal();
      return n.filename().empty() ? n.parent_path() : n;
    };
    const fs::path log = normal(options.export_log), out_abs = normal(out_dir);
    const auto inside = [](const fs::path& a, const fs::path& b) {  // a at or under b
      const auto m = std::mismatch(b.begin(), b.end(), a.begin(), a.end());
      return m.first == b.end();
    };
    if (inside(log, out_abs) || inside(out_abs, log)) {
      throw InputError("--export-log " + CapForMessage(options.export_log) +
                       ": inside the output folder or holding it; name a folder of its own");
    }
  }
  OutputDir out(out_dir, options.force, inputs);

  Json summary;
  summary["scenario"] = name;
  summary["kind"] = prepared.kind_name;
  if (!description.empty()) summary["description"] = description;
  summary["seed"] = seed;
  // How to make this result again (it names --out: the same invocation, the same bytes).
  summary["command"] =
      options.command.empty() ? EquivalentCommand(options, out_dir) : options.command;
  // What the command line changed, so that a result says how it was made.
  if (!options.set.empty()) summary["overrides"] = options.set;
  summary["metrics"] = Json::object();
  summary["estimators"] = Json::object();
  Json timing = Json::object();

  const auto info = [&options](const std::string& line) {
    if (!options.quiet) Log(line);
  };
  RunContext ctx;
  ctx.seed = seed;
  ctx.out = &out;
  ctx.summary = &summary;
  ctx.timing = &timing;
  ctx.log = info;
  ctx.export_log = options.export_log;
  ctx.frames = options.frames;
  ProgressLine::Options progress_options;
  progress_options.terminal = isatty(fileno(stderr));
  progress_options.quiet = options.quiet;
  auto progress = std::make_shared<ProgressLine>(progress_options, [](const std::string& text) {
    std::fputs(text.c_str(), stderr);
    std::fflush(stderr);
  });
  ctx.progress = [progress](const std::string& stage, int done, int total) {
    progress->Update(stage, done, total);
  };
  info("scenario " + name + " (" + shown_path + "), seed " + std::to_string(seed));
  kind->Run(ctx);

  if (options.frames == FrameOutput::kNone) out.RemoveImages();
  if (!options.data_files) out.RemoveDataFiles();
  CheckMetricsFinite(summary["metrics"], "");
  CheckMetricsFinite(summary["estimators"], "estimators");
  CheckGateMetricsExist(gates, summary);
  bool all_passed = true;
  summary["gates"] = EvaluateGates(gates, summary, &all_passed);
  timing["total_s"] =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  summary["timing"] = timing;
  // Strings from data files (labels, paths) that are not UTF-8 are replaced, never fatal.
  WriteFileAtomic(out.File("summary.json"),
                  summary.dump(2, ' ', false, Json::error_handler_t::replace) + "\n");
  // Inside the temporary folder, so the report moves into place with the results. A report
  // that cannot be made costs the page, never the run: `flexbench report` can retry.
  try {
    WriteReport(out.File("summary.json").parent_path());
  } catch (const std::exception& e) {
    Log(std::string("report.html not written: ") + e.what());
  }
  out.Commit();

  for (const Json& g : summary["gates"]) {
    if (options.quiet && g["passed"].get<bool>()) continue;
    Log(std::string(g["passed"].get<bool>() ? "PASS" : "FAIL") + " gate " +
        g["name"].get<std::string>() + ": " + g["metric"].get<std::string>() + " = " +
        g["value"].dump() + " " + g["op"].get<std::string>() + " " + g["threshold"].dump());
  }
  info("results in " + out.final_dir().string());
  if (options.check_gates && !all_passed) return kExitGateFailed;
  return kExitOk;
}

int ReportError(const std::exception& e) {
  if (dynamic_cast<const InputError*>(&e)) {
    std::cerr << "flexbench: error: " << OneLine(e.what()) << "\n";
    return kExitBadInput;
  }
  if (dynamic_cast<const SimulationError*>(&e)) {
    std::cerr << "flexbench: simulation error: " << OneLine(e.what()) << "\n";
    return kExitBadInput;
  }
  if (const auto* f = dynamic_cast<const fs::filesystem_error*>(&e)) {
    std::string paths;
    if (!f->path1().empty()) paths += CapForMessage(f->path1().string()) + ": ";
    std::cerr << "flexbench: error: " << paths << OneLine(f->code().message()) << "\n";
    return kExitBadInput;
  }
  std::cerr << "flexbench: internal error: " << OneLine(e.what()) << "\n";
  return kExitInternal;
}

int RunScenario(const RunOptions& options) {
  try {
    const ConfigNode root =
        ConfigNode::LoadFile(options.scenario_path, ParseOverrides(options.set));
    return RunLoaded(root, options, options.scenario_path, {fs::path(options.scenario_path)});
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

ScenarioCheck CheckScenario(const std::string& path, const std::vector<std::string>& set) {
  const ConfigNode root = ConfigNode::LoadFile(path, ParseOverrides(set));
  const PreparedRun p = Prepare(root, RunOptions{});
  ScenarioCheck check;
  check.name = p.name;
  for (const GateSpec& g : p.gates) check.gate_names.push_back(g.name);
  return check;
}

int ListScenarios(const std::string& scenarios_dir) {
  std::error_code ec;
  if (!fs::is_directory(scenarios_dir, ec)) {
    std::cerr << "flexbench: error: --dir " << CapForMessage(scenarios_dir) << ": not a folder"
              << (ec ? " (" + ec.message() + ")" : std::string()) << "\n";
    return kExitBadInput;
  }
  std::cout << "scenario kinds:\n";
  for (const KindEntry& e : ScenarioKinds()) {
    std::printf("  %-24s %s\n", e.name, e.description);
  }
  std::vector<fs::path> files;
  for (fs::directory_iterator it(scenarios_dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->path().extension() == ".yaml") files.push_back(it->path());
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
