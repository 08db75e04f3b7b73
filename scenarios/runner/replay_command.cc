#include "scenarios/runner/replay_command.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "estimators/error.h"
#include "estimators/estimator.h"
#include "scenarios/runner/runner.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

// A YAML scalar holding `text` exactly (a JSON string is one); `what` names it when it is not
// UTF-8 (YAML text must be).
std::string Quoted(const std::string& text, const std::string& what) {
  try {
    return nlohmann::json(text).dump();
  } catch (const nlohmann::json::exception&) {
    throw InputError(what + ": the path is not UTF-8 text; rename it");
  }
}

// `path` absolute, without "." or ".." and without a trailing '/'.
fs::path Normal(const std::string& path) {
  const fs::path n = fs::absolute(path).lexically_normal();
  return n.filename().empty() ? n.parent_path() : n;
}

std::string ReplayScenario(const ReplayCliOptions& o) {
  if (o.log.empty()) throw InputError("LOG: name the log folder");
  const fs::path log = Normal(o.log);
  std::error_code ec;
  if (!fs::is_directory(log, ec)) {
    throw InputError(CapForMessage(o.log) + ": not a folder (a recorded log holds log.yaml)");
  }
  if (!(o.step_hz >= 0.0) || !std::isfinite(o.step_hz)) {
    throw InputError("--step-hz: must be 0 (a step per joint row) or a rate > 0 in Hz");
  }
  std::string yaml =
      "scenario: replay\nkind: replay\nseed: 0\nlog: " + Quoted(log.string(), "LOG") + "\n";
  if (!o.declared.empty()) {
    yaml += "declared: " + Quoted(Normal(o.declared).string(), "--declared") + "\n";
  }
  char hz[40];
  std::snprintf(hz, sizeof(hz), "%.17g", o.step_hz);
  yaml += std::string("step_hz: ") + hz + "\n";
  if (o.estimate_imu_clock_offset) yaml += "imu_clock_offset: estimate\n";
  yaml += "estimators:\n";
  if (o.estimators.empty()) throw InputError("--estimators: name at least one estimator");
  for (const std::string& e : o.estimators) {
    const auto& reg = estimators::EstimatorRegistry();
    if (std::none_of(reg.begin(), reg.end(), [&](const auto& r) { return e == r.name; })) {
      std::string known;
      for (const auto& r : reg) known += (known.empty() ? "" : ", ") + std::string(r.name);
      throw InputError("--estimators: unknown estimator '" + CapForMessage(e) +
                       "' (known: " + known + ")");
    }
    yaml += "  " + e + ": {}\n";
  }
  return yaml;
}

}  // namespace

int ReplayCommand(const ReplayCliOptions& o) {
  try {
    const std::string yaml = ReplayScenario(o);
    std::vector<ConfigOverride> overrides;
    for (const std::string& s : o.set) overrides.push_back(ParseOverride(s));
    const ConfigNode root = ConfigNode::LoadString(yaml, "replay command line", overrides);
    RunOptions run;
    run.out_dir = o.out_dir.empty() ? "out/replay/" + Normal(o.log).filename().string() : o.out_dir;
    run.check_gates = o.check_gates;
    run.force = o.force;
    run.set = o.set;
    run.quiet = o.quiet;
    run.command = o.command;
    return RunLoaded(root, run, "replay command line", {});
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
