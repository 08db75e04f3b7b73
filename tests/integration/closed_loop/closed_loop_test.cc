// Closing the loop: the augmented kinematics against MuJoCo, identification of known
// effects from synthetic data, unidentifiable and indistinguishable candidates, bad CSV input,
// and the MUKCa real-data scenario (skipped when ../shared/data/mukca is absent).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/cross_validation.h"
#include "scenarios/identify/equivalence.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/problem.h"
#include "scenarios/runner/runner.h"
#include "sim/declared_chain.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/test_arms.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

namespace fs = std::filesystem;

const std::string kArm3 = testing::Arm3Mjcf();

// j2 and j3 turn about one axis line: their offsets cannot be told apart by any data.
constexpr char kTwinJoints[] = R"(
<mujoco model="twin">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1"/>
      <geom type="cylinder" size="0.05 0.05" mass="2"/>
      <body name="upper" pos="0 0 0.1">
        <joint name="j2" axis="0 1 0"/>
        <geom type="sphere" size="0.03" mass="1"/>
        <body name="fore" pos="0 0 0">
          <joint name="j3" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0.6 0 0" size="0.025" mass="2"/>
          <site name="ee" pos="0.6 0 0.02"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>)";

struct Fixture {
  sim::MjModelPtr m;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
};

Fixture Make(const std::string& xml, const std::vector<std::string>& joints) {
  Fixture f;
  f.m = sim::LoadModelFromString(xml, "inline.xml");
  sim::DeclaredModel d;
  d.file = "inline.declared";
  d.actuated_joints = joints;
  d.end_effector = "ee";
  f.chain = sim::BuildDeclaredChain(f.m.get(), d);
  f.em = std::make_unique<EffectModel>(f.m.get(), f.chain, f.chain.end_effector);
  return f;
}

int Candidate(const EffectModel& em, const std::string& name) {
  const int c = em.FindCandidate(name);
  EXPECT_GE(c, 0) << name;
  return c;
}

// Measured points of the truth (the model with `active` at `theta`) plus Gaussian noise.
DataSet PointData(const EffectModel& em, const std::vector<int>& active,
                  const Eigen::VectorXd& theta, int rows, double noise, std::mt19937_64& rng) {
  DataSet d;
  d.sets = {"s"};
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::normal_distribution<double> n(0.0, noise);
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (int r = 0; r < rows; ++r) {
    Observation o;
    o.q = Eigen::VectorXd(em.chain().nq());
    for (int k = 0; k < o.q.size(); ++k) o.q[k] = u(rng);
    const ConfigLoads L = em.Loads(o.q);
    o.p_base = em.Predict(o.q, L, active, theta.data(), ws) + Vec3(n(rng), n(rng), n(rng));
    d.rows.push_back(o);
  }
  return d;
}

std::vector<int> AllCandidates(const EffectModel& em, const std::string& type = "") {
  std::vector<int> c;
  for (size_t i = 0; i < em.candidates().size(); ++i) {
    if (type.empty() || type == ToString(em.candidates()[i].type)) c.push_back(i);
  }
  return c;
}

TEST(EffectModel, WithoutEffectsItIsMujocosKinematics) {
  auto sim = sim::Simulation::Load(testing::SourceDir() + "/models/rover_arm.xml");
  sim::DeclaredModel d =
      sim::LoadDeclaredModel(testing::SourceDir() + "/models/rover_arm.declared.yaml");
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(sim->nominal_model(), d);
  const EffectModel em(sim->nominal_model(), chain, chain.end_effector);
  EffectModel::Workspace ws = em.MakeWorkspace();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int j3 = Candidate(em, "joint_offset@j3");
  for (int trial = 0; trial < 10; ++trial) {
    Eigen::VectorXd cmd = Eigen::VectorXd::Zero(sim->num_actuated());
    for (int k = 0; k < cmd.size(); ++k) cmd[k] = u(rng);
    Eigen::VectorXd q(chain.model.nq());
    for (int k = 0; k < q.size(); ++k) {
      const auto& names = sim->actuated_joints();
      q[k] = cmd[std::find(names.begin(), names.end(), chain.q_joints[k]) - names.begin()];
    }
    const ConfigLoads L = em.Loads(q);
    const Vec3 p = em.Predict(q, L, {}, nullptr, ws);
    EXPECT_LT((p - sim->NominalPose("ee", cmd).translation()).norm(), 1e-9);
    // A joint offset is the joint turned further: MuJoCo at q + a.
    const double a = 0.02;
    Eigen::VectorXd cmd_a = cmd;
    const auto& names = sim->actuated_joints();
    cmd_a[std::find(names.begin(), names.end(), "j3") - names.begin()] += a;
    const Vec3 pa = em.Predict(q, L, {j3}, &a, ws);
    EXPECT_LT((pa - sim->NominalPose("ee", cmd_a).translation()).norm(), 1e-9);
    // Loads: the gravity torque each joint holds is MuJoCo's qfrc_bias at rest.
    const Eigen::VectorXd g = sim->GravityTorque(cmd);
    // The arm's joints (the mast is not on the way to the end effector and carries no load here).
    for (int k = 0; k < 6; ++k) {
      ASSERT_EQ(chain.q_joints[k], "j" + std::to_string(k + 1));
      const double tau_mj =
          g[std::find(names.begin(), names.end(), chain.q_joints[k]) - names.begin()];
      EXPECT_NEAR(L.tau[k], tau_mj, 1e-9 * (1.0 + std::abs(tau_mj))) << chain.q_joints[k];
    }
  }
}

// The loads cache the effect-free chain poses at their q;
// a prediction with the cache is bit-identical to one without, for every candidate alone and in
// pairs, and a prediction at another q (the diagnostics' perturbed readings) ignores the cache.
TEST(EffectModel, CachedNominalPosesGiveTheSameBits) {
  const sim::MjModelPtr m = sim::LoadModel(testing::SourceDir() + "/models/rover_arm.xml");
  const sim::DeclaredModel d =
      sim::LoadDeclaredModel(testing::SourceDir() + "/models/rover_arm.declared.yaml");
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d);
  const EffectModel em(m.get(), chain, chain.end_effector);
  EffectModel::Workspace ws = em.MakeWorkspace();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.2, 1.2), t(-1e-2, 1e-2);
  const int nc = static_cast<int>(em.candidates().size());
  ASSERT_GT(nc, 10);
  const auto same = [](const lie::SE3& a, const lie::SE3& b) {
    return std::memcmp(a.rotation().data(), b.rotation().data(), 9 * sizeof(double)) == 0 &&
           std::memcmp(a.translation().data(), b.translation().data(), 3 * sizeof(double)) == 0;
  };
  for (int trial = 0; trial < 4; ++trial) {
    Eigen::VectorXd q(chain.model.nq());
    for (int k = 0; k < q.size(); ++k) q[k] = u(rng);
    const ConfigLoads L = em.Loads(q);
    ASSERT_FALSE(L.T_nominal.empty());
    ConfigLoads L_plain = L;
    L_plain.T_nominal.clear();
    std::vector<double> theta(64);
    for (double& v : theta) v = t(rng);
    EXPECT_TRUE(
        same(em.PredictPose(q, L, {}, nullptr, ws), em.PredictPose(q, L_plain, {}, nullptr, ws)));
    for (int a = 0; a < nc; ++a) {
      if (em.candidates()[a].type == EffectType::kCameraOffset) continue;
      const int b = (a * 7 + trial) % nc;
      for (const std::vector<int>& act : {std::vector<int>{a}, std::vector<int>{b, a}}) {
        if (em.candidates()[b].type == EffectType::kCameraOffset || (act.size() == 2 && a == b)) {
          continue;
        }
        EXPECT_TRUE(same(em.PredictPose(q, L, act, theta.data(), ws),
                         em.PredictPose(q, L_plain, act, theta.data(), ws)))
            << ToString(em.candidates()[a].type) << "@" << em.candidates()[a].location;
      }
    }
    // Another reading with this row's loads: the cache is not used.
    Eigen::VectorXd q2 = q;
    q2[0] += 0.1;
    const int j2 = em.FindCandidate("joint_compliance@j2");
    ASSERT_GE(j2, 0);
    EXPECT_TRUE(
        same(em.PredictPose(q2, L, {}, nullptr, ws), em.PredictPose(q2, L_plain, {}, nullptr, ws)));
    EXPECT_TRUE(same(em.PredictPose(q2, L, {j2}, theta.data(), ws),
                     em.PredictPose(q2, L_plain, {j2}, theta.data(), ws)));
    EXPECT_FALSE(
        same(em.PredictPose(q2, L, {}, nullptr, ws), em.PredictPose(q, L, {}, nullptr, ws)));
  }
}

