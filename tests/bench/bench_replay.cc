// Replaying a recorded log: `flexbench replay` over a 60 s jsk_arm log (100 Hz joints, two IMUs
// at 200 Hz, truth at 100 Hz; tests/common/jsk_log.h), one estimator a run, a step at every
// joint row (6,000 steps). Counters: realtime_x (60 s of log over the run's own time,
// summary.json timing.total_s) and wall_realtime_x (over the whole process: loading included).
// BM_ReadRecordedLog: the reader alone on a log of 1,000,000 IMU rows (and 250,000 joint and
// truth rows), s_per_million_rows of all three streams. BM_Replay/ppoe_ekf_tags: the same log
// with a fixed camera's detections of the gripper tag at 10 Hz. BM_LogLoop: closed_loop on that
// log (truth.tum as tracker points and the tags' pixels, 42 s identified, 18 s held out and
// replayed through fk), the whole run.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "sim/recorded_log.h"
#include "tests/common/jsk_log.h"

namespace fs = std::filesystem;

namespace {

fs::path BinDir() { return fs::read_symlink("/proc/self/exe").parent_path(); }

fs::path WorkDir() {
  static const fs::path d =
      fs::temp_directory_path() / ("bench_replay_" + std::to_string(getpid()));
  return d;
}

const fs::path& Log(const std::string& name, double duration, bool tags = false) {
  static std::map<std::string, fs::path> logs;
  auto it = logs.find(name);
  if (it == logs.end()) {
    const fs::path dir = WorkDir() / name;
    flexbench::testing::JskLogOptions o;
    o.duration = duration;
    o.tags = tags;
    flexbench::testing::WriteJskLog(dir, o);
    it = logs.emplace(name, dir).first;
  }
  return it->second;
}

void BM_Replay(benchmark::State& state, const std::string& estimator, bool tags) {
  const fs::path& log = tags ? Log("log60tags", 60.0, true) : Log("log60", 60.0);
  const fs::path out = WorkDir() / ("out_" + estimator);
  const std::string set =
      estimator.rfind("pf_", 0) == 0 ? " --set estimators." + estimator + ".particles=2048" : "";
  const std::string cmd = (BinDir() / "flexbench").string() + " replay " + log.string() +
                          " --estimators " + estimator + set + " --quiet --out " + out.string();
  double run_s = 0.0, wall_s = 0.0;
  for (auto _ : state) {
    fs::remove_all(out);
    const auto t0 = std::chrono::steady_clock::now();
    if (std::system(cmd.c_str()) != 0) {
      state.SkipWithError("flexbench replay failed");
      return;
    }
    wall_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::ifstream in(out / "summary.json");
    run_s += nlohmann::json::parse(in)["timing"]["total_s"].get<double>();
  }
  const double n = static_cast<double>(state.iterations());
  state.counters["realtime_x"] = 60.0 / (run_s / n);
  state.counters["wall_realtime_x"] = 60.0 / (wall_s / n);
}

void BM_LogLoop(benchmark::State& state) {
  const fs::path& log = Log("log60tags", 60.0, true);
  const fs::path scenario = WorkDir() / "loop.yaml";
  const std::string models = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";
  std::ofstream(scenario) << "scenario: loop\nkind: closed_loop\nseed: 1\nmodel: " << models
                          << "jsk_arm.xml\ndeclared: " << models
                          << "jsk_arm.declared.yaml\ncalibration: {log: {dir: " << log.string()
                          << ", to_s: 42}}\nvalidation: {log: {dir: " << log.string()
                          << ", from_s: 42.001}}\n";
  const fs::path out = WorkDir() / "out_loop";
  const std::string cmd = (BinDir() / "flexbench").string() + " run " + scenario.string() +
                          " --quiet --out " + out.string();
  for (auto _ : state) {
    fs::remove_all(out);
    if (std::system(cmd.c_str()) != 0) {
      state.SkipWithError("flexbench run (closed_loop on a log) failed");
      return;
    }
  }
  std::ifstream in(out / "summary.json");
  const nlohmann::json m = nlohmann::json::parse(in)["metrics"];
  state.counters["rows"] = m["calibration_rows"].get<double>() + m["validation_rows"].get<double>();
}

void BM_ReadRecordedLog(benchmark::State& state) {
  const fs::path& log = Log("log2500", 2500.0);  // 1,000,000 IMU rows
  size_t rows = 0;
  for (auto _ : state) {
    const flexbench::sim::RecordedLog l = flexbench::sim::ReadRecordedLog(log.string());
    rows = l.imu.size() + l.joint_t.size() + l.truth_t.size();
    benchmark::DoNotOptimize(l.imu.data());
  }
  state.counters["rows"] = static_cast<double>(rows);
  state.counters["s_per_million_rows"] = benchmark::Counter(
      static_cast<double>(rows) / 1e6,
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

}  // namespace

BENCHMARK_CAPTURE(BM_Replay, ppoe_ekf, std::string("ppoe_ekf"), false)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Replay, ppoe_ekf_tags, std::string("ppoe_ekf"), true)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Replay, pf_encoders_imu, std::string("pf_encoders_imu"), false)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Replay, fk, std::string("fk"), false)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();
BENCHMARK(BM_LogLoop)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();
BENCHMARK(BM_ReadRecordedLog)->Unit(benchmark::kMillisecond)->Iterations(3);

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  fs::remove_all(WorkDir());
  return 0;
}
