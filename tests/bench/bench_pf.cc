// One full step of the von Mises / Bingham particle filter (PF paper sec. III) on the 4-DoF
// jsk_arm's declared model: predict [PF eq. 30], batch kinematics of the IMU and grasp frames,
// the likelihood of [PF eq. 23] (reference angles, two Bingham IMU terms, the grasp position) and
// ESS-triggered stratified resampling (which fires every step with these sensors). Target (one
// core): N = 2048 in at most 200 us, no heap allocation per step (tests/unit/pf_alloc/).
// Also: the scaling for N = 256 ... 8192, the encoder-conjugate and Laplace proposals, and the
// batch kinematics alone.
// Run with --benchmark_repetitions=5 --benchmark_report_aggregates_only=true.
//
// Target for the estimate (BM_Summary): at most 0.25x of a step (BM_PfStep) in the same run; the
// measured figures are in docs/performance.md.
// Where BM_Summary/2048 goes (perf): about half the particles are negligible (w < 1e-14) after
// a reading, and the summary now skips them (KeptParticles): the end-effector logs about a
// quarter, the four joints' band passes, gathers and band sorts about half, the weights and
// resultants (over all particles) about a tenth.
#include <benchmark/benchmark.h>

#include <memory>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/pf/particle_filter.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

namespace flexbench::pf {
namespace {

struct Arm {
  Arm() {
    const std::string dir = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";
    declared = sim::LoadDeclaredModel(dir + "jsk_arm.declared.yaml");
    mj = sim::LoadModel(declared.model_path);
    chain = std::make_unique<sim::DeclaredChain>(sim::BuildDeclaredChain(mj.get(), declared));
    imu2 = chain->ObservedFrame("imu_link2");
    imu3 = chain->ObservedFrame("imu_link3");
    grasp = chain->end_effector;
    q = Eigen::VectorXd(4);
    q << 0.3, 0.9, 0.5, 0.1;
    kinematics::PpoeData data(chain->model);
    kinematics::ForwardKinematics(chain->model, data, q);
    q2 = Quat(data.T_base_frame[imu2].rotation());
    q3 = Quat(data.T_base_frame[imu3].rotation());
    p = data.T_base_frame[grasp].translation();
  }
  sim::DeclaredModel declared;
  sim::MjModelPtr mj;
  std::unique_ptr<sim::DeclaredChain> chain;
  FrameId imu2, imu3, grasp;
  Eigen::VectorXd q;
  Quat q2, q3;
  Vec3 p;
};

const Arm& TheArm() {
  static const Arm arm;
  return arm;
}

void FilterStep(benchmark::State& state, Proposal proposal, bool with_estimate = false) {
  const Arm& arm = TheArm();
  ParticleFilterConfig c;  // Table I
  c.num_particles = static_cast<int>(state.range(0));
  c.position_frames = {arm.grasp};
  c.orientation_frames = {arm.imu2, arm.imu3};
  c.end_effector = arm.grasp;
  c.proposal = proposal;
  ParticleFilter pf(arm.chain->model, c, 1);
  for (int k = 0; k < 5; ++k) {  // converge first: the steady state is what runs online
    pf.Predict();
    pf.UpdateReference(arm.q.data(), 4);
    pf.UpdateOrientation(arm.imu2, arm.q2);
    pf.UpdateOrientation(arm.imu3, arm.q3);
    pf.UpdatePosition(arm.grasp, Vec3::Zero(), arm.p);
    pf.CompleteStep();
  }
  for (auto _ : state) {
    pf.Predict();
    pf.UpdateReference(arm.q.data(), 4);
    pf.UpdateOrientation(arm.imu2, arm.q2);
    pf.UpdateOrientation(arm.imu3, arm.q3);
    pf.UpdatePosition(arm.grasp, Vec3::Zero(), arm.p);
    pf.CompleteStep();  // the kLaplace move (a no-op for the other proposals)
    if (with_estimate) benchmark::DoNotOptimize(pf.Summary().mean[0]);
    benchmark::ClobberMemory();
  }
  state.counters["resampled"] = pf.last_step_resampled() ? 1 : 0;
  state.SetItemsProcessed(state.iterations() * state.range(0));
}

void BM_PfStep(benchmark::State& state) { FilterStep(state, Proposal::kBootstrap); }
// A step and the estimate a user reads after it (circular means, 95% intervals, end-effector
// pose and covariance): what a filter that reports every step costs.
void BM_PfStepWithEstimate(benchmark::State& state) {
  FilterStep(state, Proposal::kBootstrap, true);
}
void BM_PfStepConjugate(benchmark::State& state) { FilterStep(state, Proposal::kEncoderConjugate); }
// The proposal that folds every reading into the move; compare /256 with BM_PfStepConjugate/2048
// (equal accuracy on the Fig. 6 setting, docs/particle_filter.md).
void BM_PfStepLaplace(benchmark::State& state) { FilterStep(state, Proposal::kLaplace); }

void BM_BatchKinematics(benchmark::State& state) {
  const Arm& arm = TheArm();
  const int n = static_cast<int>(state.range(0));
  BatchKinematics fk(arm.chain->model, {arm.imu2, arm.imu3, arm.grasp}, n);
  std::vector<double> c(4 * n), s(4 * n);
  for (int i = 0; i < 4 * n; ++i) {
    c[i] = std::cos(0.001 * i);
    s[i] = std::sin(0.001 * i);
  }
  for (auto _ : state) {
    fk.Compute(c.data(), s.data(), n, n);
    benchmark::DoNotOptimize(fk.t(2, 0));
  }
  state.SetItemsProcessed(state.iterations() * n);
}

// The estimate alone (circular means, 95% intervals, end-effector pose and covariance) after a
// predict and two updates; see the figures at the top.
void BM_Summary(benchmark::State& state) {
  const Arm& arm = TheArm();
  ParticleFilterConfig c;
  c.num_particles = static_cast<int>(state.range(0));
  c.position_frames = {arm.grasp};
  c.orientation_frames = {arm.imu2, arm.imu3};
  c.end_effector = arm.grasp;
  ParticleFilter pf(arm.chain->model, c, 1);
  for (auto _ : state) {
    state.PauseTiming();
    pf.Predict();  // invalidates the cached summary
    pf.UpdateReference(arm.q.data(), 4);
    pf.UpdateOrientation(arm.imu2, arm.q2);
    state.ResumeTiming();
    benchmark::DoNotOptimize(pf.Summary().mean[0]);
  }
}

BENCHMARK(BM_PfStep)->RangeMultiplier(2)->Range(256, 8192)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PfStepWithEstimate)
    ->RangeMultiplier(2)
    ->Range(256, 8192)
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PfStepConjugate)->RangeMultiplier(2)->Range(256, 8192)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PfStepLaplace)->RangeMultiplier(2)->Range(256, 2048)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_BatchKinematics)->Arg(2048)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Summary)->Arg(2048)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace flexbench::pf

BENCHMARK_MAIN();
