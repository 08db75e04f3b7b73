// Speed of the truth side on rover_arm (contacts disabled in the model):
//  - BM_RoverMjStep: MuJoCo's mj_step on the MJCF as written (every passive joint free).
//    Target >= 30,000 steps/s.
//  - BM_RoverSimulationStep: Simulation::Step with base plate and elastic links on (servo
//    feed-forward, locked-joint projection).
//  - BM_RoverSettle: one quasi-static settle (direct Newton solve) per configuration, cycling
//    through a folded-to-stretched-out sweep. Target < 50 ms per configuration.
// Run with --benchmark_repetitions=5 --benchmark_report_aggregates_only=true; quote medians.
#include <benchmark/benchmark.h>

#include <cmath>

#include "sim/mujoco_model.h"
#include "sim/simulation.h"

namespace flexbench::sim {
namespace {

std::string RoverPath() { return std::string(FLEXBENCH_SOURCE_DIR) + "/models/rover_arm.xml"; }

std::unique_ptr<Simulation> CompliantRover() {
  EffectList fx;
  fx.push_back(MakeEffect("base_compliance"));
  fx.push_back(MakeEffect("link_bending"));
  fx.push_back(MakeEffect("camera_mount_sag"));
  return Simulation::Load(RoverPath(), fx);
}

Eigen::VectorXd SweepCommand(int num_actuated, int k, int n) {
  const double a = static_cast<double>(k % n) / (n - 1);
  const double deg = M_PI / 180.0;
  Eigen::VectorXd q = Eigen::VectorXd::Zero(num_actuated);
  q[0] = (k / n % 2 ? 90.0 : 0.0) * deg;  // forward, then sideways
  q[1] = 90.0 * a * deg;
  q[2] = 150.0 * (1 - a) * deg;
  q[4] = (-90.0 + 60.0 * a) * deg;
  return q;
}

void BM_RoverMjStep(benchmark::State& state) {
  MjModelPtr model = LoadModel(RoverPath());
  MjDataPtr data = MakeData(model.get());
  mjModel* m = model.get();
  mjData* d = data.get();
  // Hold the arm stretched out.
  for (int a = 0; a < m->nu; ++a) d->ctrl[a] = 0.0;
  d->ctrl[1] = M_PI / 2;
  for (auto _ : state) {
    mj_step(m, d);
  }
  benchmark::DoNotOptimize(d->qpos[0]);
  state.SetItemsProcessed(state.iterations());
  state.counters["ncon"] = d->ncon;
}
BENCHMARK(BM_RoverMjStep);

void BM_RoverSimulationStep(benchmark::State& state) {
  auto sim = CompliantRover();
  sim->SetCommand(SweepCommand(sim->num_actuated(), 7, 8));
  sim->Settle();
  for (auto _ : state) {
    sim->Step(1);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_RoverSimulationStep);

void BM_RoverSettle(benchmark::State& state) {
  auto sim = CompliantRover();
  int k = 0;
  int iterations = 0;
  for (auto _ : state) {
    sim->SetCommand(SweepCommand(sim->num_actuated(), k++, 8));
    iterations += sim->Settle().iterations;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["newton_iterations"] =
      benchmark::Counter(iterations, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_RoverSettle)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace flexbench::sim

BENCHMARK_MAIN();
