// A scenario kind turns a scenario file into results. Kinds are chosen by the file's `kind`
// key from one explicit list (registry.cc).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "scenarios/runner/output.h"
#include "sim/config.h"

namespace flexbench::scenarios {
using flexbench::ConfigNode;

using Json = nlohmann::ordered_json;

// What a running scenario can use and fill.
struct RunContext {
  std::uint64_t seed = 0;
  OutputDir* out = nullptr;
  // summary.json: kinds fill `metrics` and `estimators.NAME.metrics`; the runner adds
  // scenario, seed, gates and timing.
  Json* summary = nullptr;
  // Wall-clock seconds of named stages, reported under `timing`.
  Json* timing = nullptr;
  // Log line to stderr ("[flexbench] ...").
  std::function<void(const std::string&)> log;
  // Progress of long runs (shown on stderr only when it is a terminal).
  std::function<void(const std::string& stage, int done, int total)> progress;
  // A folder to write the run's readings into as a recorded log (ScenarioKind::ExportsLog);
  // empty: none.
  std::string export_log;
  // Which images to write (--frames); kinds ask WritesFrame for rendered camera frames, and the
  // runner removes every image of a run with kNone.
  FrameOutput frames = FrameOutput::kKey;
};

class ScenarioKind {
 public:
  virtual ~ScenarioKind() = default;
  // Reads the kind's keys from the scenario file (every key it does not read is reported as
  // unknown afterwards). Must validate everything, so that bad input fails before any work.
  virtual void Configure(const ConfigNode& root) = 0;
  virtual void Run(RunContext& ctx) = 0;
  // Whether Run writes its readings to RunContext::export_log when asked.
  virtual bool ExportsLog() const { return false; }
};

struct KindEntry {
  const char* name;
  const char* description;
  std::unique_ptr<ScenarioKind> (*make)();
};

// The explicit list of scenario kinds.
const std::vector<KindEntry>& ScenarioKinds();

}  // namespace flexbench::scenarios
