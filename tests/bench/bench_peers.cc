// flexbench against the reference implementations a user already has, in one binary and one
// run, on the same models and configurations:
//  - FK (mean) vs MuJoCo's mj_kinematics + reading the end-effector pose: rover_arm (the 8
//    joints of its declared chain: arm and mast) and humanoid_upper (19: both arms, neck, finger).
//  - FrameJacobian vs mj_jacSite (after mj_kinematics + mj_comPos, as MuJoCo needs).
//  - FK with 2nd-order covariance vs a plain Eigen baseline written here: a Matrix4d chain and
//    one 6x6 adjoint sandwich per frame (what one writes from [PPOE eq. 18] without PPOE's
//    kernels).
//  - Batch kinematics for 2048 particles (what a PF step uses) vs one mj_kinematics per
//    particle on jsk_arm; with BM_PfStep in the same run, the step a user without batch
//    kinematics would have.
// The ratios are printed after the table. Run with --benchmark_repetitions=3 (or more); the
// ratios use the medians then (else the single means).
#include <benchmark/benchmark.h>

#include <cstdio>
#include <map>
#include <random>
#include <string>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/pf/batch_kinematics.h"
#include "estimators/pf/particle_filter.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

namespace flexbench {
namespace {

using kinematics::FrameId;

struct Robot {
  explicit Robot(const std::string& declared_name) {
    const std::string dir = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";
    declared = sim::LoadDeclaredModel(dir + declared_name);
    m = sim::LoadModel(declared.model_path);
    d = sim::MakeData(m.get());
    chain = std::make_unique<sim::DeclaredChain>(sim::BuildDeclaredChain(m.get(), declared));
    ee = chain->end_effector;
    std::string name = chain->model.frame(ee).name;
    const size_t slash = name.find('/');
    kind = name.substr(0, slash);
    name = name.substr(slash + 1);
    ee_id = mj_name2id(m.get(), kind == "site" ? mjOBJ_SITE : mjOBJ_BODY, name.c_str());
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(-0.8, 0.8);
    q = Eigen::VectorXd(chain->model.nq());
    for (int k = 0; k < q.size(); ++k) q[k] = u(rng);
    SetQpos();
  }
  void SetQpos() const {
    for (int k = 0; k < q.size(); ++k) {
      d->qpos[chain->q_qposadr[k]] = chain->q_qpos0[k] + q[k];
    }
  }
  sim::DeclaredModel declared;
  sim::MjModelPtr m;
  sim::MjDataPtr d;
  std::unique_ptr<sim::DeclaredChain> chain;
  FrameId ee = -1;
  std::string kind;
  int ee_id = -1;
  Eigen::VectorXd q;
};

const Robot& Rover() {
  static const Robot r("rover_arm.declared.yaml");
  return r;
}
const Robot& Humanoid() {
  static const Robot r("humanoid_upper.declared.yaml");
  return r;
}
const Robot& Jsk() {
  static const Robot r("jsk_arm.declared.yaml");
  return r;
}
const Robot& Pick(int which) { return which == 0 ? Rover() : Humanoid(); }

void BM_FlexbenchFk(benchmark::State& state) {
  const Robot& r = Pick(static_cast<int>(state.range(0)));
  kinematics::PpoeData data(r.chain->model);
  for (auto _ : state) {
    kinematics::ForwardKinematics(r.chain->model, data, r.q);
    benchmark::DoNotOptimize(data.T_base_frame[r.ee]);
  }
}

void BM_MujocoKinematics(benchmark::State& state) {
  const Robot& r = Pick(static_cast<int>(state.range(0)));
  Vec3 p;
  for (auto _ : state) {
    r.SetQpos();
    mj_kinematics(r.m.get(), r.d.get());
    const mjtNum* x = r.kind == "site" ? r.d->site_xpos + 3 * r.ee_id : r.d->xpos + 3 * r.ee_id;
    const mjtNum* R = r.kind == "site" ? r.d->site_xmat + 9 * r.ee_id : r.d->xmat + 9 * r.ee_id;
    p = Vec3(x[0], x[1], x[2]) + Vec3(R[0], R[4], R[8]);
    benchmark::DoNotOptimize(p);
  }
}

void BM_FlexbenchFrameJacobian(benchmark::State& state) {
  const Robot& r = Pick(static_cast<int>(state.range(0)));
  kinematics::PpoeData data(r.chain->model);
  kinematics::ForwardKinematics(r.chain->model, data, r.q);
  kinematics::Matrix6Xd J(6, r.chain->model.nq());
  for (auto _ : state) {
    kinematics::ComputeFrameJacobian(r.chain->model, data, r.ee, J);
    benchmark::DoNotOptimize(J.data());
  }
}

void BM_MujocoJacSite(benchmark::State& state) {
  const Robot& r = Pick(static_cast<int>(state.range(0)));
  r.SetQpos();
  mj_kinematics(r.m.get(), r.d.get());
  mj_comPos(r.m.get(), r.d.get());
  std::vector<mjtNum> jacp(3 * r.m->nv), jacr(3 * r.m->nv);
  for (auto _ : state) {
    if (r.kind == "site") {
      mj_jacSite(r.m.get(), r.d.get(), jacp.data(), jacr.data(), r.ee_id);
    } else {
      mj_jacBody(r.m.get(), r.d.get(), jacp.data(), jacr.data(), r.ee_id);
    }
    benchmark::DoNotOptimize(jacp.data());
  }
}

void BM_FlexbenchFkCov2(benchmark::State& state) {
  const Robot& r = Pick(static_cast<int>(state.range(0)));
  kinematics::PpoeData data(r.chain->model);
  for (auto _ : state) {
    kinematics::ForwardKinematicsWithCovariance(r.chain->model, data, r.q,
                                                lie::CompoundOrder::kSecond);
    benchmark::DoNotOptimize(data.Sigma_frame[r.ee]);
  }
}

// The baseline: per frame, T_parent_i = T_parent_ip * Exp(zeta q) as a Matrix4d (rotation by
// Eigen's AngleAxis), the pose chained by Matrix4d products, and Sigma_i = Ad(T_parent_i^-1)
// (Sigma_parent + Ad(T_parent_ip) Sigma_source Ad(T_parent_ip)^T) Ad(T_parent_i^-1)^T.
using Mat4 = Eigen::Matrix4d;
Mat6 Adjoint(const Mat4& T) {
  Mat6 A = Mat6::Zero();
  const Mat3 R = T.topLeftCorner<3, 3>();
  const Vec3 t = T.topRightCorner<3, 1>();
  Mat3 tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  A.block<3, 3>(kTransIdx, kTransIdx) = R;
  A.block<3, 3>(kRotIdx, kRotIdx) = R;
  A.block<3, 3>(kTransIdx, kRotIdx) = tx * R;
  return A;
}

void BM_EigenBaselineFkCov2(benchmark::State& state) {
  const Robot& r = Pick(static_cast<int>(state.range(0)));
  const kinematics::PpoeModel& model = r.chain->model;
  const int n = model.num_frames();
  std::vector<Mat4> T(n), fixed(n);
  std::vector<Mat6> Sigma(n);
  for (FrameId f = 1; f < n; ++f) {
    fixed[f].setIdentity();
    fixed[f].topLeftCorner<3, 3>() = model.frame(f).T_parent_ip.rotation();
    fixed[f].topRightCorner<3, 1>() = model.frame(f).T_parent_ip.translation();
  }
  for (auto _ : state) {
    T[0].setIdentity();
    Sigma[0].setZero();
    for (FrameId f = 1; f < n; ++f) {
      const kinematics::PpoeFrame& fr = model.frame(f);
      Mat4 motion = Mat4::Identity();
      if (fr.joint.type == kinematics::JointType::kRevolute) {
        const Mat3 R = Eigen::AngleAxisd(r.q[fr.q_index], fr.joint.axis).toRotationMatrix();
        motion.topLeftCorner<3, 3>() = R;
        motion.topRightCorner<3, 1>() = fr.joint.point - R * fr.joint.point;
      } else if (fr.joint.type == kinematics::JointType::kPrismatic) {
        motion.topRightCorner<3, 1>() = r.q[fr.q_index] * fr.joint.axis;
      }
      const Mat4 rel = fixed[f] * motion;
      T[f] = T[fr.parent] * rel;
      const Mat6 A = Adjoint(fixed[f]);
      const Mat6 B = Adjoint(rel.inverse());
      Sigma[f] = B * (Sigma[fr.parent] + A * fr.source_cov * A.transpose()) * B.transpose();
    }
    benchmark::DoNotOptimize(Sigma[r.ee]);
  }
}

constexpr int kParticles = 2048;

void BM_BatchKinematics(benchmark::State& state) {
  const Robot& r = Jsk();
  const int nq = r.chain->model.nq();
  pf::BatchKinematics fk(r.chain->model, {r.ee}, kParticles);
  std::vector<double> c(nq * kParticles), s(nq * kParticles);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (size_t i = 0; i < c.size(); ++i) {
    const double a = u(rng);
    c[i] = std::cos(a);
    s[i] = std::sin(a);
  }
  for (auto _ : state) {
    fk.Compute(c.data(), s.data(), kParticles, kParticles);
    benchmark::DoNotOptimize(fk.t(0, 0));
  }
}

void BM_MujocoKinematicsPerParticle(benchmark::State& state) {
  const Robot& r = Jsk();
  const int nq = r.chain->model.nq();
  std::vector<double> angles(nq * kParticles);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (double& a : angles) a = u(rng);
  for (auto _ : state) {
    for (int i = 0; i < kParticles; ++i) {
      for (int k = 0; k < nq; ++k) {
        r.d->qpos[r.chain->q_qposadr[k]] = r.chain->q_qpos0[k] + angles[k * kParticles + i];
      }
      mj_kinematics(r.m.get(), r.d.get());
    }
    benchmark::DoNotOptimize(r.d->xpos[3]);
  }
}

void BM_PfStep(benchmark::State& state) {
  const Robot& r = Jsk();
  pf::ParticleFilterConfig c;
  c.num_particles = kParticles;
  c.position_frames = {r.ee};
  c.end_effector = r.ee;
  pf::ParticleFilter f(r.chain->model, c, 1);
  kinematics::PpoeData data(r.chain->model);
  kinematics::ForwardKinematics(r.chain->model, data, r.q);
  const Vec3 p = data.T_base_frame[r.ee].translation();
  for (auto _ : state) {
    f.Predict();
    f.UpdateReference(r.q.data(), static_cast<int>(r.q.size()));
    f.UpdatePosition(r.ee, Vec3::Zero(), p);
    benchmark::ClobberMemory();
  }
}

BENCHMARK(BM_FlexbenchFk)->Arg(0)->Arg(1);
BENCHMARK(BM_MujocoKinematics)->Arg(0)->Arg(1);
BENCHMARK(BM_FlexbenchFrameJacobian)->Arg(0)->Arg(1);
BENCHMARK(BM_MujocoJacSite)->Arg(0)->Arg(1);
BENCHMARK(BM_FlexbenchFkCov2)->Arg(0)->Arg(1);
BENCHMARK(BM_EigenBaselineFkCov2)->Arg(0)->Arg(1);
BENCHMARK(BM_BatchKinematics)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MujocoKinematicsPerParticle)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PfStep)->Unit(benchmark::kMicrosecond);

