// `flexbench identify`: the closed_loop kind on a user's own model, declared model and CSV files,
// configured from the command line's options (no scenario text in between): an option's value
// goes into the run's set-up, its checks name the option; --set reads the other closed_loop keys
// over them.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/runner/common/closed_loop/setup.h"
#include "scenarios/runner/kinds/kinds.h"
#include "scenarios/runner/runner.h"
#include "sim/config.h"
#include "sim/declared_model.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

// Bad input about a command-line option: "--<option> <value>: <what>".
[[noreturn]] void OptionError(const std::string& option, const std::string& value,
                              const std::string& what) {
  throw InputError(option + " " + CapForMessage(value) + ": " + what);
}

// What messages call the --set keys' file.
constexpr const char* kIdentifyName = "flexbench identify";

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

// A CSV source as the user named it: a relative path stays relative (rows are named
// "<path>:<line>" as typed), normalised as a scenario file's paths are.
Source CsvSource(const std::string& path, const std::string& option) {
  Source s;
  s.type = Source::Type::kCsv;
  const fs::path p(path);
  s.path = p.is_absolute() ? p.string() : p.lexically_normal().string();
  s.where = option;
  s.path_where = option;
  return s;
}

// The options' conditions: those of the closed_loop keys they set (CheckIdentifyOption), and
// --reading-std-deg's own range.
void CheckSelectionOptions(const IdentifyCliOptions& o) {
  if (o.reading_std_deg && !(std::isfinite(*o.reading_std_deg) && *o.reading_std_deg > 0.0 &&
                             *o.reading_std_deg <= 10.0)) {
    OptionError("--reading-std-deg", std::to_string(*o.reading_std_deg),
                "must be in (0, 10] (degrees)");
  }
  if (o.max_effects) CheckIdentifyOption("max_effects", *o.max_effects, "--max-effects");
  if (o.time_budget_s) CheckIdentifyOption("time_budget_s", *o.time_budget_s, "--time-budget");
  if (o.bic_threshold) CheckIdentifyOption("bic_threshold", *o.bic_threshold, "--bic-threshold");
  if (o.folds_by) CheckFoldsBy(*o.folds_by, "--folds-by");
  if (o.outlier_iqr) CheckIdentifyOption("outlier_iqr", *o.outlier_iqr, "--outlier-iqr");
}

// A repeated option's names, each once: a name given twice is refused (`refuse_twice`, where
// the second would be a second thing of that name) or kept once.
std::vector<NamedNode> Named(const std::vector<std::string>& names, const std::string& option,
                             bool refuse_twice) {
  std::vector<NamedNode> out;
  for (const std::string& n : names) {
    const bool seen =
        std::any_of(out.begin(), out.end(), [&](const NamedNode& e) { return e.first == n; });
    if (seen && refuse_twice) {
      throw InputError(option + " '" + CapForMessage(n) + "': given twice");
    }
    if (!seen) out.push_back({n, option});
  }
  return out;
}

// The options as a closed_loop set-up; `keys` (the --set keys) are read over them.
void SetupFromOptions(const IdentifyCliOptions& o, sim::DeclaredModel declared,
                      const ConfigNode& keys, ClosedLoopSetup* cl) {
  cl->model_path = declared.model_path;
  cl->declared = std::move(declared);
  cl->calibration = CsvSource(o.calibration_csv, "--calibration");
  cl->validation = CsvSource(o.validation_csv, "--validation");
  identify::IdentifyOptions& opt = cl->opt;
  opt.point_std_m = o.point_std_m;
  if (o.reading_std_deg) cl->reading_std_rad = *o.reading_std_deg * kDeg;
  if (o.max_effects) opt.max_effects = *o.max_effects;
  if (o.time_budget_s) opt.time_budget_s = *o.time_budget_s;
  if (o.bic_threshold) opt.bic_threshold = *o.bic_threshold;
  if (o.folds_by) opt.folds_by = *o.folds_by;
  if (o.outlier_iqr) opt.outlier_iqr = *o.outlier_iqr;
  if (o.no_cross_validation) opt.cross_validation = false;
  for (const NamedNode& f : Named(o.frames, "--frame", /*refuse_twice=*/true)) {
    identify::CheckFrameName(f.first, f.second);
    identify::MeasurementFrame frame;
    frame.name = f.first;
    frame.where = f.second;
    cl->frames.push_back(frame);
  }
  cl->marker_nodes = Named(o.markers, "--marker", false);
  cl->unknown_offset_nodes = Named(o.unknown_marker_offsets, "--unknown-marker-offset", false);
  cl->candidate_specs = Named(o.candidates, "--candidates", false);
  ReadClosedLoopKeys(keys, cl, /*sources=*/false);
  BuildClosedLoopSetup(keys, cl);
}

}  // namespace

int IdentifyCommand(const IdentifyCliOptions& o) {
  try {
    CheckIdentifyInputs(o);
    const std::string declared_abs = fs::absolute(o.declared).lexically_normal().string();
    sim::DeclaredModel declared = IdentifyDeclared(o, declared_abs);
    CheckIdentifyRows(o);
    CheckIdentifyOverrides(o.set);
    CheckSelectionOptions(o);
    const ConfigNode keys = ConfigNode::LoadString("{}", kIdentifyName, ParseOverrides(o.set));
    PreparedRun prepared;
    ReadRunHeader(keys, RunOptions{}, "identify", &prepared);
    prepared.kind_name = "closed_loop";
    prepared.gates = ParseGates(keys);
    auto setup = std::make_unique<ClosedLoopSetup>();
    const std::string model_path = declared.model_path;
    SetupFromOptions(o, std::move(declared), keys, setup.get());
    keys.CheckNoUnknownKeys();
    prepared.kind = MakeClosedLoopKind(std::move(setup));
    RunOptions run;
    run.out_dir = o.out_dir;
    run.force = o.force;
    run.set = o.set;  // recorded in summary.json
    run.quiet = o.quiet;
    run.command = o.command;
    return RunPrepared(std::move(prepared), run, "identify command line",
                       {fs::path(o.declared), fs::path(model_path), fs::path(o.calibration_csv),
                        fs::path(o.validation_csv)});
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
