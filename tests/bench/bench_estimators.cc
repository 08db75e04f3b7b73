// Speed of the Lie-group EKF (PPOE paper sec. V-A): one update with the tag-centre pixel model
// [PPOE eq. 25] with analytic and with numeric Jacobians, and the PPOE prior (FK with covariance)
// of rover_arm's declared model. Run with --benchmark_repetitions=5 and quote medians.
#include <benchmark/benchmark.h>

#include "estimators/ekf/lg_ekf.h"
#include "estimators/ekf/measurement_model.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "sim/declared_chain.h"
#include "sim/mujoco_model.h"

namespace flexbench::estimators {
namespace {

PinholeCamera Camera() {
  PinholeCamera c;
  c.fx = c.fy = 625.0;
  c.cx = 320.0;
  c.cy = 240.0;
  c.width = 640;
  c.height = 480;
  return c;
}

void BM_EkfUpdateTagCentre(benchmark::State& state) {
  Mat3 R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // camera looking along +x of the base
  const lie::SE3 T_base_cam(R, Vec3(0.0, 0.0, 1.3));
  const lie::SE3 X0(lie::SO3Exp(Vec3(0.1, 0.2, 0.0)), Vec3(1.2, 0.1, 0.7));
  const Vec3 p_ee(0.0, 0.05, 0.06);
  Eigen::Vector2d uv;
  Camera().Project(T_base_cam.Inverse() * (X0 * p_ee), &uv);
  const PixelPointModel model(Camera(), T_base_cam, p_ee, uv + Eigen::Vector2d(1.5, -2.0),
                              Eigen::Matrix2d::Identity() * 0.25);
  Mat6 P0 = Mat6::Identity() * 1e-4;
  P0.bottomRightCorner<3, 3>() *= 0.1;
  LgEkfOptions options;
  options.numeric_jacobians = state.range(0) != 0;
  options.max_iterations = 1;  // one update = one linearisation, [PPOE eqs. 20-23]
  for (auto _ : state) {
    lie::SE3 X = X0;
    Mat6 P = P0;
    benchmark::DoNotOptimize(LgEkfUpdate(model, options, &X, &P));
    benchmark::DoNotOptimize(P);
  }
}
BENCHMARK(BM_EkfUpdateTagCentre)->Arg(0)->Arg(1)->ArgNames({"numeric"});

void BM_EkfUpdateTagCentreIterated(benchmark::State& state) {
  Mat3 R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const lie::SE3 T_base_cam(R, Vec3(0.0, 0.0, 1.3));
  const lie::SE3 X0(lie::SO3Exp(Vec3(0.1, 0.2, 0.0)), Vec3(1.2, 0.1, 0.7));
  const Vec3 p_ee(0.0, 0.05, 0.06);
  Eigen::Vector2d uv;
  Camera().Project(T_base_cam.Inverse() * (X0 * p_ee), &uv);
  const PixelPointModel model(Camera(), T_base_cam, p_ee, uv + Eigen::Vector2d(1.5, -2.0),
                              Eigen::Matrix2d::Identity() * 0.25);
  const Mat6 P0 = Mat6::Identity() * 1e-4;
  for (auto _ : state) {
    lie::SE3 X = X0;
    Mat6 P = P0;
    benchmark::DoNotOptimize(LgEkfUpdate(model, LgEkfOptions{}, &X, &P));
  }
}
BENCHMARK(BM_EkfUpdateTagCentreIterated);

void BM_PpoePriorRover(benchmark::State& state) {
  const sim::DeclaredModel declared =
      sim::LoadDeclaredModel(std::string(FLEXBENCH_SOURCE_DIR) + "/models/rover_arm.declared.yaml");
  sim::MjModelPtr m = sim::LoadModel(declared.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), declared);
  kinematics::PpoeData data(chain.model);
  Eigen::VectorXd q = Eigen::VectorXd::Constant(chain.model.nq(), 0.3);
  const auto order =
      state.range(0) == 4 ? lie::CompoundOrder::kFourth : lie::CompoundOrder::kSecond;
  for (auto _ : state) {
    kinematics::ForwardKinematicsWithCovariance(chain.model, data, q, order);
    benchmark::DoNotOptimize(data.Sigma_frame[chain.end_effector]);
  }
  state.counters["frames"] = chain.model.num_frames();
}
BENCHMARK(BM_PpoePriorRover)->Arg(2)->Arg(4)->ArgNames({"order"});

}  // namespace
}  // namespace flexbench::estimators

BENCHMARK_MAIN();
