// Lateral joint compliance (bearing and housing bending about the two axes normal to a joint's
// own; Tenhumberg & Bauml 2021, kappa_alpha / kappa_beta), end to end on a small arm whose MJCF
// carries the hinges j2_lateral_a, j2_lateral_b before j2:
//   - the truth: MuJoCo statics (sim::Simulation::Settle) bend the hinges by the weight's moment
//     over the stiffness, checked against a moment summed here from the bodies' masses; locked,
//     the hinges change nothing;
//   - identification on rows made by that truth (not by the effect model) names
//     lateral_compliance@j2 and recovers the compliances, and does not name it on data without
//     it;
//   - the declared model with the identified effect predicts as the identification model;
//   - a coupled joint does not offer it (listed as skipped), and bad input is an InputError.
#include <gtest/gtest.h>

#include <cstdio>
#include <map>
#include <random>
#include <string>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "estimators/lie/so3.h"
#include "scenarios/identify/effect_model.h"
#include "scenarios/identify/identify.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/identify_test_util.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

// j1 rolls the arm about the horizontal x, so gravity has components along both of j2's lateral
// axes (a = x along the upper arm, b = -z); j3 swings the forearm sideways.
constexpr char kArm[] = R"(
<mujoco model="arm_lateral">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001"/>
  <default><joint armature="0.01" damping="5"/></default>
  <worldbody>
    <body name="base" pos="0 0 0.3">
      <joint name="j1" axis="1 0 0"/>
      <geom type="cylinder" size="0.05 0.05" mass="1"/>
      <body name="upper" pos="0.02 0.01 0.1">
        <joint name="j2_lateral_a" axis="1 0 0"/>
        <joint name="j2_lateral_b" axis="0 0 -1"/>
        <joint name="j2" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="3"/>
        <body name="fore" pos="0.4 0 0">
          <joint name="j3" axis="0 0 1"/>
          <geom type="capsule" fromto="0 0 0 0.35 0 0" size="0.025" mass="2"/>
          <body name="wrist" pos="0.35 0 0">
            <joint name="j4" axis="0 1 0"/>
            <geom type="box" size="0.03 0.03 0.03" pos="0.03 0 0.01" mass="0.7"/>
            <site name="ee" pos="0.08 0.01 0.02"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="j1" joint="j1" kp="500"/>
    <position name="j2" joint="j2" kp="500"/>
    <position name="j3" joint="j3" kp="500"/>
    <position name="j4" joint="j4" kp="500"/>
  </actuator>
</mujoco>)";

constexpr double kNoise = 1e-4;  // point noise per axis, m

sim::EffectList Lateral(const std::string& params) {
  sim::EffectList effects;
  effects.push_back(sim::MakeEffect("lateral_compliance", params));
  return effects;
}

sim::DeclaredModel Declared() {
  sim::DeclaredModel d;
  d.file = "arm_lateral.declared.yaml";
  d.model_path = "arm_lateral.xml";
  d.actuated_joints = {"j1", "j2", "j3", "j4"};
  d.end_effector = "ee";
  return d;
}

struct Rig {
  std::unique_ptr<sim::Simulation> sim;
  sim::DeclaredModel declared;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
};

std::unique_ptr<Rig> MakeRig(const sim::EffectList& effects) {
  auto rig = std::make_unique<Rig>();
  rig->sim = sim::Simulation::FromString(kArm, "arm_lateral.xml", effects);
  rig->declared = Declared();
  rig->chain = sim::BuildDeclaredChain(rig->sim->nominal_model(), rig->declared);
  rig->em =
      std::make_unique<EffectModel>(rig->sim->nominal_model(), rig->chain, rig->chain.end_effector);
  return rig;
}

Eigen::VectorXd RandomCommand(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd q(4);
  for (int k = 0; k < 4; ++k) q[k] = u(rng);
  return q;
}

