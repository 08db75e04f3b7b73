// What the sweep machinery costs per run. A local sweep of 16 runs of the contact
// scenario (~60 ms of work each) with one worker, against the same 16 runs as 16 `flexbench
// run` processes in a shell loop (what a user without sweeps writes). Counters: wall time per
// run, the runs' own time (summary.json timing.total_s) and the difference, the overhead.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace fs = std::filesystem;

namespace {

fs::path BinDir() { return fs::read_symlink("/proc/self/exe").parent_path(); }

fs::path WorkDir() {
  static const fs::path d = fs::temp_directory_path() / ("bench_sweep_" + std::to_string(getpid()));
  return d;
}

std::string Scenario() {
  return std::string(FLEXBENCH_SOURCE_DIR) + "/scenarios/humanoid_table_contact.yaml";
}

// Mean of timing.total_s over the summaries under `dir`.
double MeanRunSeconds(const fs::path& dir) {
  double sum = 0.0;
  int n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.path().filename() != "summary.json") continue;
    std::ifstream in(e.path());
    const auto j = nlohmann::json::parse(in);
    sum += j["timing"]["total_s"].get<double>();
    ++n;
  }
  return n ? sum / n : 0.0;
}

void Report(benchmark::State& state, double wall_s_total, double run_s) {
  const int runs = static_cast<int>(state.range(0));
  const double per_run = wall_s_total / state.iterations() / runs;
  state.counters["ms_per_run"] = per_run * 1e3;
  state.counters["run_own_ms"] = run_s * 1e3;
  state.counters["overhead_ms"] = (per_run - run_s) * 1e3;
}

void BM_SweepLocal(benchmark::State& state) {
  const int kRuns = static_cast<int>(state.range(0));
  const fs::path file = WorkDir() / "s.yaml";
  fs::create_directories(WorkDir());
  std::ofstream(file) << "sweep: bench\nscenario: " << Scenario()
                      << "\nseeds: {from: 1, to: " << kRuns << "}\n";
  const fs::path out = WorkDir() / "sweep_out";
  const std::string cmd = (BinDir() / "flexbench").string() + " sweep " + file.string() +
                          " --out " + out.string() + " -j 1 2>/dev/null";
  double wall = 0.0, run_s = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    fs::remove_all(out);
    state.ResumeTiming();
    const auto t0 = std::chrono::steady_clock::now();
    if (std::system(cmd.c_str()) != 0) state.SkipWithError("sweep failed");
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    state.PauseTiming();
    run_s = MeanRunSeconds(out / "runs");
    state.ResumeTiming();
  }
  Report(state, wall, run_s);
}
BENCHMARK(BM_SweepLocal)
    ->Arg(4)
    ->Arg(32)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3)
    ->UseRealTime();

void BM_ShellLoopOfRuns(benchmark::State& state) {
  const int kRuns = static_cast<int>(state.range(0));
  const fs::path out = WorkDir() / "loop_out";
  std::string cmd;
  for (int s = 1; s <= kRuns; ++s) {
    cmd += (BinDir() / "flexbench").string() + " run " + Scenario() + " --seed " +
           std::to_string(s) + " --out " + (out / std::to_string(s)).string() +
           " 2>/dev/null >/dev/null; ";
  }
  double wall = 0.0, run_s = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    fs::remove_all(out);
    fs::create_directories(out);
    state.ResumeTiming();
    const auto t0 = std::chrono::steady_clock::now();
    if (std::system(cmd.c_str()) != 0) state.SkipWithError("runs failed");
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    state.PauseTiming();
    run_s = MeanRunSeconds(out);
    state.ResumeTiming();
  }
  Report(state, wall, run_s);
  fs::remove_all(WorkDir());
}
BENCHMARK(BM_ShellLoopOfRuns)->Arg(16)->Unit(benchmark::kMillisecond)->Iterations(3)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