// The row passes run on several threads, each row in its
// own slots, so the whole identification (selection, cross-validation, alternatives, reports)
// gives the same bits on 1, 2 or 3 threads. 1,600 point rows in 4 sets: 3 threads' worth at
// the chunk floor, folds of 1,200 training rows (2 threads); three effect types as candidates
// (a few seconds a run).
TEST(Identify, ThreadsGiveTheSameBits) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_offset@j2"),
                                  Candidate(*f.em, "joint_compliance@j3")};
  Eigen::VectorXd theta(2);
  theta << 0.01, -2e-3;
  std::mt19937_64 rng(12);
  DataSet d = PointData(*f.em, truth, theta, 1600, 1e-4, rng);
  d.sets = {"a", "b", "c", "d"};
  for (size_t r = 0; r < d.rows.size(); ++r) d.rows[r].set = static_cast<int>(r % 4);
  const auto loads = ComputeLoads(*f.em, d);
  const auto bits = [](double v) {
    uint64_t b;
    std::memcpy(&b, &v, sizeof(b));
    return b;
  };
  std::vector<int> candidates = AllCandidates(*f.em, "joint_offset");
  for (const char* type : {"joint_compliance", "link_length"}) {
    for (int c : AllCandidates(*f.em, type)) candidates.push_back(c);
  }
  std::vector<IdentifyResult> runs;
  for (int threads : {1, 2, 3}) {
    IdentifyOptions opt;
    opt.threads = threads;
    runs.push_back(Identify(*f.em, d, loads, candidates, opt));
  }
  ASSERT_EQ(runs[0].effects.size(), 2u);
  for (size_t k = 1; k < runs.size(); ++k) {
    EXPECT_EQ(runs[k].steps, runs[0].steps);
    EXPECT_EQ(bits(runs[k].cv_before), bits(runs[0].cv_before));
    EXPECT_EQ(bits(runs[k].cv_after), bits(runs[0].cv_after));
    EXPECT_EQ(bits(runs[k].after.rss), bits(runs[0].after.rss));
    ASSERT_EQ(runs[k].effects.size(), runs[0].effects.size());
    for (size_t e = 0; e < runs[0].effects.size(); ++e) {
      EXPECT_EQ(runs[k].effects[e].name, runs[0].effects[e].name);
      EXPECT_EQ(bits(runs[k].effects[e].value[0]), bits(runs[0].effects[e].value[0]));
      EXPECT_EQ(bits(runs[k].effects[e].std[0]), bits(runs[0].effects[e].std[0]));
    }
  }
}

// Screening scores a candidate by one Gauss-Newton step from the current fit with
// the columns at hand, instead of a Levenberg-Marquardt fit from zero. For every candidate the
// step reaches the full fit's sum of squares (that of FitWith run to convergence) to within
// 1e-4 of it (on the data of the true effect, whose RSS falls 100-fold, and on the others), and
// is never below it by more than rounding.
TEST(Identify, ScreeningStepReachesTheFullFit) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_compliance@j3")};
  Eigen::VectorXd theta(1);
  theta << -2e-3;
  std::mt19937_64 rng(13);
  const DataSet d = PointData(*f.em, truth, theta, 300, 1e-4, rng);
  const auto loads = ComputeLoads(*f.em, d);
  const IdentifyOptions opt;
  const Fit cur = FitEffects(*f.em, d, loads, {}, Eigen::VectorXd(), opt);
  const Eigen::MatrixXd J_cur = FitJacobian(*f.em, d, loads, cur, opt);
  const Eigen::VectorXd r_cur = FitResiduals(*f.em, d, loads, cur, opt);
  EXPECT_NEAR(r_cur.squaredNorm(), cur.rss, 1e-9 * cur.rss);
  int screened = 0;
  for (int c : AllCandidates(*f.em)) {
    const Eigen::MatrixXd Jc = CandidateJacobian(*f.em, d, loads, cur, c, opt);
    const Projector proj(J_cur);
    double rel = 0.0;
    const Eigen::MatrixXd B = ObservableBasis(Jc, proj, opt.rank_tol, &rel);
    if (B.cols() == 0) continue;
    const Fit step = ScreenWith(*f.em, d, loads, cur, c, B, J_cur, Jc, r_cur, opt);
    const Fit full = FitWith(*f.em, d, loads, cur, c, B, opt);
    const std::string name = f.em->candidates()[c].Name();
    EXPECT_LE(step.rss, full.rss * (1.0 + 1e-4)) << name;
    EXPECT_GE(step.rss, full.rss * (1.0 - 1e-9)) << name;
    EXPECT_EQ(step.active, full.active) << name;
    if (c == truth[0]) {
      EXPECT_LT(step.rss, 0.01 * cur.rss);
    }
    ++screened;
  }
  EXPECT_GT(screened, 5);
}

TEST(Identify, FindsAnOffsetAndAGearComplianceFromPoints) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_offset@j2"),
                                  Candidate(*f.em, "joint_compliance@j3")};
  Eigen::VectorXd theta(2);
  theta << 0.01, -2e-3;  // a gear of stiffness 500 N m/rad (c = -1/k)
  std::mt19937_64 rng(11);
  const DataSet d = PointData(*f.em, truth, theta, 80, 1e-4, rng);
  const auto loads = ComputeLoads(*f.em, d);
  // The selection log reaches on_step as it is written, every line once, in order; the first
  // line arrives before the first effect is added.
  IdentifyOptions opt;
  std::vector<std::string> streamed;
  size_t before_first_add = 0;
  opt.on_step = [&](const std::string& line) {
    if (line.rfind("add ", 0) == 0 && before_first_add == 0) before_first_add = streamed.size();
    streamed.push_back(line);
  };
  const IdentifyResult r = Identify(*f.em, d, loads, AllCandidates(*f.em), opt);
  EXPECT_EQ(streamed, r.steps);
  EXPECT_GT(before_first_add, 0u);
  std::vector<std::string> found;
  for (const auto& e : r.effects) found.push_back(e.name);
  std::sort(found.begin(), found.end());
  EXPECT_EQ(found, (std::vector<std::string>{"joint_compliance@j3", "joint_offset@j2"}));
  for (const auto& e : r.effects) {
    const double want = e.name == "joint_offset@j2" ? theta[0] : theta[1];
    EXPECT_NEAR(e.value[0], want, 4.0 * e.std[0]) << e.name;
    EXPECT_LT(e.std[0], 0.05 * std::abs(want)) << e.name;
  }
  // The fit leaves the noise: RSS of whitened residuals ~ its degrees of freedom.
  EXPECT_LT(r.after.rss, 1.5 * r.after.num_residuals);
  EXPECT_GT(r.before.rss, 100.0 * r.after.rss);
}

// Backlash with the direction of the last motion recorded per row: the flank follows the motion,
// not the load (here random), and identification uses it.
TEST(Identify, BacklashFollowsTheRecordedMotion) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "backlash@j3")};
  const double half_play = 0.004;
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::normal_distribution<double> n(0.0, 1e-4);
  DataSet d;
  d.sets = {"s"};
  EffectModel::Workspace ws = f.em->MakeWorkspace();
  for (int r = 0; r < 60; ++r) {
    Observation o;
    o.q = Eigen::Vector3d(u(rng), u(rng), u(rng));
    o.motion_sign = Eigen::Vector3d(0, 0, u(rng) > 0 ? 1 : -1);
    ConfigLoads L = f.em->Loads(o.q);
    L.motion_sign = o.motion_sign;
    o.p_base = f.em->Predict(o.q, L, truth, &half_play, ws) + Vec3(n(rng), n(rng), n(rng));
    d.rows.push_back(o);
  }
  const auto loads = ComputeLoads(*f.em, d);
  const IdentifyResult r = Identify(*f.em, d, loads, AllCandidates(*f.em), IdentifyOptions{});
  ASSERT_EQ(r.effects.size(), 1u);
  EXPECT_EQ(r.effects[0].name, "backlash@j3");
  EXPECT_NEAR(r.effects[0].value[0], half_play, 4.0 * r.effects[0].std[0]);
  // Without the recorded motion the load picks the flank, and the data no longer fits.
  DataSet blind = d;
  for (Observation& o : blind.rows) o.motion_sign.resize(0);
  const auto blind_loads = ComputeLoads(*f.em, blind);
  const Fit fit =
      FitEffects(*f.em, blind, blind_loads, truth, Eigen::VectorXd(), IdentifyOptions{});
  EXPECT_GT(fit.rss, 10.0 * r.after.rss);
}