// The moment about j2's anchor of the weight of everything j2's body carries, and j2's lateral
// axes, in world coordinates, from the poses in d: summed here body by body from MuJoCo's masses
// and centres of mass (no statics, no effect model).
void MomentAtJ2(const mjModel* m, const mjData* d, Vec3* M, Vec3* a, Vec3* b) {
  const int j2 = mj_name2id(m, mjOBJ_JOINT, "j2");
  const int body = m->jnt_bodyid[j2];
  const Vec3 anchor(d->xanchor + 3 * j2);
  const Vec3 g(m->opt.gravity);
  *M = Vec3::Zero();
  for (int bi = 1; bi < m->nbody; ++bi) {
    int p = bi;
    while (p > 0 && p != body) p = m->body_parentid[p];
    if (p != body) continue;
    *M += (Vec3(d->xipos + 3 * bi) - anchor).cross(m->body_mass[bi] * g);
  }
  for (const auto& [name, out] : {std::pair{"j2_lateral_a", a}, std::pair{"j2_lateral_b", b}}) {
    *out = Vec3(d->xaxis + 3 * mj_name2id(m, mjOBJ_JOINT, name));
  }
}

// The same with the arm at command q and the hinges at their reference.
void NominalMoment(const mjModel* m, const Eigen::VectorXd& q, Vec3* M, Vec3* a, Vec3* b) {
  sim::MjDataPtr d = sim::MakeData(m);
  mju_copy(d->qpos, m->qpos0, m->nq);
  for (int k = 0; k < 4; ++k) {
    const int j = mj_name2id(m, mjOBJ_JOINT, ("j" + std::to_string(k + 1)).c_str());
    d->qpos[m->jnt_qposadr[j]] = q[k];
  }
  mj_kinematics(m, d.get());
  MomentAtJ2(m, d.get(), M, a, b);
}

// Each hinge holds the weight's moment about its axis at the settled pose (k theta = a . M, to
// the settle's tolerance); to first order that is the moment at the undeflected pose over k, what
// the identification's lateral_compliance assumes. The first order errs by the other hinge's
// turn moving the load (theta_b |r| |F| against the moment about a): stiffer hinges, smaller
// error.
TEST(LateralCompliance, StaticsBendTheHingesByTheWeightsMomentOverTheStiffness) {
  for (const double scale : {1.0, 5.0}) {
    const double ka = 900.0 * scale, kb = 1400.0 * scale;
    auto sim =
        sim::Simulation::FromString(kArm, "arm_lateral.xml",
                                    Lateral("{stiffness_Nm_per_rad: {j2: [" + std::to_string(ka) +
                                            ", " + std::to_string(kb) + "]}}"));
    std::mt19937_64 rng(7);
    double worst_exact = 0.0, worst_first = 0.0;
    for (int t = 0; t < 10; ++t) {
      const Eigen::VectorXd q = RandomCommand(rng);
      sim->SetCommand(q);
      sim->Settle();
      const double theta[2] = {sim->JointPosition("j2_lateral_a"),
                               sim->JointPosition("j2_lateral_b")};
      const double k[2] = {ka, kb};
      Vec3 M, a, b, M0, a0, b0;
      MomentAtJ2(sim->model(), sim->data(), &M, &a, &b);
      NominalMoment(sim->nominal_model(), q, &M0, &a0, &b0);
      for (int i = 0; i < 2; ++i) {
        const double exact = (i == 0 ? a : b).dot(M), first = (i == 0 ? a0 : b0).dot(M0) / k[i];
        EXPECT_NEAR(k[i] * theta[i], exact, 1e-8) << "trial " << t;
        EXPECT_GT(std::abs(theta[i]), 1e-5) << "trial " << t << ": the hinge did not bend";
        const double err = std::abs(theta[i] - first) / std::abs(first);
        worst_exact = std::max(worst_exact, std::abs(k[i] * theta[i] - exact));
        worst_first = std::max(worst_first, err);
        EXPECT_LT(err, 0.1 / scale) << "trial " << t << ": " << theta[i] << " vs " << first;
      }
    }
    std::printf(
        "k x %.0f: k theta vs the settled moment %.2g N m; theta vs nominal moment / k: "
        "worst %.3g relative\n",
        scale, worst_exact, worst_first);
  }
}

