// PPOE forward kinematics timings: mean only, and with covariance at 2nd and 4th order, for a
// 7-DoF and a 27-DoF chain with random geometry (fixed seed) and a full 6-DoF source at every
// joint. Targets (one core, 7-DoF): mean <= 0.25 us, 2nd order <= 0.5 us, 4th order <= 5 us.
// Run with --benchmark_repetitions=5 --benchmark_report_aggregates_only=true.
#include <benchmark/benchmark.h>

#include <random>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "tests/unit/kinematics/ppoe_test_models.h"

namespace flexbench::kinematics {
namespace {

struct Fixture {
  explicit Fixture(int dof) : model(Build(dof)), data(model), q(Q(model)) {}

  static PpoeModel Build(int dof) {
    std::mt19937_64 rng(42);
    testing::RandomChainOptions o;
    o.dof = dof;
    o.trans_sd = 0.005;
    o.rot_sd = 0.02;
    o.tag = false;  // links + end effector only
    return testing::RandomChain(rng, o);
  }
  static Eigen::VectorXd Q(const PpoeModel& model) {
    std::mt19937_64 rng(7);
    return testing::RandomQ(rng, model);
  }

  PpoeModel model;
  PpoeData data;
  Eigen::VectorXd q;
};

void BM_ForwardKinematics(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    ForwardKinematics(f.model, f.data, f.q);
    benchmark::DoNotOptimize(f.data.T_base_frame.back());
    benchmark::ClobberMemory();
  }
}

void BM_ForwardKinematicsCov2(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    ForwardKinematicsWithCovariance(f.model, f.data, f.q, lie::CompoundOrder::kSecond);
    benchmark::DoNotOptimize(f.data.Sigma_frame.back());
    benchmark::ClobberMemory();
  }
}

// The path a CPU without AVX2 runs (two-lane SSE2 transports, same bits), timed on this CPU;
// the target is <= 550 ns on 7 DoF. Its ratio to BM_ForwardKinematicsCov2 in the same run
// is the cost of having no AVX2 (figures: docs/performance.md).
void BM_ForwardKinematicsCov2Baseline(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    internal::ForwardKinematicsWithCovarianceBaseline(f.model, f.data, f.q,
                                                      lie::CompoundOrder::kSecond);
    benchmark::DoNotOptimize(f.data.Sigma_frame.back());
    benchmark::ClobberMemory();
  }
}

void BM_ForwardKinematicsCov4(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    ForwardKinematicsWithCovariance(f.model, f.data, f.q, lie::CompoundOrder::kFourth);
    benchmark::DoNotOptimize(f.data.Sigma_frame.back());
    benchmark::ClobberMemory();
  }
}

// Identified effects on the 7-DoF chain: 1 kg on every link, three load-driven effects (a gear
// spring at the 2nd joint, the link ending at the 4th bending, the mount tilting at the 1st) and
// an encoder offset. The loads are computed per call from the masses.
ModelEffects ThreeLoadDrivenEffects(const PpoeModel& model) {
  ModelEffects e = ModelEffects::None(model);
  for (FrameId f = 1; f < model.num_frames(); ++f) {
    if (model.frame(f).q_index >= 0) e.masses[f] = {1.0, Vec3(0.05, 0.0, 0.01)};
  }
  for (FrameId f = model.FindFrame("ee"); f > 0; f = model.frame(f).parent) e.on_path[f] = 1;
  e.joints[0].offset = 0.01;
  e.joints[1].compliance = -2e-3;
  const FrameId j4 = model.joint_frame(3);
  e.frames[j4].bend = 1e-3;
  e.frames[j4].bend_start = model.joint_frame(2);
  e.frames[j4].bend_dir = model.frame(j4).T_parent_ip.translation().normalized();
  e.mount = model.joint_frame(0);
  e.mount_compliance = Eigen::Vector2d(1e-3, 2e-3);
  return e;
}

// Baseline in the same run: BM_ForwardKinematicsCov2/7 (the target: at most 2x). What keeps the
// update cheap: the loads come from each subtree's first moment in its own frame (no base
// poses), the mount's rotation from MountTilt's own sines and cosines.
void BM_AugmentedForwardKinematicsCov2(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  const ModelEffects effects = ThreeLoadDrivenEffects(f.model);
  EffectiveChain kin(f.model, &effects);
  for (auto _ : state) {
    kin.Update(f.q);
    ForwardKinematicsWithCovariance(kin.model(), f.data, kin.q(), lie::CompoundOrder::kSecond);
    benchmark::DoNotOptimize(f.data.Sigma_frame.back());
    benchmark::ClobberMemory();
  }
}

// The correction alone (loads, joint map, bent and tilted fixed parts), without the FK.
void BM_EffectiveChainUpdate(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  const ModelEffects effects = ThreeLoadDrivenEffects(f.model);
  EffectiveChain kin(f.model, &effects);
  for (auto _ : state) {
    kin.Update(f.q);
    benchmark::DoNotOptimize(kin.q().data());
    benchmark::ClobberMemory();
  }
}

// The same with the fitted parameters' stds carried as sources (ModelEffects::Uncertainty): the
// compliances' and the plate's sources are re-evaluated at every reading.
void BM_AugmentedUncertainForwardKinematicsCov2(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  ModelEffects effects = ThreeLoadDrivenEffects(f.model);
  for (int k = 0; k < f.model.nq(); ++k) effects.uncertainty.joints[k].offset = 1e-8;
  effects.uncertainty.joints[1].compliance = 1e-8;
  for (FrameId fr = 1; fr < f.model.num_frames(); ++fr) {
    if (effects.frames[fr].bend != 0.0) effects.uncertainty.bend[fr] = 1e-9;
  }
  effects.uncertainty.mount_compliance = Eigen::Vector2d(1e-8, 1e-8);
  EffectiveChain kin(f.model, &effects);
  for (auto _ : state) {
    kin.Update(f.q);
    ForwardKinematicsWithCovariance(kin.model(), f.data, kin.q(), lie::CompoundOrder::kSecond);
    benchmark::DoNotOptimize(f.data.Sigma_frame.back());
    benchmark::ClobberMemory();
  }
}

void BM_FrameJacobian(benchmark::State& state) {
  Fixture f(static_cast<int>(state.range(0)));
  ForwardKinematics(f.model, f.data, f.q);
  const FrameId ee = f.model.FindFrame("ee");
  Matrix6Xd J(6, f.model.nq());
  for (auto _ : state) {
    ComputeFrameJacobian(f.model, f.data, ee, J);
    benchmark::DoNotOptimize(J.data());
    benchmark::ClobberMemory();
  }
}

BENCHMARK(BM_ForwardKinematics)->Arg(7)->Arg(27);
BENCHMARK(BM_ForwardKinematicsCov2)->Arg(7)->Arg(27);
BENCHMARK(BM_ForwardKinematicsCov2Baseline)->Arg(7)->Arg(27);
BENCHMARK(BM_ForwardKinematicsCov4)->Arg(7)->Arg(27);
BENCHMARK(BM_AugmentedForwardKinematicsCov2)->Arg(7);
BENCHMARK(BM_AugmentedUncertainForwardKinematicsCov2)->Arg(7);
BENCHMARK(BM_EffectiveChainUpdate)->Arg(7);
BENCHMARK(BM_FrameJacobian)->Arg(7)->Arg(27);

}  // namespace
}  // namespace flexbench::kinematics

BENCHMARK_MAIN();