// Rows of `group` socket points reached by the truth from several starting postures.
DataSet SocketData(const EffectModel& em, const std::vector<int>& active,
                   const Eigen::VectorXd& theta, int sockets, std::mt19937_64& rng) {
  DataSet d;
  d.sets = {"s"};
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  EffectModel::Workspace ws = em.MakeWorkspace();
  const int nq = em.chain().nq();
  for (int s = 0; s < sockets; ++s) {
    const Vec3 target(0.45 + 0.1 * u(rng), 0.3 * u(rng), 0.25 + 0.1 * u(rng));
    const int g = LabelIndex(&d.groups, "socket" + std::to_string(s));
    for (int start = 0; start < 4; ++start) {
      // Both elbows, facing the socket and reaching over the top: all postures of a 3-DoF arm.
      Eigen::VectorXd q(nq);
      q[0] = std::atan2(target.y(), target.x()) + (start / 2 ? M_PI : 0.0) + 0.1 * u(rng);
      q[1] = (start / 2 ? 1.0 : -1.0) * (-0.5 + 0.1 * u(rng));
      q[2] = (start % 2 ? 1.0 : -1.0) * (1.2 + 0.1 * u(rng));
      for (int it = 0; it < 60; ++it) {
        const Vec3 p = em.Predict(q, em.Loads(q), active, theta.data(), ws);
        if ((target - p).norm() < 1e-12) break;
        Eigen::Matrix3Xd J(3, nq);
        for (int k = 0; k < nq; ++k) {
          Eigen::VectorXd qk = q;
          qk[k] += 1e-7;
          J.col(k) = (em.Predict(qk, em.Loads(qk), active, theta.data(), ws) - p) / 1e-7;
        }
        q += J.transpose() * (J * J.transpose() + 1e-9 * Mat3::Identity()).ldlt().solve(target - p);
      }
      Observation o;
      o.q = q + 1e-5 * Eigen::VectorXd::NullaryExpr(nq, [&] { return noise(rng); });  // encoders
      o.type = ObservationType::kGroup;
      o.group = g;
      d.rows.push_back(o);
    }
  }
  return d;
}

TEST(Identify, AnOffsetTheSocketsAbsorbIsUnidentifiableAndNeverFitted) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_offset@j2")};
  const Eigen::VectorXd theta = Eigen::VectorXd::Constant(1, 0.02);
  std::mt19937_64 rng(12);
  const DataSet d = SocketData(*f.em, truth, theta, 8, rng);
  const auto loads = ComputeLoads(*f.em, d);
  const IdentifyResult r =
      Identify(*f.em, d, loads, AllCandidates(*f.em, "joint_offset"), IdentifyOptions{});
  std::string log;
  for (const auto& s : r.steps) log += s + "\n";
  ASSERT_EQ(r.effects.size(), 1u) << log;
  EXPECT_EQ(r.effects[0].name, "joint_offset@j2");
  EXPECT_NEAR(r.effects[0].value[0], 0.02, 4.0 * r.effects[0].std[0]);
  // Turning the base about the vertical moves every socket alike: the free socket points absorb it.
  EXPECT_NE(std::find(r.unidentifiable.begin(), r.unidentifiable.end(), "joint_offset@j1"),
            r.unidentifiable.end());
}

TEST(Identify, TwoCandidatesTheDataCannotTellApartAreBothNamedNeverOne) {
  const Fixture f = Make(kTwinJoints, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_offset@j3")};
  const Eigen::VectorXd theta = Eigen::VectorXd::Constant(1, 0.01);
  std::mt19937_64 rng(13);
  const DataSet d = PointData(*f.em, truth, theta, 40, 1e-4, rng);
  const auto loads = ComputeLoads(*f.em, d);
  const IdentifyResult r =
      Identify(*f.em, d, loads, AllCandidates(*f.em, "joint_offset"), IdentifyOptions{});
  // The correction is kept (the data supports it) but no single joint is named as its cause.
  ASSERT_EQ(r.effects.size(), 1u);
  const std::string& name = r.effects[0].name;
  EXPECT_NE(name.find("joint_offset@j2"), std::string::npos) << name;
  EXPECT_NE(name.find("joint_offset@j3"), std::string::npos) << name;
  EXPECT_NE(name.find(" | "), std::string::npos) << name;
  EXPECT_NEAR(r.effects[0].value[0], 0.01, 4.0 * r.effects[0].std[0]);
  ASSERT_EQ(r.indistinguishable.size(), 1u);
  std::vector<std::string> names = r.indistinguishable[0];
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"joint_offset@j2", "joint_offset@j3"}));
}

// Points of kTwinJoints made by MuJoCo's kinematics, not by the effect model under test: j3 turns
// `offset_rad` beyond its reading, 0.1 mm Gaussian noise per axis. Sets "a" and "b" alternate,
// so cross-validation leaves one out.
DataSet TwinRows(const Fixture& f, double offset_rad, int rows, std::mt19937_64& rng) {
  DataSet d;
  d.sets = {"a", "b"};
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::normal_distribution<double> n(0.0, 1e-4);
  mjData* md = mj_makeData(f.m.get());
  const int ee = mj_name2id(f.m.get(), mjOBJ_SITE, "ee");
  for (int r = 0; r < rows; ++r) {
    Observation o;
    o.q = Eigen::Vector3d(u(rng), u(rng), u(rng));
    for (int k = 0; k < 3; ++k) {
      const int jid = mj_name2id(f.m.get(), mjOBJ_JOINT, ("j" + std::to_string(k + 1)).c_str());
      md->qpos[f.m->jnt_qposadr[jid]] = o.q[k] + (k == 2 ? offset_rad : 0.0);
    }
    mj_kinematics(f.m.get(), md);
    o.p_base = Vec3(md->site_xpos[3 * ee], md->site_xpos[3 * ee + 1], md->site_xpos[3 * ee + 2]) +
               Vec3(n(rng), n(rng), n(rng));
    o.set = r % 2;
    d.rows.push_back(o);
  }
  mj_deleteData(md);
  return d;
}

// Mean point error of `fit` on rows it was not fitted to.
double ValidationError(const EffectModel& em, const DataSet& val, const Fit& fit) {
  const RowLoads loads = ComputeLoads(em, val, fit.active, fit.theta);
  return ConsistencyError(val, RowErrors(val, PredictAll(em, val, loads, fit.active, fit.theta)));
}

// An alternative as simple as the chosen cause keeps the verdict "ambiguous": with the chosen
// offset banned, the twin joint's offset (one parameter, as the chosen one) reaches the same
// held-out error. It is not put aside as one that merely also fits.
TEST(Identify, AnEquallySimpleAlternativeKeepsTheVerdictAmbiguous) {
  const Fixture f = Make(kTwinJoints, {"j1", "j2", "j3"});
  std::mt19937_64 rng(21);
  const DataSet cal = TwinRows(f, 0.01, 60, rng);
  const DataSet val = TwinRows(f, 0.01, 30, rng);
  const IdentifyResult r = Identify(*f.em, cal, ComputeLoads(*f.em, cal),
                                    AllCandidates(*f.em, "joint_offset"), IdentifyOptions{});
  std::string log;
  for (const auto& s : r.steps) log += s + "\n";
  ASSERT_EQ(r.effects.size(), 1u) << log;
  ASSERT_EQ(r.alternatives.size(), 1u) << log;
  const Alternative& a = r.alternatives[0];
  ASSERT_EQ(a.effects.size(), 1u) << log;
  std::vector<std::string> pair = {a.banned, a.effects[0]};
  std::sort(pair.begin(), pair.end());
  EXPECT_EQ(pair, (std::vector<std::string>{"joint_offset@j2", "joint_offset@j3"})) << log;
  EXPECT_EQ(a.num_params, 1) << log;
  EXPECT_EQ(a.chosen_params, 1) << log;
  EXPECT_LT(a.cv, 1.25 * r.cv_after) << log;
  EXPECT_TRUE(r.also_fits.empty()) << log;
  EXPECT_FALSE(r.attribution_unique) << log;
  const double before = ValidationError(*f.em, val, r.before);
  const double after = ValidationError(*f.em, val, r.after);
  EXPECT_LT(after, 0.3 * before) << log;
  EXPECT_EQ(Verdict(r, before, after), "ambiguous") << log;
}