// Locked (the effect off) the hinges stay at their reference: the hand is where the same MJCF
// without the hinges puts it, to the last bits of a settle.
TEST(LateralCompliance, LockedHingesChangeNothing) {
  std::string plain = kArm;
  for (const char* line : {"<joint name=\"j2_lateral_a\" axis=\"1 0 0\"/>",
                           "<joint name=\"j2_lateral_b\" axis=\"0 0 -1\"/>"}) {
    plain.erase(plain.find(line), std::string(line).size());
  }
  auto with = sim::Simulation::FromString(kArm, "arm_lateral.xml");
  auto without = sim::Simulation::FromString(plain, "arm_plain.xml");
  std::mt19937_64 rng(8);
  for (int t = 0; t < 5; ++t) {
    const Eigen::VectorXd q = RandomCommand(rng);
    with->SetCommand(q);
    without->SetCommand(q);
    with->Settle();
    without->Settle();
    EXPECT_EQ(with->JointPosition("j2_lateral_a"), 0.0);
    EXPECT_EQ(with->JointPosition("j2_lateral_b"), 0.0);
    EXPECT_LT((with->Pose("ee").translation() - without->Pose("ee").translation()).norm(), 1e-12);
  }
  // The declared chain freezes them: no frame, the same chain as without the hinges.
  sim::MjModelPtr m_plain = sim::LoadModelFromString(plain, "arm_plain.xml");
  const sim::DeclaredChain a = sim::BuildDeclaredChain(with->nominal_model(), Declared());
  const sim::DeclaredChain b = sim::BuildDeclaredChain(m_plain.get(), Declared());
  ASSERT_EQ(a.model.num_frames(), b.model.num_frames());
  for (int f = 0; f < a.model.num_frames(); ++f) {
    EXPECT_EQ(a.model.frame(f).name, b.model.frame(f).name);
    EXPECT_TRUE(a.model.frame(f).T_parent_ip.translation() ==
                b.model.frame(f).T_parent_ip.translation());
  }
}

// Point rows of the truth (settled at random commands) with noise.
DataSet Rows(Rig& rig, int n, std::mt19937_64& rng) {
  std::normal_distribution<double> noise(0.0, kNoise);
  DataSet d;
  d.sets = {"s"};
  for (int r = 0; r < n; ++r) {
    Observation o;
    o.q = RandomCommand(rng);  // declared order j1..j4 = actuator order
    rig.sim->SetCommand(o.q);
    rig.sim->Settle();
    o.p_base = rig.sim->Pose("ee").translation() + Vec3(noise(rng), noise(rng), noise(rng));
    d.rows.push_back(o);
  }
  return d;
}

IdentifyResult IdentifyRows(const Rig& rig, const DataSet& cal) {
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  opt.threads = 1;
  return Identify(*rig.em, cal, ComputeLoads(*rig.em, cal), testing::NamedCandidates(*rig.em), opt);
}

const FittedEffect* Found(const IdentifyResult& r, const std::string& name) {
  for (const FittedEffect& e : r.effects) {
    for (const std::string& m : e.members) {
      if (m == name) return &e;
    }
  }
  return nullptr;
}

TEST(LateralCompliance, IdentificationNamesItAndRecoversTheCompliances) {
  const double k[2] = {2500.0, 4000.0};
  auto rig = MakeRig(Lateral("{stiffness_Nm_per_rad: {j2: [2500, 4000]}}"));
  const int seeds = 6;
  int named = 0, recovered = 0;
  for (int seed = 0; seed < seeds; ++seed) {
    std::mt19937_64 rng(100 + seed);
    const DataSet cal = Rows(*rig, 120, rng);
    const IdentifyResult res = IdentifyRows(*rig, cal);
    const FittedEffect* e = Found(res, "lateral_compliance@j2");
    std::printf("seed %d: %s\n", seed, testing::EffectNames(res).c_str());
    if (!e) continue;
    ++named;
    bool ok = true;
    for (int i = 0; i < 2; ++i) {
      const double truth = 1.0 / k[i], err = std::abs(e->value[i] - truth);
      std::printf("  kappa_%c %.4g (std %.2g) vs %.4g: %.2f%%, %.1f std\n", "ab"[i], e -> value[i],
                  e -> std[i], truth, 100 * err / truth, err / e -> std[i]);
      ok &= err <= 3.0 * e->std[i] || err <= 0.03 * truth;
    }
    recovered += ok;
  }
  std::printf("named %d of %d seeds, recovered %d\n", named, seeds, recovered);
  EXPECT_EQ(named, seeds);
  EXPECT_GE(recovered, seeds - 1);
}

