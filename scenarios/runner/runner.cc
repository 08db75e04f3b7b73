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

std::vector<ConfigOverride> ParseOverrides(const std::vector<std::string>& args) {
  std::vector<ConfigOverride> out;
  for (const std::string& a : args) out.push_back(ParseOverride(a));
  return out;
}

// A loaded scenario with everything checked that can be wrong with the input, before any
// work is done.
struct Prepared {
  std::string name;
  std::string description;
  std::uint64_t seed = 0;
  std::unique_ptr<ScenarioKind> kind;
  std::vector<GateSpec> gates;
};

Prepared Prepare(const ConfigNode& root, const RunOptions& options) {
  Prepared p;
  const ConfigNode name_node = root.Child("scenario");
  p.name = name_node.AsString();
  CheckScenarioName(name_node, p.name);
  p.description = root.GetString("description", "");
  const ConfigNode seed_node = root.Child("seed");
  if (seed_node.AsInt() < 0) seed_node.Fail("seed must be >= 0");
  p.seed = options.seed ? *options.seed : static_cast<std::uint64_t>(seed_node.AsInt());
  p.kind = MakeKind(root.Child("kind"));
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

int RunLoaded(const ConfigNode& root, const RunOptions& options, const std::string& shown_path,
              const std::vector<fs::path>& inputs) {
  const auto t_start = std::chrono::steady_clock::now();
  Prepared prepared = Prepare(root, options);
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
      throw InputError("--export-log: scenario kind '" + root.GetString("kind") +
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
  summary["kind"] = root.GetString("kind");
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
  const Prepared p = Prepare(root, RunOptions{});
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

namespace flexbench::scenarios {
namespace {

// A YAML double-quoted scalar holding `s` exactly (control characters escaped).
std::string Quoted(const std::string& s) {
  std::string q = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') {
      q += '\\';
      q += c;
    } else if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      char b[8];
      std::snprintf(b, sizeof(b), "\\x%02x", static_cast<unsigned char>(c));
      q += b;
    } else {
      q += c;
    }
  }
  return q + "\"";
}

// Bad input about a command-line option: "--<option> <value>: <what>".
[[noreturn]] void OptionError(const std::string& option, const std::string& value,
                              const std::string& what) {
  throw InputError(option + " " + CapForMessage(value) + ": " + what);
}

// The in-memory scenario's name in messages; "<name>:<line>" is replaced by the option that
// line came from.
constexpr const char* kIdentifyName = "flexbench identify";

}  // namespace

namespace {

// The input files exist and are regular files; --point-std is a length.
void CheckIdentifyInputs(const IdentifyCliOptions& o) {
  for (const auto& [option, path] :
       {std::pair{"--declared", o.declared}, std::pair{"--calibration", o.calibration_csv},
        std::pair{"--validation", o.validation_csv}}) {
    std::error_code ec;
    const fs::file_status st = fs::status(path, ec);
    if (ec || !fs::exists(st)) {
      OptionError(option, path,
                  "not found" + (ec && ec != std::errc::no_such_file_or_directory
                                     ? " (" + ec.message() + ")"
                                     : std::string()));
    }
    if (!fs::is_regular_file(st)) OptionError(option, path, "not a regular file");
  }
  if (!(std::isfinite(o.point_std_m) && o.point_std_m >= 1e-7 && o.point_std_m <= 1.0)) {
    char v[32];
    std::snprintf(v, sizeof(v), "%g", o.point_std_m);  // to_string: 1e-300 -> "0.000000"
    OptionError("--point-std", v, "must be between 1e-7 and 1 (metres)");
  }
}

// The declared model (--declared), and --model, when given, is the file it names.
sim::DeclaredModel IdentifyDeclared(const IdentifyCliOptions& o, const std::string& declared_abs) {
  sim::DeclaredModel declared;
  try {
    declared = sim::LoadDeclaredModel(declared_abs);
  } catch (const InputError& e) {
    throw InputError(std::string("--declared: ") + e.what());
  }
  if (!o.model.empty()) {
    std::error_code ec;
    if (!fs::exists(o.model, ec)) OptionError("--model", o.model, "not found");
    if (!fs::equivalent(o.model, declared.model_path, ec)) {
      OptionError("--model", o.model,
                  "is not the model the declared file names (" +
                      CapForMessage(declared.model_path) + "); omit --model or name the same file");
    }
  }
  return declared;
}

// Size caps before the same-rows comparison reads both files whole.
void CheckIdentifyRows(const IdentifyCliOptions& o) {
  for (const auto& [option, path] : {std::pair{"--calibration", o.calibration_csv},
                                     std::pair{"--validation", o.validation_csv}}) {
    try {
      CheckInputFile(path, identify::kMaxCalibrationCsvBytes);
    } catch (const InputError& e) {
      throw InputError(std::string(option) + ": " + e.what());
    }
  }
}

// The options own these keys: a --set of one would be ignored (model) or bypass the option's
// checks (the CSV files), so it is refused and the option named.
void CheckIdentifyOverrides(const std::vector<std::string>& set) {
  const std::vector<std::pair<std::string, std::string>> owned = {
      {"model", "--model (the model is the one --declared names)"},
      {"declared", "--declared"},
      {"calibration", "--calibration"},
      {"validation", "--validation"},
      {"kind", "another command (identify is the closed_loop kind)"}};
  for (const ConfigOverride& o : ParseOverrides(set)) {
    const std::string top = o.key.substr(0, o.key.find('.'));
    for (const auto& [key, option] : owned) {
      if (top == key) {
        throw InputError("--set " + CapForMessage(o.key) + ": identify sets '" + key +
                         "' from its options; use " + option);
      }
    }
  }
}

// The command line as a closed_loop scenario, configured in memory, one option a line:
// option_of_line[k] names the option line k (1-based) came from.
std::string IdentifyScenario(const IdentifyCliOptions& o, const sim::DeclaredModel& declared,
                             const std::string& declared_abs,
                             std::vector<std::string>* option_of_line_out) {
  std::vector<std::string>& option_of_line = *option_of_line_out;
  option_of_line = {""};  // 1-based lines
  std::ostringstream y;
  const auto line = [&](const std::string& option, const std::string& text) {
    y << text << "\n";
    option_of_line.push_back(option);
  };
  line("", "scenario: identify");
  line("", "kind: closed_loop");
  line("", "seed: 0");
  line("--declared", "model: " + Quoted(declared.model_path));
  line("--declared", "declared: " + Quoted(declared_abs));
  // CSV paths as given (relative ones resolve against the working folder): rows are named
  // "<path>:<line>" as the user wrote the path, whatever the working folder's location.
  line("--calibration", "calibration: {csv: " + Quoted(o.calibration_csv) + "}");
  line("--validation", "validation: {csv: " + Quoted(o.validation_csv) + "}");
  char num[64];
  std::snprintf(num, sizeof(num), "%.17g", o.point_std_m);
  line("--point-std", std::string("point_std_m: ") + num);
  if (o.reading_std_deg) {
    if (!(std::isfinite(*o.reading_std_deg) && *o.reading_std_deg > 0.0 &&
          *o.reading_std_deg <= 10.0)) {
      OptionError("--reading-std-deg", std::to_string(*o.reading_std_deg),
                  "must be in (0, 10] (degrees)");
    }
    std::snprintf(num, sizeof(num), "%.17g", *o.reading_std_deg);
    line("--reading-std-deg", std::string("reading_std_deg: ") + num);
  }
  if (o.max_effects) line("--max-effects", "max_effects: " + std::to_string(*o.max_effects));
  if (o.time_budget_s) {
    std::snprintf(num, sizeof(num), "%.17g", *o.time_budget_s);
    line("--time-budget", std::string("time_budget_s: ") + num);
  }
  if (o.bic_threshold) {
    std::snprintf(num, sizeof(num), "%.17g", *o.bic_threshold);
    line("--bic-threshold", std::string("bic_threshold: ") + num);
  }
  if (o.folds_by) line("--folds-by", "folds_by: " + Quoted(*o.folds_by));
  if (o.outlier_iqr) {
    std::snprintf(num, sizeof(num), "%.17g", *o.outlier_iqr);
    line("--outlier-iqr", std::string("outlier_iqr: ") + num);
  }
  if (o.no_cross_validation) line("--no-cross-validation", "cross_validation: false");
  if (!o.frames.empty()) {
    std::string f = "frames: {";
    for (size_t i = 0; i < o.frames.size(); ++i)
      f += (i ? ", " : "") + Quoted(o.frames[i]) + ": {}";
    line("--frame", f + "}");
  }
  if (!o.markers.empty()) {
    std::string m = "markers: [";
    for (size_t i = 0; i < o.markers.size(); ++i) m += (i ? ", " : "") + Quoted(o.markers[i]);
    line("--marker", m + "]");
  }
  if (!o.unknown_marker_offsets.empty()) {
    std::string u = "unknown_marker_offsets: [";
    for (size_t i = 0; i < o.unknown_marker_offsets.size(); ++i) {
      u += (i ? ", " : "") + Quoted(o.unknown_marker_offsets[i]);
    }
    line("--unknown-marker-offset", u + "]");
  }
  if (!o.candidates.empty()) {
    std::string c = "candidates: [";
    for (size_t i = 0; i < o.candidates.size(); ++i) {
      c += (i ? ", " : "") + Quoted(o.candidates[i]);
    }
    line("--candidates", c + "]");
  }
  return y.str();
}

// "flexbench identify:<line>: ..." names the option that line came from instead.
InputError WithOptionName(const InputError& e, const std::vector<std::string>& option_of_line) {
  std::string m = e.what();
  const std::string prefix = std::string(kIdentifyName) + ":";
  if (m.compare(0, prefix.size(), prefix) == 0) {
    size_t end = prefix.size();
    while (end < m.size() && std::isdigit(static_cast<unsigned char>(m[end]))) ++end;
    const int ln = std::atoi(m.substr(prefix.size(), end - prefix.size()).c_str());
    const std::string option =
        ln > 0 && ln < static_cast<int>(option_of_line.size()) ? option_of_line[ln] : "";
    std::string rest = m.substr(end);
    // The option names what the user wrote; the scenario key it became would only confuse.
    const std::string key_prefix = ": key '";
    const size_t key_end = rest.find("'", key_prefix.size());
    if (!option.empty() && rest.compare(0, key_prefix.size(), key_prefix) == 0 &&
        key_end != std::string::npos) {
      rest.erase(0, key_end + 1);
    }
    m = (option.empty() ? std::string("identify") : option) + rest;
  }
  return InputError(m);
}

}  // namespace

// The command line is checked, written as a closed_loop scenario in memory and run by the
// closed_loop kind: the CLI and the scenario files share one identification path.
int IdentifyCommand(const IdentifyCliOptions& o) {
  try {
    CheckIdentifyInputs(o);
    const std::string declared_abs = fs::absolute(o.declared).lexically_normal().string();
    const sim::DeclaredModel declared = IdentifyDeclared(o, declared_abs);
    CheckIdentifyRows(o);
    CheckIdentifyOverrides(o.set);
    std::vector<std::string> option_of_line;
    const std::string yaml = IdentifyScenario(o, declared, declared_abs, &option_of_line);
    const ConfigNode root = ConfigNode::LoadString(yaml, kIdentifyName, ParseOverrides(o.set));
    RunOptions run;
    run.out_dir = o.out_dir;
    run.force = o.force;
    run.set = o.set;  // recorded in summary.json
    run.quiet = o.quiet;
    run.command = o.command;
    try {
      return RunLoaded(root, run, "identify command line",
                       {fs::path(o.declared), fs::path(declared.model_path),
                        fs::path(o.calibration_csv), fs::path(o.validation_csv)});
    } catch (const InputError& e) {
      throw WithOptionName(e, option_of_line);
    }
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