// Points of kArm3 whose j3 turns by an error periodic in its own angle, 2 cycles per revolution
// (a strain-wave transmission error): written with the declared chain's plain forward kinematics,
// not with the effect model under test. Two sets, so cross-validation leaves one out. j3 spans
// +-j3_scale * pi; the points carry Gaussian noise of noise_m per axis.
DataSet PeriodicErrorData(const EffectModel& em, double amplitude, int rows, std::mt19937_64& rng,
                          double j3_scale = 0.6, double noise_m = 1e-4) {
  DataSet d;
  d.sets = {"a", "b"};
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  std::normal_distribution<double> n(0.0, noise_m);
  kinematics::PpoeData pd(em.chain());
  const kinematics::FrameId ee = em.chain().num_frames() - 1;
  for (int r = 0; r < rows; ++r) {
    Observation o;
    o.q = Eigen::Vector3d(u(rng), 0.6 * u(rng), j3_scale * u(rng));
    Eigen::VectorXd q_link = o.q;
    q_link[2] += amplitude * std::sin(2.0 * o.q[2] + 0.7);
    kinematics::ForwardKinematics(em.chain(), pd, q_link);
    o.p_base = pd.T_base_frame[ee].translation() + Vec3(n(rng), n(rng), n(rng));
    o.set = r % 2;
    d.rows.push_back(o);
  }
  return d;
}

std::vector<int> WithoutNeedsEvidence(const EffectModel& em) {
  std::vector<int> c;
  for (size_t i = 0; i < em.candidates().size(); ++i) {
    if (!em.candidates()[i].needs_evidence) c.push_back(i);
  }
  return c;
}

TEST(Identify, AnEffectOutsideTheLibraryIsReportedNotMisnamed) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  ASSERT_EQ(f.em->chain().frame(f.em->chain().num_frames() - 1).name, "site/ee");
  std::mt19937_64 rng(31);
  const double amplitude = 0.08 * M_PI / 180.0;
  const DataSet cal = PeriodicErrorData(*f.em, amplitude, 120, rng);
  const DataSet val = PeriodicErrorData(*f.em, amplitude, 80, rng);
  const auto cal_loads = ComputeLoads(*f.em, cal);
  const auto val_loads = ComputeLoads(*f.em, val);
  const IdentifyResult r =
      Identify(*f.em, cal, cal_loads, WithoutNeedsEvidence(*f.em), IdentifyOptions{});
  std::string log;
  for (const auto& s : r.steps) log += s + "\n";
  std::printf("%s\n", r.finding.message.c_str());
  // The structure is found where it lives: j3, 2 cycles per revolution, about its size.
  EXPECT_TRUE(r.finding.significant) << log;
  EXPECT_EQ(r.finding.kind, "periodic") << log;
  EXPECT_EQ(r.finding.variable, "j3") << log;
  EXPECT_EQ(r.finding.cycles, 2) << log;
  EXPECT_NEAR(r.finding.size, 0.08, 0.03) << log;
  const auto error = [&](const DataSet& d, const RowLoads& L, const Fit& fit) {
    return ConsistencyError(d, RowErrors(d, PredictAll(*f.em, d, L, fit.active, fit.theta)));
  };
  const double before = error(val, val_loads, r.before);
  const double after = error(val, val_loads, r.after);
  EXPECT_LE(after, before) << log;
  EXPECT_NE(Verdict(r, before, after), "explained") << log;
  EXPECT_NE(Verdict(r, before, after), "no_effect") << log;
  EXPECT_FALSE(r.finding.below_noise) << log;
}

// A periodic finding's size is what the data show: half the fitted curve's peak-to-peak over the
// joint's observed range, never more than the residual it explains. On noise alone a
// three-harmonic fit's largest coefficient once read hundreds of degrees.
TEST(Identify, APeriodicSizeIsWhatTheObservedRangeShows) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  for (const double scale : {0.6, 0.15}) {
    std::mt19937_64 rng(7);
    const DataSet cal = PeriodicErrorData(*f.em, 0.0, 120, rng, scale);
    const IdentifyResult r = Identify(*f.em, cal, ComputeLoads(*f.em, cal),
                                      WithoutNeedsEvidence(*f.em), IdentifyOptions{});
    if (r.finding.kind != "periodic") continue;
    double lo = HUGE_VAL, hi = -HUGE_VAL;
    for (const double z : r.finding.z) lo = std::min(lo, z), hi = std::max(hi, z);
    EXPECT_LE(r.finding.size, 0.5 * (hi - lo) * 180.0 / M_PI + 1e-12) << r.finding.message;
    EXPECT_FALSE(r.finding.significant) << r.finding.message;
  }
}

// Over a third of a turn the harmonics of 1, 2 and 3 cycles are nearly the same curve: they are
// not fitted together, and one is fitted alone only where half its cycle is seen.
TEST(Identify, HarmonicsTheRangeCannotTellApartAreNotFittedTogether) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  std::mt19937_64 rng(31);
  // j3 over +-0.3 pi (108 deg): only the 2- and 3-cycle harmonics, each alone.
  const DataSet cal = PeriodicErrorData(*f.em, 0.08 * M_PI / 180.0, 160, rng, 0.3);
  const IdentifyResult r = Identify(*f.em, cal, ComputeLoads(*f.em, cal),
                                    WithoutNeedsEvidence(*f.em), IdentifyOptions{});
  ASSERT_EQ(r.finding.kind, "periodic") << r.finding.message;
  EXPECT_EQ(r.finding.variable, "j3");
  // Over 0.3 of a turn the 2- and 3-cycle curves differ by less than a third of a cycle: either
  // may be reported, but never both fitted together.
  EXPECT_TRUE(r.finding.cycles == 2 || r.finding.cycles == 3) << r.finding.message;
  EXPECT_TRUE(r.finding.significant) << r.finding.message;
  int fitted = 0;
  for (int c = 1; c <= 3; ++c) {
    fitted += r.finding.coefficients[2 * c - 1] != 0.0 || r.finding.coefficients[2 * c] != 0.0;
  }
  EXPECT_EQ(fitted, 1) << r.finding.message;
  EXPECT_LE(r.finding.size, 0.08 + 0.02) << r.finding.message;
}

// Noise-free points whose deterministic residual is 0.15x the stated noise: a tiny p-value, but
// no evidence of a missing effect.
TEST(Identify, AStructureBelowTheStatedNoiseIsNeverSignificant) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  std::mt19937_64 rng(5);
  // The stated point noise (1e-4 m) seen as an angle at j3, whose marker is 0.6 m away.
  const double noise_rad = 1e-4 / 0.6;
  const DataSet cal = PeriodicErrorData(*f.em, 0.15 * noise_rad, 160, rng, 0.6, 1e-12);
  const IdentifyResult r = Identify(*f.em, cal, ComputeLoads(*f.em, cal),
                                    WithoutNeedsEvidence(*f.em), IdentifyOptions{});
  EXPECT_FALSE(r.finding.significant) << r.finding.message;
  EXPECT_FALSE(r.finding.notable) << r.finding.message;
  if (r.finding.kind == "periodic") {
    EXPECT_TRUE(r.finding.below_noise) << r.finding.message;
    EXPECT_NE(r.finding.message.find("below the stated noise"), std::string::npos)
        << r.finding.message;
  }
  EXPECT_NE(Verdict(r, 1.0, 0.5), "unexplained") << r.finding.message;
}

TEST(Identify, OnlyTheObservablePartOfAnOffsetIsReported) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "link_offset@j2")};
  const Eigen::Vector3d offset(0.002, 0.0, 0.003);  // z: along j1's axis, a pure translation
  std::mt19937_64 rng(14);
  const DataSet d = SocketData(*f.em, truth, offset, 8, rng);
  const auto loads = ComputeLoads(*f.em, d);
  const IdentifyResult r =
      Identify(*f.em, d, loads, AllCandidates(*f.em, "link_offset"), IdentifyOptions{});
  std::string log;
  for (const auto& s : r.steps) log += s + "\n";
  ASSERT_EQ(r.effects.size(), 1u) << log;
  EXPECT_EQ(r.effects[0].name.rfind("link_offset@j2", 0), 0u) << r.effects[0].name;
  EXPECT_NEAR(r.effects[0].value[0], 0.002, 2e-4) << log;
  EXPECT_NEAR(r.effects[0].value[1], 0.0, 2e-4) << log;
  EXPECT_NEAR(r.effects[0].value[2], 0.0, 1e-9) << "the unseen z part is not reported";
  ASSERT_EQ(r.effects[0].unobservable.size(), 1u) << log;
  EXPECT_GT(std::abs(r.effects[0].unobservable[0][2]), 0.99);
  EXPECT_EQ(std::find(r.unidentifiable.begin(), r.unidentifiable.end(), "link_offset@j2"),
            r.unidentifiable.end());
}