TEST(LateralCompliance, NotChosenOnDataWithoutIt) {
  // Rigid, and with a gear compliance at j3 instead (a load-driven effect of another kind).
  for (const bool gear : {false, true}) {
    sim::EffectList effects;
    if (gear) {
      effects.push_back(sim::MakeEffect("joint_compliance", "{stiffness_Nm_per_rad: {j3: 800}}"));
    }
    auto rig = MakeRig(effects);
    for (int seed = 0; seed < 3; ++seed) {
      std::mt19937_64 rng(200 + seed);
      const IdentifyResult res = IdentifyRows(*rig, Rows(*rig, 120, rng));
      std::printf("%s, seed %d: %s\n", gear ? "gear at j3" : "rigid", seed,
                  testing::EffectNames(res).c_str());
      for (const FittedEffect& e : res.effects) {
        EXPECT_EQ(e.name.find("lateral_compliance"), std::string::npos) << e.name;
      }
      if (gear) EXPECT_NE(Found(res, "joint_compliance@j3"), nullptr);
    }
  }
}

// The declared model carrying the identified effect (what every estimator predicts with) equals
// the identification's model, with loads from the declared masses instead of MuJoCo's.
TEST(LateralCompliance, DeclaredModelPredictsAsTheIdentificationModel) {
  auto rig = MakeRig({});
  const EffectModel& em = *rig->em;
  const std::vector<std::pair<std::string, std::vector<double>>> effects = {
      {"lateral_compliance@j2", {4e-4, 2.5e-4}},
      {"lateral_compliance@j3", {3e-4, 6e-4}},
      {"joint_axis_tilt_a@j2", {0.01}}};
  sim::DeclaredModel aug = rig->declared;
  std::vector<int> active;
  std::vector<double> theta;
  for (const auto& [name, v] : effects) {
    aug.identified_effects.push_back({name, v, {}, "", "test:1", {}});
    active.push_back(em.FindCandidate(name));
    ASSERT_GE(active.back(), 0) << name;
    theta.insert(theta.end(), v.begin(), v.end());
  }
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->sim->nominal_model(), aug);
  kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
  kinematics::PpoeData pd(chain.model);
  EffectModel::Workspace ws = em.MakeWorkspace();
  std::mt19937_64 rng(9);
  double worst = 0.0, moved = 0.0;
  for (int t = 0; t < 20; ++t) {
    const Eigen::VectorXd q = 1.5 * RandomCommand(rng);
    kin.Update(q);
    kinematics::ForwardKinematics(kin.model(), pd, kin.q());
    const lie::SE3 expected = em.PredictPose(q, em.Loads(q), active, theta.data(), ws);
    const lie::SE3& got = pd.T_base_frame[chain.end_effector];
    worst = std::max({worst, (got.translation() - expected.translation()).norm(),
                      (got.rotation() - expected.rotation()).cwiseAbs().maxCoeff()});
    moved = std::max(moved, (em.PredictPose(q, em.Loads(q), {}, nullptr, ws).translation() -
                             expected.translation())
                                .norm());
  }
  std::printf("declared model vs identification model: %.3g (the effects move the hand %.3g m)\n",
              worst, moved);
  EXPECT_LT(worst, 1e-12);
  EXPECT_GT(moved, 1e-3);
}