// Keeps each benchmark's median (or its only run) for the ratios.
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& run : runs) {
      const std::string name = run.run_name.str();
      if (run.run_type == Run::RT_Aggregate && run.aggregate_name != "median") continue;
      if (run.run_type == Run::RT_Iteration && seen_median_.count(name)) continue;
      if (run.run_type == Run::RT_Aggregate) seen_median_[name] = true;
      ns_[name] = run.GetAdjustedRealTime() * (run.time_unit == benchmark::kMicrosecond   ? 1e3
                                               : run.time_unit == benchmark::kMillisecond ? 1e6
                                                                                          : 1.0);
    }
  }
  void PrintRatios() const {
    std::printf(
        "\nRatios (flexbench / reference; < 1: flexbench faster). %s clone of the FK "
        "kernels.\n",
        __builtin_cpu_supports("avx2") ? "AVX2" : "baseline (no AVX2)");
    const char* robots[2] = {"rover_arm", "humanoid_upper"};
    for (int k = 0; k < 2; ++k) {
      const std::string a = "/" + std::to_string(k);
      Ratio(std::string("FK mean vs mj_kinematics, ") + robots[k], "BM_FlexbenchFk" + a,
            "BM_MujocoKinematics" + a);
      Ratio(std::string("FrameJacobian vs mj_jacSite, ") + robots[k],
            "BM_FlexbenchFrameJacobian" + a, "BM_MujocoJacSite" + a);
      Ratio(std::string("FK 2nd-order covariance vs Eigen baseline, ") + robots[k],
            "BM_FlexbenchFkCov2" + a, "BM_EigenBaselineFkCov2" + a);
    }
    Ratio("batch kinematics vs mj_kinematics per particle (2048, jsk_arm)", "BM_BatchKinematics",
          "BM_MujocoKinematicsPerParticle");
    const auto get = [&](const std::string& n) {
      const auto it = ns_.find(n);
      return it == ns_.end() ? -1.0 : it->second;
    };
    const double step = get("BM_PfStep"), batch = get("BM_BatchKinematics"),
                 naive = get("BM_MujocoKinematicsPerParticle");
    if (step > 0 && batch > 0 && naive > 0) {
      std::printf("  %-66s %8.3f  (%.0f us vs %.0f us)\n",
                  "PF step vs the same step with mj_kinematics per particle",
                  step / (step - batch + naive), step / 1e3, (step - batch + naive) / 1e3);
    }
  }

 private:
  void Ratio(const std::string& what, const std::string& a, const std::string& b) const {
    const auto ia = ns_.find(a), ib = ns_.find(b);
    if (ia == ns_.end() || ib == ns_.end()) return;
    std::printf("  %-66s %8.3f  (%.0f ns vs %.0f ns)\n", what.c_str(), ia->second / ib->second,
                ia->second, ib->second);
  }
  std::map<std::string, double> ns_;
  std::map<std::string, bool> seen_median_;
};

}  // namespace
}  // namespace flexbench

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  flexbench::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  reporter.PrintRatios();
  benchmark::Shutdown();
  return 0;
}