TEST(Identify, RefusesAGroupOfOneRowAndTooFewResiduals) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  std::mt19937_64 rng(15);
  DataSet d = SocketData(*f.em, {}, Eigen::VectorXd(), 4, rng);
  d.rows.erase(d.rows.begin() + 1, d.rows.begin() + 4);  // socket0 keeps one row
  const auto loads = ComputeLoads(*f.em, d);
  try {
    Identify(*f.em, d, loads, AllCandidates(*f.em), IdentifyOptions{});
    FAIL() << "accepted a group of one row";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("group 'socket0' has one row"), std::string::npos)
        << e.what();
  }
}

TEST(Identify, AFarOffRowIsRejectedAndTheEffectStillFound) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_offset@j2")};
  const Eigen::VectorXd theta = Eigen::VectorXd::Constant(1, 0.01);
  std::mt19937_64 rng(16);
  DataSet d = PointData(*f.em, truth, theta, 60, 1e-4, rng);
  for (size_t r = 0; r < d.rows.size(); ++r) d.rows[r].set = r % 2;
  d.sets = {"a", "b"};
  d.rows[17].p_base.x() = 1e6;
  const auto loads = ComputeLoads(*f.em, d);
  const std::vector<int> out = FindOutliers(*f.em, d, loads, IdentifyOptions{});
  ASSERT_EQ(out, std::vector<int>{17});
  const DataSet clean = WithoutRows(d, out);
  const IdentifyResult r =
      Identify(*f.em, clean, ComputeLoads(*f.em, clean), AllCandidates(*f.em), IdentifyOptions{});
  ASSERT_EQ(r.effects.size(), 1u);
  // (Every row holds j2 on the same flank here, so a backlash there is the same correction.)
  EXPECT_EQ(r.effects[0].name.rfind("joint_offset@j2", 0), 0u) << r.effects[0].name;
  EXPECT_NEAR(r.effects[0].value[0], 0.01, 4.0 * r.effects[0].std[0]);
}

TEST(Identify, FoldsAreSetsThenGroupsThenRows) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  std::mt19937_64 rng(17);
  DataSet sockets = SocketData(*f.em, {}, Eigen::VectorXd(), 5, rng);
  EXPECT_EQ(MakeFolds(sockets).by, "group");
  EXPECT_EQ(MakeFolds(sockets).test_rows.size(), 5u);
  sockets.sets = {"a", "b"};
  for (size_t r = 0; r < sockets.rows.size(); ++r) sockets.rows[r].set = r < 8 ? 0 : 1;
  EXPECT_EQ(MakeFolds(sockets).by, "set");
  const DataSet points = PointData(*f.em, {}, Eigen::VectorXd(), 12, 1e-4, rng);
  const Folds rows = MakeFolds(points);
  EXPECT_EQ(rows.by, "row");
  ASSERT_EQ(rows.test_rows.size(), 5u);
  EXPECT_EQ(rows.test_rows[2], (std::vector<int>{2, 7}));
  // A held-out fold keeps its groups and sets, renumbered.
  const DataSet sub = Subset(sockets, {8, 9, 12});
  EXPECT_EQ(sub.groups.size(), 2u);
  EXPECT_EQ(sub.sets, std::vector<std::string>{"b"});
}

// Two markers seen at one posture share its reading errors: a fold holding one of them and
// training on the other would score the posture's own errors as predicted. Rows with the same
// readings (and set), or the same `pose` label, stay in one fold.
TEST(Identify, FoldsKeepAPosturesRowsTogether) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  std::mt19937_64 rng(23);
  DataSet points = PointData(*f.em, {}, Eigen::VectorXd(), 12, 1e-4, rng);
  DataSet twice;
  twice.sets = points.sets;
  for (const Observation& o : points.rows) {
    twice.rows.push_back(o);
    twice.rows.push_back(o);  // the second marker: same readings, another point
    twice.rows.back().p_base += Vec3(0.01, 0.0, 0.0);
  }
  const Folds by_posture = MakeFolds(twice);
  ASSERT_EQ(by_posture.test_rows.size(), 5u);
  EXPECT_EQ(by_posture.test_rows[2], (std::vector<int>{4, 5, 14, 15}));
  for (const std::vector<int>& fold : by_posture.test_rows) {
    for (int r : fold) {
      const int other = r % 2 ? r - 1 : r + 1;
      EXPECT_NE(std::find(fold.begin(), fold.end(), other), fold.end()) << "row " << r;
    }
  }
  // A `pose` label ties rows whose readings differ (a reading per marker); different labels
  // part rows whose readings are the same.
  for (size_t r = 0; r < twice.rows.size(); ++r) {
    twice.rows[r].pose = LabelIndex(&twice.poses, "p" + std::to_string(r / 4));
  }
  for (size_t r = 0; r < twice.rows.size(); r += 4) twice.rows[r + 2].q[0] += 1e-3;
  const Folds by_label = MakeFolds(twice);
  ASSERT_EQ(by_label.test_rows.size(), 5u);
  EXPECT_EQ(by_label.test_rows[0], (std::vector<int>{0, 1, 2, 3, 20, 21, 22, 23}));
  twice.poses.clear();
  for (size_t r = 0; r < twice.rows.size(); ++r) {
    twice.rows[r].pose = LabelIndex(&twice.poses, "p" + std::to_string(r));
  }
  EXPECT_EQ(MakeFolds(twice).test_rows[1], (std::vector<int>{1, 6, 11, 16, 21}));
}

// Full poses (a tracker with orientation) and pixels of a fixed, slightly miscalibrated camera.
TEST(Identify, PosesAndPixelsWithACameraOffset) {
  sim::MjModelPtr m = sim::LoadModelFromString(kArm3, "inline.xml");
  sim::DeclaredModel dm;
  dm.file = "inline.declared";
  dm.actuated_joints = {"j1", "j2", "j3"};
  dm.end_effector = "ee";
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), dm);
  const EffectModel em(m.get(), chain, chain.end_effector, "cam");
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  std::normal_distribution<double> n(0.0, 1.0);
  EffectModel::Workspace ws = em.MakeWorkspace();

  // Poses: an axis tilt only the orientation reveals well, at 1 mm / 1 mrad.
  {
    const std::vector<int> truth = {Candidate(em, "joint_axis_tilt_a@j3")};
    const double theta = 0.01;
    DataSet d;
    d.sets = {"s"};
    for (int r = 0; r < 40; ++r) {
      Observation o;
      o.type = ObservationType::kPose;
      o.q = Eigen::Vector3d(u(rng), u(rng), u(rng));
      const lie::SE3 T = em.PredictPose(o.q, em.Loads(o.q), truth, &theta, ws);
      o.p_base = T.translation() + 1e-3 * Vec3(n(rng), n(rng), n(rng));
      o.R_base = T.rotation() * lie::SO3Exp(1e-3 * Vec3(n(rng), n(rng), n(rng)));
      d.rows.push_back(o);
    }
    IdentifyOptions opt;
    opt.point_std_m = 1e-3;
    opt.rotation_std_rad = 1e-3;
    const auto loads = ComputeLoads(em, d);
    const IdentifyResult r = Identify(em, d, loads, AllCandidates(em, "joint_axis_tilt"), opt);
    ASSERT_EQ(r.effects.size(), 1u);
    EXPECT_EQ(r.effects[0].name, "joint_axis_tilt_a@j3");
    EXPECT_NEAR(r.effects[0].value[0], theta, 4.0 * r.effects[0].std[0]);
  }

  // Pixels: the camera is 1.5 m in front of the arm, looking back at it.
  {
    DataSet d;
    d.sets = {"s"};
    d.camera.present = true;
    d.camera.name = "cam";
    d.camera.intrinsics.fx = d.camera.intrinsics.fy = 600.0;
    d.camera.intrinsics.cx = 320.0;
    d.camera.intrinsics.cy = 240.0;
    Mat3 R;
    R.col(0) = Vec3(0, 1, 0);   // x right
    R.col(1) = Vec3(0, 0, -1);  // y down
    R.col(2) = Vec3(-1, 0, 0);  // z forward, towards the arm
    d.camera.T_base_cam = lie::SE3(R, Vec3(1.5, 0.0, 0.3));
    const std::vector<int> truth = {Candidate(em, "camera_offset@cam"),
                                    Candidate(em, "joint_offset@j2")};
    Eigen::VectorXd theta(7);
    theta << 0.01, -0.008, 0.012, 0.006, -0.008, 0.004, 0.02;
    const lie::SE3 T_true_cam = d.camera.T_base_cam * lie::SE3::Exp(theta.head<6>());
    for (int r = 0; r < 80; ++r) {
      Observation o;
      o.type = ObservationType::kPixel;
      o.q = Eigen::Vector3d(u(rng), u(rng), u(rng));
      const Vec3 p = em.Predict(o.q, em.Loads(o.q), truth, theta.data(), ws);
      const Vec3 pc = T_true_cam.rotation().transpose() * (p - T_true_cam.translation());
      o.uv = Eigen::Vector2d(600.0 * pc.x() / pc.z() + 320.0, 600.0 * pc.y() / pc.z() + 240.0) +
             0.3 * Eigen::Vector2d(n(rng), n(rng));
      d.rows.push_back(o);
    }
    IdentifyOptions opt;
    opt.pixel_std_px = 0.3;
    const auto loads = ComputeLoads(em, d);
    std::vector<int> cands = AllCandidates(em, "joint_offset");
    cands.push_back(Candidate(em, "camera_offset@cam"));
    const IdentifyResult r = Identify(em, d, loads, cands, opt);
    std::vector<std::string> found;
    for (const auto& e : r.effects) found.push_back(e.name);
    std::sort(found.begin(), found.end());
    std::string log;
    for (const auto& s : r.steps) log += s + "\n";
    EXPECT_EQ(found, (std::vector<std::string>{"camera_offset@cam", "joint_offset@j2"})) << log;
    const auto before = RowErrors(d, PredictAll(em, d, loads, {}, Eigen::VectorXd()),
                                  PredictPixels(em, d, loads, {}, Eigen::VectorXd()));
    const auto after = RowErrors(d, PredictAll(em, d, loads, r.after.active, r.after.theta),
                                 PredictPixels(em, d, loads, r.after.active, r.after.theta));
    EXPECT_GT(MeanRowError(d, before, RowUnit::kPixels), 10.0);
    EXPECT_LT(MeanRowError(d, after, RowUnit::kPixels), 0.6);
  }
}