// The analytic derivatives (EffectModel::PoseTangents) of lateral_compliance@j2 and @j3 equal
// central differences of PredictPose, with the family active itself, beside a tilt at the same
// joint and a payload (its share of the moment).
TEST(LateralCompliance, TangentsEqualCentralDifferences) {
  auto rig = MakeRig({});
  const EffectModel& em = *rig->em;
  const int lat2 = em.FindCandidate("lateral_compliance@j2");
  const int lat3 = em.FindCandidate("lateral_compliance@j3");
  const int tilt = em.FindCandidate("joint_axis_tilt_b@j2");
  const int payload = em.FindCandidate("payload@ee");
  ASSERT_TRUE(lat2 >= 0 && lat3 >= 0 && tilt >= 0 && payload >= 0);
  const std::vector<int> active = {lat2, tilt, payload};
  const std::vector<double> theta = {4e-4, 2e-4, 0.01, 1.2, 0.02, -0.01, 0.03};
  EffectModel::Workspace ws = em.MakeWorkspace();
  std::mt19937_64 rng(11);
  for (int t = 0; t < 10; ++t) {
    const Eigen::VectorXd q = 1.5 * RandomCommand(rng);
    const ConfigLoads L = em.Loads(q);
    for (const int c : {lat2, lat3}) {
      ASSERT_TRUE(em.HasTangent(c, active));
      EffectModel::Tangent tangent[2];
      em.PoseTangents(q, L, active, theta.data(), {c}, ws, tangent);
      std::vector<int> act = active;
      act.push_back(c);
      for (int k = 0; k < 2; ++k) {
        const double h = em.candidates()[c].step;
        std::vector<double> tp = theta, tm = theta;
        tp.insert(tp.end(), {0.0, 0.0});
        tm.insert(tm.end(), {0.0, 0.0});
        tp[theta.size() + k] += h;
        tm[theta.size() + k] -= h;
        const lie::SE3 Tp = em.PredictPose(q, L, act, tp.data(), ws);
        const lie::SE3 Tm = em.PredictPose(q, L, act, tm.data(), ws);
        const Vec3 dp = (Tp.translation() - Tm.translation()) / (2 * h);
        const Vec3 w = lie::SO3Log(Tp.rotation() * Tm.rotation().transpose()) / (2 * h);
        EXPECT_LT((tangent[k].dp - dp).norm(), 1e-7 * (1.0 + dp.norm())) << c << " " << k;
        EXPECT_LT((tangent[k].w - w).norm(), 1e-7 * (1.0 + w.norm())) << c << " " << k;
        EXPECT_GT(dp.norm(), 1e-3) << "a vacuous column";
      }
    }
  }
}

// What the augmented declared file says is what it was written from: lateral_compliance@J with
// its values and stds, read back into the same corrected chain; the stds become the joint
// frame's source, scaled by the moment at the reading.
TEST(LateralCompliance, AugmentedFileRoundTrips) {
  testing::TempDir tmp;
  testing::WriteFile(tmp.path() / "arm_lateral.xml", kArm);
  sim::DeclaredModel aug = Declared();
  aug.model_path = (tmp.path() / "arm_lateral.xml").string();
  aug.identified_effects = {
      {"lateral_compliance@j2", {4e-4, 2.5e-4}, {1e-5, 2e-5}, "rad/Nm", "test:1", {}}};
  testing::WriteFile(tmp.path() / "aug.declared.yaml", sim::EmitDeclaredModel(aug, "test", 17));
  const sim::DeclaredModel back =
      sim::LoadDeclaredModel((tmp.path() / "aug.declared.yaml").string());
  ASSERT_EQ(back.identified_effects.size(), 1u);
  EXPECT_EQ(back.identified_effects[0].effect, "lateral_compliance@j2");
  sim::MjModelPtr m = sim::LoadModel(aug.model_path);
  const sim::DeclaredChain a = sim::BuildDeclaredChain(m.get(), aug);
  const sim::DeclaredChain b = sim::BuildDeclaredChain(m.get(), back);
  kinematics::EffectiveChain ka(a.model, a.effects_or_null()), kb(b.model, b.effects_or_null());
  kinematics::PpoeData pa(a.model), pb(b.model);
  std::mt19937_64 rng(10);
  const FrameId f = a.model.joint_frame(a.QIndex("j2"));
  for (int t = 0; t < 5; ++t) {
    const Eigen::VectorXd q = RandomCommand(rng);
    ka.Update(q);
    kb.Update(q);
    kinematics::ForwardKinematics(ka.model(), pa, ka.q());
    kinematics::ForwardKinematics(kb.model(), pb, kb.q());
    EXPECT_LT((pa.T_base_frame[a.end_effector].translation() -
               pb.T_base_frame[b.end_effector].translation())
                  .norm(),
              1e-15);
    // The stds' share: rotation variance about a and b at j2's frame, std x moment.
    const Mat3 C = kb.model().frame(f).source_cov.block<3, 3>(kRotIdx, kRotIdx);
    EXPECT_GT(C.trace(), 0.0);
    EXPECT_LT(std::sqrt(C.trace()), 2e-5 * 50.0);
  }
}

