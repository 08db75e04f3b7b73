#include "scenarios/sweep/sweep_command.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <thread>

#include "scenarios/runner/output.h"
#include "scenarios/runner/report.h"
#include "scenarios/runner/runner.h"
#include "scenarios/sweep/collect.h"
#include "scenarios/sweep/local_executor.h"
#include "sim/config.h"

namespace fs = std::filesystem;

namespace flexbench::scenarios::sweep {
namespace {

constexpr const char* kMarker = ".flexbench-sweep";

void Log(const std::string& line) { std::cerr << "[sweep] " << line << "\n"; }

// The output folder is this sweep's (it holds the marker naming it), or new, or empty.
void PrepareOutDir(const fs::path& out, const SweepSpec& spec) {
  std::error_code ec;
  if (fs::exists(out, ec)) {
    if (!fs::is_directory(out, ec)) {
      throw InputError("--out " + CapForMessage(out.string()) + ": not a folder");
    }
    std::ifstream in(out / kMarker);
    std::string name;
    if (in >> name) {
      if (name != spec.name) {
        throw InputError("--out " + CapForMessage(out.string()) + ": holds the sweep '" +
                         CapForMessage(name) + "', not '" + spec.name + "'");
      }
      return;
    }
    if (!fs::is_empty(out, ec)) {
      throw InputError("--out " + CapForMessage(out.string()) +
                       ": exists and is not a sweep's folder (no " + kMarker + ")");
    }
  }
  fs::create_directories(out);
  WriteFileAtomic(out / kMarker, spec.name + "\n");
}

void ParseShard(const std::string& text, int* index, int* count) {
  const size_t slash = text.find('/');
  const auto fail = [&](const std::string& why) {
    throw InputError("--shard '" + CapForMessage(text) + "': " + why);
  };
  if (slash == std::string::npos) fail("expected i/n (e.g. 0/4)");
  try {
    size_t used = 0;
    *index = std::stoi(text.substr(0, slash), &used);
    if (used != slash) fail("expected i/n (e.g. 0/4)");
    const std::string n = text.substr(slash + 1);
    *count = std::stoi(n, &used);
    if (used != n.size()) fail("expected i/n (e.g. 0/4)");
  } catch (const std::logic_error&) {
    fail("expected i/n (e.g. 0/4)");
  }
  if (*count < 1) fail("n must be >= 1");
  if (*index < 0 || *index >= *count) {
    fail("index out of range (0.." + std::to_string(*count - 1) + ")");
  }
}

// Every point's scenario is loaded and configured before any run: a swept key the scenario
// lacks, or a value of the wrong type, is bad input naming the point.
std::set<std::string> CheckPoints(const SweepSpec& spec, const std::vector<SweepPoint>& points) {
  std::set<std::string> gate_names;
  for (const SweepPoint& p : points) {
    std::vector<std::string> set = spec.set;
    set.insert(set.end(), p.set.begin(), p.set.end());
    try {
      const ScenarioCheck check = CheckScenario(spec.scenario, set);
      gate_names.insert(check.gate_names.begin(), check.gate_names.end());
    } catch (const InputError& e) {
      throw InputError(spec.file + ": point '" + p.name + "': " + e.what());
    }
  }
  for (const SweepGate& g : spec.gates) {
    for (const Statistic* s : {&g.metric, &g.threshold_metric}) {
      if (s->of_gate && !gate_names.count(s->path)) {
        throw InputError(g.where + ": gate '" + g.name + "': '" + CapForMessage(s->path) +
                         "' is not a gate of the scenario " + spec.scenario);
      }
    }
  }
  return gate_names;
}

// How the sweep was collected, for its report; aggregate.json stays free of it, so that it is
// the same bytes whichever executor or folder made it.
void WriteSweepCommand(const fs::path& out, const SweepSpec& spec, const std::string& command) {
  Json how;
  how["command"] = command;
  how["sweep_file"] = spec.file;
  how["scenario"] = spec.scenario;
  WriteFileAtomic(out / kSweepCommandFile,
                  how.dump(2, ' ', false, Json::error_handler_t::replace) + "\n");
}

int CollectAndGate(const SweepSpec& spec, const std::vector<SweepPoint>& points,
                   const std::vector<SweepRun>& runs, const RunKeys& keys, const fs::path& out,
                   const std::string& command) {
  std::vector<fs::path> run_dirs;
  for (const SweepRun& run : runs) run_dirs.push_back(out / run.dir);
  RemoveEndedTemporaries(run_dirs);
  std::map<std::string, size_t> stale;
  const std::vector<RunOutcome> outcomes = ReadOutcomes(out, points, runs, keys, &stale);
  if (!stale.empty()) {
    size_t n = 0;
    for (const auto& [why, k] : stale) n += k;
    Log(std::to_string(n) + " results made with other settings not collected (" +
        RerunReasons(stale) + "): run the sweep again without --collect to redo them");
  }
  const Collected c = Collect(spec, points, runs, outcomes);
  WriteCollected(out, spec, points, c);
  if (!command.empty()) WriteSweepCommand(out, spec, command);
  try {
    WriteReport(out);
  } catch (const std::exception& e) {
    Log(std::string("report.html not written: ") + e.what());
  }
  size_t failed = 0, missing = 0;
  for (const RunOutcome& o : outcomes) {
    failed += o.present && !o.ok;
    missing += !o.present;
  }
  for (const Json& g : c.aggregate["gates"]) {
    Log(std::string(g["passed"].get<bool>() ? "PASS" : "FAIL") + " gate " +
        g["name"].get<std::string>() + " @" + g["point"].get<std::string>() + ": " +
        g["metric"].get<std::string>() + " = " + g["value"].dump() + " " +
        g["op"].get<std::string>() + " " + g["threshold"].dump());
  }
  Log("results in " + out.string() + " (sweep.csv, aggregate.json, report.html)");
  if (failed || missing) {
    Log(std::to_string(failed) + " runs failed, " + std::to_string(missing) +
        " have no result (see aggregate.json \"failed\")");
  }
  if (!c.gates_passed) return kExitGateFailed;
  return failed || missing ? kExitInternal : kExitOk;
}

int RunOnSlurm(const SweepCliOptions& o, const SweepSpec& spec,
               const std::vector<SweepPoint>& points, const std::vector<SweepRun>& runs,
               const RunKeys& keys, const fs::path& out) {
  int tasks = 0;
  const std::string id = SubmitSlurm(spec, runs.size(), out, o.slurm, &tasks);
  Log("submitted Slurm job " + id + " (" + std::to_string(tasks) + " array tasks)");
  if (!o.slurm.wait) {
    Log("collect when it has ended: flexbench sweep " + spec.file + " --out " + out.string() +
        " --collect");
    return kExitOk;
  }
  std::vector<int> failed;
  for (const SlurmTaskEnd& e : WaitForSlurm(id, tasks, out)) {
    if (e.state == "COMPLETED" && e.exit_code == 0) continue;
    failed.push_back(e.index);
    Log("task " + std::to_string(e.index) + " ended " + e.state + " (exit " +
        std::to_string(e.exit_code) + "); its output: " +
        (out / "slurm" / ("task_" + std::to_string(e.index) + ".out")).string());
  }
  if (!failed.empty()) {
    std::string list;
    for (int i : failed) list += (list.empty() ? "" : ",") + std::to_string(i);
    Log("resubmit the failed tasks alone: flexbench sweep " + spec.file + " --out " + out.string() +
        " --executor slurm --tasks " + std::to_string(tasks) + " --array " + list);
  }
  return CollectAndGate(spec, points, runs, keys, out, o.command);
}

// The files the points' checks accepted (scenario, models, declared models, CSVs), without the
// sweep file: with the scenario file they define the runs' results.
std::vector<std::string> InputFiles(const SweepSpec& spec) {
  std::error_code ec;
  const std::string sweep_file = fs::weakly_canonical(fs::absolute(spec.file), ec).string();
  std::vector<std::string> files;
  for (const std::string& f : RecordedInputFiles()) {
    if (f != sweep_file) files.push_back(f);
  }
  return files;
}

}  // namespace

int SweepCommand(const SweepCliOptions& o) {
  try {
    if (o.executor != "local" && o.executor != "slurm") {
      throw InputError("--executor '" + CapForMessage(o.executor) + "': expected local or slurm");
    }
    if (o.jobs < 0 || o.jobs > 1024) {
      throw InputError("-j " + std::to_string(o.jobs) +
                       ": must be between 1 and 1024 (or 0: one per core)");
    }
    CheckSlurmOptions(o.slurm);
    int shard_index = 0, shard_count = 0;
    if (!o.shard.empty()) ParseShard(o.shard, &shard_index, &shard_count);
    if (o.executor == "slurm") CheckSlurmClients();
    SweepSpec spec = LoadSweep(o.sweep_path);
    if (!o.run_files.empty()) spec.run_data_files = ParseRunFiles(o.run_files, "--run-files");
    const std::vector<SweepPoint> points = ExpandPoints(spec);
    const std::vector<SweepRun> runs = ExpandRuns(spec, points);
    const fs::path out =
        o.out_dir.empty() ? fs::path("out") / "sweeps" / spec.name : fs::path(o.out_dir);
    if (o.collect) {
      std::error_code ec;
      if (!fs::is_regular_file(out / kMarker, ec)) {
        throw InputError("--out " + CapForMessage(out.string()) + ": not a sweep's folder");
      }
    }
    // Also before --collect: the checks read the input files that the run keys cover.
    CheckPoints(spec, points);
    const RunKeys keys(spec, points, InputFiles(spec));
    if (o.collect) return CollectAndGate(spec, points, runs, keys, out, o.command);
    if (o.executor == "slurm") CheckSlurmOut(out);
    PrepareOutDir(out, spec);
    if (o.executor == "slurm") return RunOnSlurm(o, spec, points, runs, keys, out);
    const PendingRunList pending = PendingRuns(out, runs, keys, shard_index, shard_count);
    const int jobs =
        o.jobs > 0 ? o.jobs : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
    if (!pending.rerun.empty()) Log(RerunMessage(pending.rerun));
    Log(spec.name + ": " + std::to_string(points.size()) + " points x " +
        std::to_string(spec.seeds.size()) + " seeds" +
        (shard_count ? ", shard " + o.shard : std::string()) + ": " +
        std::to_string(pending.todo.size()) + " runs to do, -j " + std::to_string(jobs));
    const LocalOutcome done = RunLocal(spec, points, runs, pending.todo, out, jobs, keys);
    if (done.signal) {
      Log("stopped by a signal; the finished runs are kept: run the same command to resume");
      return 128 + done.signal;
    }
    if (shard_count) return done.failed ? kExitInternal : kExitOk;
    return CollectAndGate(spec, points, runs, keys, out, o.command);
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios::sweep