class CalibrationCsv : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("flexbench_csv_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& text) {
    const fs::path p = dir_ / "data.csv";
    testing::WriteFile(p, text);
    return p.string();
  }
  std::string Error(const std::string& text) {
    DataSet d;
    try {
      ReadCalibrationCsv(Write(text), {"j1", "j2"}, &d);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  }
  fs::path dir_;
};

TEST_F(CalibrationCsv, ReadsGroupsSetsAndPoints) {
  DataSet d;
  ReadCalibrationCsv(Write("# socket data\nj2,j1,group,set\n0.1,0.2,a,p1\n0.3,0.4,b,p1\n"
                           "0.5,0.6,a,p2\n"),
                     {"j1", "j2"}, &d);
  ASSERT_EQ(d.rows.size(), 3u);
  EXPECT_EQ(d.rows[0].q, (Eigen::VectorXd(2) << 0.2, 0.1).finished());
  EXPECT_EQ(d.groups, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(d.sets, (std::vector<std::string>{"p1", "p2"}));
  EXPECT_EQ(d.rows[2].group, 0);
  DataSet p;
  ReadCalibrationCsv(Write("j1,j2,x,y,z\n0,0,1,2,3\n"), {"j1", "j2"}, &p);
  EXPECT_EQ(p.rows[0].p_base, Vec3(1, 2, 3));
  EXPECT_EQ(p.rows[0].type, ObservationType::kPoint);
  DataSet q;
  ReadCalibrationCsv(Write("j1,j2,x,y,z,qw,qx,qy,qz\n0,0,1,2,3,0,0,0,1\n"), {"j1", "j2"}, &q);
  EXPECT_EQ(q.rows[0].type, ObservationType::kPose);
  EXPECT_TRUE(
      q.rows[0].R_base.get().isApprox(Eigen::Vector3d(-1, -1, 1).asDiagonal().toDenseMatrix()));
}

TEST_F(CalibrationCsv, APoseColumnLabelsPostures) {
  DataSet d;
  ReadCalibrationCsv(Write("j1,j2,x,y,z,pose\n0,0,1,2,3,7\n0,0,1,2,4,7\n0,1,1,2,3,8\n"),
                     {"j1", "j2"}, &d);
  ASSERT_EQ(d.rows.size(), 3u);
  EXPECT_EQ(d.poses, (std::vector<std::string>{"7", "8"}));
  EXPECT_EQ(d.rows[1].pose, 0);
  EXPECT_EQ(d.rows[2].pose, 1);
  EXPECT_NE(Error("j1,j2,x,y,z,pose\n0,0,1,2,3,\n").find("data.csv:2: column 'pose' is empty"),
            std::string::npos);
}

TEST_F(CalibrationCsv, BadInputNamesTheFileAndLine) {
  EXPECT_NE(Error("j1,j2,group\n0,0,a\n0,0\n").find("data.csv:3: 2 columns, the header has 3"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,group\n0,nan,a\n").find("data.csv:2: column 'j2' is nan"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,j9,group\n0,0,0,a\n").find("data.csv:1: column 'j9' is neither"),
            std::string::npos);
  EXPECT_NE(Error("j1,group\n0,a\n").find("no column for joint 'j2'"), std::string::npos);
  EXPECT_NE(Error("j1,j2,x,y\n0,0,1,2\n").find("x, y and z go together"), std::string::npos);
  EXPECT_NE(Error("j1,j2,group\n0,abc,a\n").find("'abc' is not a number"), std::string::npos);
  EXPECT_NE(Error("j1,j2,group\n").find("no data rows"), std::string::npos);
  EXPECT_NE(Error("j1,j2,x,y,z,qw,qx\n0,0,1,1,1,1,0\n").find("a pose needs"), std::string::npos);
  EXPECT_NE(Error("j1,j2,x,y,z,qw,qx,qy,qz\n0,0,1,1,1,2,0,0,0\n").find("not of unit length"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,u,v\n0,0,1,1\n").find("need a camera"), std::string::npos);
  EXPECT_NE(Error("j1,j2,up_x,up_y,up_z\n0,0,0,0,2\n")
                .find("data.csv:2: (up_x, up_y, up_z) is "
                      "not of unit length"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,up_x,up_y\n0,0,0,1\n").find("up_x, up_y and up_z go together"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,up_x,up_y,up_z,x,y,z\n0,0,0,0,1,1,1,1\n").find("need exactly one of"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,x,y,z,x\n0,0,1,1,1,1\n").find("column 'x' twice"), std::string::npos);
  EXPECT_NE(Error("j1,j2,group,set\n0,0,a,\n").find("column 'set' is empty"), std::string::npos);
  EXPECT_NE(Error("j1,j2,motion_j2,group\n0,0,2,a\n").find("must be -1, 0 or 1"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,motion_j7,group\n0,0,1,a\n").find("names no actuated joint"),
            std::string::npos);
}

// Excel's byte-order mark, absurd values, groups that span sets, socket distances.
TEST_F(CalibrationCsv, ByteOrderMarkIsNotPartOfTheFirstColumn) {
  DataSet d;
  ReadCalibrationCsv(Write("\xEF\xBB\xBFj1,j2,x,y,z\n0.1,0.2,1,2,3\n"), {"j1", "j2"}, &d);
  ASSERT_EQ(d.rows.size(), 1u);
  EXPECT_EQ(d.rows[0].q[0], 0.1);
}

TEST_F(CalibrationCsv, FiniteAbsurdValuesAreOutOfRange) {
  EXPECT_NE(Error("j1,j2,x,y,z\n1e200,0,1,2,3\n")
                .find("data.csv:2: column 'j1': 1e200 is out "
                      "of range"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,x,y,z\n0,0,1e308,2,3\n").find("column 'x': 1e308 is out of range"),
            std::string::npos);
  EXPECT_NE(Error("j1,j2,group\n0,1e5,a\n").find("out of range"), std::string::npos);
  EXPECT_EQ(Error("j1,j2,x,y,z\n-3.1,6.2,-2.5,0.5,1e2\n"), "");
}

TEST_F(CalibrationCsv, EchoedCellsAreCapped) {
  const std::string e = Error("j1,j2,group\n0," + std::string(10000, 'z') + ",a\n");
  EXPECT_NE(e.find("is not a number"), std::string::npos) << e.substr(0, 300);
  EXPECT_LT(e.size(), 400u);
}

TEST_F(CalibrationCsv, AGroupSpanningSetsIsWarnedAbout) {
  DataSet d;
  ::testing::internal::CaptureStderr();
  ReadCalibrationCsv(Write("j1,j2,group,set\n0,0,hole_0,front\n0,1,hole_0,left\n"), {"j1", "j2"},
                     &d);
  std::string err = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(err.find("data.csv:3: group 'hole_0' spans sets 'front' and 'left'"), std::string::npos)
      << err;
  EXPECT_NE(err.find("'left/hole_0'"), std::string::npos) << err;
  DataSet ok;
  ::testing::internal::CaptureStderr();
  ReadCalibrationCsv(Write("j1,j2,group,set\n0,0,front/hole_0,front\n0,1,left/hole_0,left\n"),
                     {"j1", "j2"}, &ok);
  err = ::testing::internal::GetCapturedStderr();
  EXPECT_EQ(err, "");
}

TEST_F(CalibrationCsv, DevicesAreRefused) {
  DataSet d;
  EXPECT_THROW(ReadCalibrationCsv("/dev/zero", {"j1", "j2"}, &d), InputError);
}

TEST(MukcaPlacement, SocketDistanceMustBePositive) {
  DataSet d;
  for (double bad : {-0.05, 0.0, 1e300}) {
    try {
      ReadMukcaPlacement("/nonexistent", "front", 7, bad, &d);
      ADD_FAILURE() << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("socket_distance_m"), std::string::npos) << e.what();
    }
  }
}

// "Bring your own robot and data": a model file, a declared model and two CSVs through the CLI.
// A simulated scenario writes its rows as the CSV a user brings; `flexbench identify` on them
// finds what the scenario found, to the last bit (the same rows, the same options).
TEST(IdentifyCommand, ASimulatedScenariosDataCsvReproducesItsResult) {
  const fs::path dir = fs::temp_directory_path() / ("flexbench_rows_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string run = testing::Flexbench() + " run " + testing::SourceDir() +
                          "/scenarios/closed_loop_humanoid_tracker.yaml --quiet --set "
                          "calibration.simulate.postures=25 --set validation.simulate.postures=10 "
                          "--out " +
                          (dir / "scenario").string();
  const testing::CommandResult sim = testing::RunCommand(run);
  ASSERT_EQ(sim.exit_code, 0) << sim.err;
  const std::string csv = testing::ReadFile(dir / "scenario" / "calibration_data.csv");
  EXPECT_EQ(testing::CountLines(csv), 1 + 2 * 25);
  EXPECT_EQ(csv.rfind("shoulder_pitch,", 0), 0u) << csv.substr(0, 200);
  EXPECT_NE(csv.find(",set,pose,frame,marker,x,y,z\n"), std::string::npos);
  const testing::CommandResult id = testing::RunCommand(
      testing::Flexbench() + " identify --quiet --declared " + testing::SourceDir() +
      "/models/humanoid_upper.declared.yaml --calibration " +
      (dir / "scenario" / "calibration_data.csv").string() + " --validation " +
      (dir / "scenario" / "validation_data.csv").string() +
      " --frame tracker --marker right_marker --marker left_marker --out " +
      (dir / "identify").string());
  ASSERT_EQ(id.exit_code, 0) << id.err;
  const auto a = nlohmann::json::parse(testing::ReadFile(dir / "scenario" / "summary.json"));
  const auto b = nlohmann::json::parse(testing::ReadFile(dir / "identify" / "summary.json"));
  for (const char* k : {"val_err_before_m", "val_err_after_m", "cal_err_after_m", "cv_err_after",
                        "effects_found", "verdict"}) {
    EXPECT_EQ(a["metrics"][k], b["metrics"][k]) << k;
  }
  // A bad name in an option says the option, not the scenario key it became.
  const testing::CommandResult bad = testing::RunCommand(
      testing::Flexbench() + " identify --quiet --declared " + testing::SourceDir() +
      "/models/humanoid_upper.declared.yaml --calibration " +
      (dir / "scenario" / "calibration_data.csv").string() + " --validation " +
      (dir / "scenario" / "validation_data.csv").string() +
      " --frame tracker --marker right_marker --unknown-marker-offset left_hand --out " +
      (dir / "bad").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(testing::LastLine(bad.err).find("flexbench: error: --unknown-marker-offset: "), 0u)
      << bad.err;
  fs::remove_all(dir);
}

// Every row type written and read back gives the same rows, bit for bit.
TEST(IdentifyCommand, CalibrationCsvRoundTrips) {
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  std::mt19937_64 rng(5);
  DataSet points = PointData(*f.em, {}, Eigen::VectorXd(), 6, 1e-4, rng);
  DataSet sockets = SocketData(*f.em, {}, Eigen::VectorXd(), 3, rng);
  DataSet gravity = points;  // an IMU at the end effector, at rest
  for (Observation& o : gravity.rows) {
    o.type = ObservationType::kGravity;
    o.p_base.setZero();
    o.up() = Eigen::Vector3d(std::normal_distribution<double>()(rng), 0.3, 1.0).normalized();
  }
  for (DataSet* d : {&points, &sockets, &gravity}) {
    const fs::path p =
        fs::temp_directory_path() / ("flexbench_rt_" + std::to_string(::getpid()) + ".csv");
    testing::WriteFile(p, FormatCalibrationCsv(*d, {"j1", "j2", "j3"}));
    DataSet back;
    ReadCalibrationCsv(p.string(), {"j1", "j2", "j3"}, &back);
    fs::remove(p);
    ASSERT_EQ(back.rows.size(), d->rows.size());
    for (size_t r = 0; r < back.rows.size(); ++r) {
      EXPECT_EQ(back.rows[r].q, d->rows[r].q);
      EXPECT_EQ(back.rows[r].p_base, d->rows[r].p_base);
      EXPECT_EQ(back.rows[r].up(), d->rows[r].up());
      EXPECT_EQ(back.rows[r].type, d->rows[r].type);
      EXPECT_EQ(back.groups.size(), d->groups.size());
    }
  }
  points.rows[1].type = ObservationType::kGroup;
  EXPECT_THROW(FormatCalibrationCsv(points, {"j1", "j2", "j3"}), InputError);
}

TEST(IdentifyCommand, FindsTheEffectInAUsersCsvAndRejectsABadRow) {
  const fs::path dir = fs::temp_directory_path() / ("flexbench_byo_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  testing::WriteFile(dir / "arm3.xml", kArm3);
  testing::WriteFile(dir / "arm3.declared.yaml",
                     "model: arm3.xml\nactuated_joints: [j1, j2, j3]\nend_effector: ee\n"
                     "sources:\n  - {at: j2, about_axis_deg: 0.5}\n");
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const std::vector<int> truth = {Candidate(*f.em, "joint_offset@j2")};
  const Eigen::VectorXd theta = Eigen::VectorXd::Constant(1, -0.01);
  std::mt19937_64 rng(21);
  for (const char* name : {"cal.csv", "val.csv"}) {
    const DataSet d = PointData(*f.em, truth, theta, 40, 1e-4, rng);
    std::string csv = "j1,j2,j3,x,y,z\n";
    char row[256];
    for (const Observation& o : d.rows) {
      std::snprintf(row, sizeof(row), "%.12g,%.12g,%.12g,%.12g,%.12g,%.12g\n", o.q[0], o.q[1],
                    o.q[2], o.p_base.x(), o.p_base.y(), o.p_base.z());
      csv += row;
    }
    testing::WriteFile(dir / name, csv);
  }
  const std::string cmd = testing::BinDir() + "/flexbench identify --model " +
                          (dir / "arm3.xml").string() + " --declared " +
                          (dir / "arm3.declared.yaml").string() + " --validation " +
                          (dir / "val.csv").string() + " --out " + (dir / "out").string();
  const testing::CommandResult ok =
      testing::RunCommand(cmd + " --calibration " + (dir / "cal.csv").string());
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  const std::string summary = testing::ReadFile(dir / "out" / "summary.json");
  EXPECT_NE(summary.find("\"effects_found\": [\n      \"joint_offset@j2\"\n    ]"),
            std::string::npos)
      << summary.substr(0, 2000);
  // The augmented declared model is a declared model again, with the effect and its value.
  const sim::DeclaredModel aug =
      sim::LoadDeclaredModel((dir / "out" / "declared_augmented.yaml").string());
  ASSERT_EQ(aug.identified_effects.size(), 1u);
  EXPECT_EQ(aug.identified_effects[0].effect, "joint_offset@j2");
  EXPECT_NEAR(aug.identified_effects[0].value[0], -0.01, 4.0 * aug.identified_effects[0].std[0]);
  EXPECT_EQ(aug.actuated_joints, (std::vector<std::string>{"j1", "j2", "j3"}));
  ASSERT_EQ(aug.sources.size(), 1u);
  EXPECT_LT(aug.sources[0].about_axis_rad, 0.5 * M_PI / 180.0);  // reduced to what remains
  // Selection options on the command line: with no effect allowed, nothing is shipped.
  const testing::CommandResult none =
      testing::RunCommand(cmd + "0 --max-effects 0 --calibration " + (dir / "cal.csv").string());
  ASSERT_EQ(none.exit_code, 0) << none.err;
  EXPECT_NE(testing::ReadFile(dir / "out0" / "summary.json").find("\"verdict\": \"unexplained\""),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "out0" / "declared_augmented.yaml"));
  const testing::CommandResult sets =
      testing::RunCommand(cmd + "1 --folds-by set --calibration " + (dir / "cal.csv").string());
  EXPECT_EQ(sets.exit_code, 2) << sets.err;
  EXPECT_NE(sets.err.find("cross-validation by set needs at least two sets"), std::string::npos)
      << sets.err;
  testing::WriteFile(dir / "bad.csv", "j1,j2,j3,x,y,z\n0,0,0,1,1,1\n0,nan,0,1,1,1\n");
  const testing::CommandResult bad =
      testing::RunCommand(cmd + " --calibration " + (dir / "bad.csv").string());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("bad.csv:3: column 'j2' is nan"), std::string::npos) << bad.err;
  fs::remove_all(dir);
}

// --reading-std-deg: the validation rows' noise is the readings' noise through the kinematics
// (the points exact, as a socket's) plus the fitted parameters' covariance, and the declared
// sources are scaled to what is left. Readings drawn with noise around MuJoCo-made points: when
// the identified model is complete the sources shrink to (almost) nothing and the validation
// NEES is inside its bounds without them; an error the candidates cannot explain (only joint
// offsets allowed) is left to the sources, sized to a mean NEES of 3 where they act, and
// reported as not covered where they do not.
TEST(IdentifyCommand, ReadingNoiseSizesTheSourcesOnWhatTheDataLeaves) {
  const fs::path dir = fs::temp_directory_path() / ("flexbench_rn_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  testing::WriteFile(dir / "arm3.xml", kArm3);
  testing::WriteFile(dir / "arm3.declared.yaml",
                     "model: arm3.xml\nactuated_joints: [j1, j2, j3]\nend_effector: ee\n"
                     "sources:\n  - {at: j2, about_axis_deg: 0.5}\n");
  const Fixture f = Make(kArm3, {"j1", "j2", "j3"});
  const double reading_std = 0.05 * M_PI / 180.0;
  const auto write = [&](const std::string& tag, const std::vector<int>& truth,
                         const Eigen::VectorXd& theta) {
    std::mt19937_64 rng(31);
    std::normal_distribution<double> n(0.0, reading_std);
    for (const char* name : {"cal", "val"}) {
      const DataSet d = PointData(*f.em, truth, theta, 60, 1e-15, rng);
      std::string csv = "j1,j2,j3,x,y,z\n";
      char row[256];
      for (const Observation& o : d.rows) {
        std::snprintf(row, sizeof(row), "%.12g,%.12g,%.12g,%.12g,%.12g,%.12g\n", o.q[0] + n(rng),
                      o.q[1] + n(rng), o.q[2] + n(rng), o.p_base.x(), o.p_base.y(), o.p_base.z());
        csv += row;
      }
      testing::WriteFile(dir / (tag + "_" + name + ".csv"), csv);
    }
  };
  const auto identify = [&](const std::string& tag, const std::string& extra,
                            const std::string& out_tag = "") {
    const std::string out = (dir / ("out_" + tag + out_tag)).string();
    const testing::CommandResult r = testing::RunCommand(
        testing::BinDir() + "/flexbench identify --declared " +
        (dir / "arm3.declared.yaml").string() + " --calibration " +
        (dir / (tag + "_cal.csv")).string() + " --validation " +
        (dir / (tag + "_val.csv")).string() + " --candidates joint_offset --out " + out + extra);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return nlohmann::json::parse(testing::ReadFile(fs::path(out) / "summary.json"))["metrics"];
  };
  const std::vector<int> offset = {Candidate(*f.em, "joint_offset@j2")};
  write("complete", offset, Eigen::VectorXd::Constant(1, -0.01));
  // Left to the j2 source: a transmission error of j2 (about its axis, where that source acts);
  // not: j3 4 mm longer (along the arm, where no source acts).
  const std::vector<int> periodic = {Candidate(*f.em, "joint_offset@j2"),
                                     Candidate(*f.em, "transmission_error@j2")};
  write("missing", periodic, (Eigen::VectorXd(5) << -0.01, 0.004, 0.0, 0.0, 0.003).finished());
  const std::vector<int> longer = {Candidate(*f.em, "joint_offset@j2"),
                                   Candidate(*f.em, "link_length@j3")};
  write("uncovered", longer, (Eigen::VectorXd(2) << -0.01, 0.004).finished());

  const auto complete = identify("complete", " --reading-std-deg 0.05");
  EXPECT_EQ(complete["source_scale_from"], "readings' noise and fitted parameters");
  EXPECT_LT(complete["source_covariance_scale"].get<double>(), 1e-3);
  EXPECT_GE(complete["nees_after_scaled"].get<double>(), complete["nees_bound_low"].get<double>());
  EXPECT_LE(complete["nees_after_scaled"].get<double>(), complete["nees_bound_high"].get<double>());

  const auto missing = identify("missing", " --reading-std-deg 0.05");
  EXPECT_GT(missing["source_covariance_scale"].get<double>(), 1e-2);
  // Scaled until the rows' NEES reaches its upper bound with the fitted parameters' shared
  // error (no further: the sources cover only what the noise and the parameters cannot).
  EXPECT_GT(missing["nees_bound_high_shared"].get<double>(), 3.0);
  EXPECT_NEAR(missing["nees_after_scaled"].get<double>(),
              missing["nees_bound_high_shared"].get<double>(), 1e-6);
  EXPECT_TRUE(missing["sources_cover_residual"].get<bool>());
  const auto uncovered = identify("uncovered", " --reading-std-deg 0.05");
  EXPECT_FALSE(uncovered["sources_cover_residual"].get<bool>());
  EXPECT_GT(uncovered["nees_after_scaled"].get<double>(),
            uncovered["nees_bound_high_shared"].get<double>());

  // Without the readings' noise the stated point noise stands in, with the 1e-6 floor.
  const auto point = identify("complete", "", "_point");
  EXPECT_EQ(point["source_scale_from"], "point_std_m (floor 1e-6)");
  // --set reaches identify's closed_loop keys too, and is recorded.
  const auto none = identify("complete", " --set max_effects=0", "_set");
  EXPECT_EQ(none["verdict"], "unexplained");
  EXPECT_EQ(nlohmann::json::parse(
                testing::ReadFile(dir / "out_complete_set" / "summary.json"))["overrides"],
            (nlohmann::json{"max_effects=0"}));
  fs::remove_all(dir);
}

TEST(ClosedLoopMukca, RealPandaDataMeetsItsGates) {
  const fs::path data = fs::path(testing::SourceDir()) / "../shared/data/mukca/data/panda_6";
  if (!fs::exists(data)) {
    GTEST_SKIP() << "MUKCa recordings not found at " << data.string()
                 << " (read from ../shared at run time, never copied)";
  }
  scenarios::RunOptions o;
  o.scenario_path = testing::SourceDir() + "/scenarios/closed_loop_mukca_panda.yaml";
  o.out_dir =
      (fs::temp_directory_path() / ("flexbench_mukca_" + std::to_string(::getpid()))).string();
  o.check_gates = true;
  EXPECT_EQ(scenarios::RunScenario(o), scenarios::kExitOk);
  fs::remove_all(o.out_dir);
}

}  // namespace
}  // namespace flexbench::identify