TEST(LateralCompliance, NotOfferedAtACoupledJointNorAtTheMountAndListedAsSkipped) {
  sim::MjModelPtr m = sim::LoadModelFromString(kArm, "arm_lateral.xml");
  sim::DeclaredModel d = Declared();
  d.actuated_joints = {"j1", "j2", "j3"};
  sim::DeclaredCoupling c;
  c.joint = "j4";
  c.drivers = {{"j3", 0.5}};
  c.driver_where = {"test:2"};
  c.where = "test:1";
  d.coupled = {c};
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d, /*with_couplings=*/true);
  const EffectModel em(m.get(), chain, chain.end_effector);
  EXPECT_LT(em.FindCandidate("lateral_compliance@j4"), 0);
  EXPECT_GE(em.FindCandidate("lateral_compliance@j3"), 0);
  // And at j1, the arm's mount: its housing tilting is the mount's tilt.
  EXPECT_LT(em.FindCandidate("lateral_compliance@j1"), 0);
  EXPECT_GE(em.FindCandidate("base_compliance@j1"), 0);
  std::map<std::string, std::string> skipped;
  for (const EffectModel::Skipped& s : em.skipped()) skipped[s.name] = s.reason;
  ASSERT_EQ(skipped.size(), 2u);
  EXPECT_NE(skipped["lateral_compliance@j4"].find("coupled"), std::string::npos);
  EXPECT_NE(skipped["lateral_compliance@j1"].find("base_compliance@j1"), std::string::npos);
}

std::string InputErrorOf(const std::string& params) {
  try {
    sim::Simulation::FromString(kArm, "arm_lateral.xml", Lateral(params));
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(LateralComplianceBadInput, UnknownJointMissingHingesNegativeStiffness) {
  const std::string unknown = InputErrorOf("{stiffness_Nm_per_rad: {j9: 800}}");
  EXPECT_NE(unknown.find("no joint named 'j9'"), std::string::npos) << unknown;
  const std::string missing = InputErrorOf("{stiffness_Nm_per_rad: {j3: 800}}");
  for (const char* part :
       {"effect 'lateral_compliance'", "joint 'j3'", "'j3_lateral_a'", "'j3_lateral_b'"}) {
    EXPECT_NE(missing.find(part), std::string::npos) << missing;
  }
  for (const char* bad : {"{stiffness_Nm_per_rad: {j2: -5}}", "{stiffness_Nm_per_rad: {j2: [800]}}",
                          "{stiffness_Nm_per_rad: {j2: [800, 0]}}"}) {
    EXPECT_THROW(sim::MakeEffect("lateral_compliance", bad), InputError) << bad;
  }
  for (const std::string& m : {unknown, missing}) EXPECT_EQ(m.find('\n'), std::string::npos);
}

// Through the command line: one line naming the option and the joint, exit code 2.
TEST(LateralComplianceBadInput, CommandLineExitsTwoWithOneLine) {
  testing::TempDir tmp;
  for (const char* set : {"elbow=-5", "wrist_pitch=800", "nope=800"}) {
    const testing::CommandResult r =
        testing::RunCommand(testing::Flexbench() + " run " + testing::SourceDir() +
                            "/scenarios/closed_loop_humanoid_tracker.yaml --quiet --out " +
                            (tmp.path() / "out").string() +
                            " --set truth.effects.lateral_compliance.stiffness_Nm_per_rad." + set);
    EXPECT_EQ(r.exit_code, 2) << set << ": " << r.err;
    std::string err = r.err;
    while (!err.empty() && err.back() == '\n') err.pop_back();
    EXPECT_EQ(err.find('\n'), std::string::npos) << err;
    EXPECT_NE(err.find("lateral_compliance"), std::string::npos) << err;
  }
}

}  // namespace
}  // namespace flexbench::identify
