// The augmented declared model is the estimators' model: for every candidate effect
// of the identification, a declared model carrying it as an identified effect predicts the end
// effector exactly as the identification's own model does (1e-9), with loads from the declared
// masses instead of MuJoCo's; every registered estimator predicts with it; bad effects are
// input errors naming the file and line.
#include <gtest/gtest.h>

#include <random>

#include "estimators/error.h"
#include "estimators/estimator.h"
#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "scenarios/identify/effect_model.h"
#include "sim/declared_chain.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

// A 4-joint arm with masses, a tool offset and no declared source ahead of j1: its mount is j1.
constexpr char kArm4[] = R"(
<mujoco model="arm4">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1"/>
      <geom type="cylinder" size="0.05 0.05" mass="2"/>
      <body name="upper" pos="0 0 0.1">
        <joint name="j2" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="3"/>
        <body name="fore" pos="0.4 0 0" quat="0.99 0 0.1 0.05">
          <joint name="j3" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0.35 0 0" size="0.025" mass="2"/>
          <body name="wrist" pos="0.35 0 0">
            <joint name="j4" axis="1 0 0"/>
            <geom type="box" size="0.03 0.03 0.03" pos="0.03 0 0.01" mass="0.7"/>
            <site name="ee" pos="0.08 0.01 0.02"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>)";

struct Rig {
  sim::MjModelPtr owned;
  const mjModel* m = nullptr;
  sim::DeclaredModel declared;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
};

std::unique_ptr<Rig> MakeRig(const std::string& which) {
  auto r = std::make_unique<Rig>();
  if (which == "arm4") {
    r->owned = sim::LoadModelFromString(kArm4, "arm4.xml");
    r->declared.file = "arm4.declared.yaml";
    r->declared.model_path = "arm4.xml";
    r->declared.actuated_joints = {"j1", "j2", "j3", "j4"};
    r->declared.end_effector = "ee";
  } else {
    r->declared =
        sim::LoadDeclaredModel(testing::SourceDir() + "/models/" + which + ".declared.yaml");
    r->owned = sim::LoadModel(r->declared.model_path);
  }
  r->m = r->owned.get();
  r->chain = sim::BuildDeclaredChain(r->m, r->declared);
  r->em = std::make_unique<EffectModel>(r->m, r->chain, r->chain.end_effector);
  return r;
}

// Parameters of a candidate of realistic size and physical sign.
std::vector<double> Values(const Candidate& c, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<double> v(c.num_params);
  for (int k = 0; k < c.num_params; ++k) {
    double scale = 0.01;  // rad
    switch (c.type) {
      case EffectType::kLinkLength:
      case EffectType::kLinkOffset:
        scale = 0.005;
        break;
      case EffectType::kJointCompliance:
      case EffectType::kLinkBending:
      case EffectType::kBaseCompliance:
      case EffectType::kStiffeningSpring:
      case EffectType::kLateralCompliance:
        scale = 2e-3;
        break;
      case EffectType::kThermalExpansion:
        scale = 4e-4;
        break;
      case EffectType::kPayload:
        scale = k == 0 ? 1.5 : 0.05;
        break;
      case EffectType::kJointOrigin:
        scale = k < 3 ? 0.004 : 0.01;
        break;
      default:
        break;
    }
    v[k] = scale * n(rng);
  }
  // Signs the bounds keep (a gear spring gives way, plates and links sag, mass is positive).
  if (c.type == EffectType::kJointCompliance) v[0] = -std::abs(v[0]);
  if (c.type == EffectType::kStiffeningSpring) v[0] = -std::abs(v[0]), v[1] = std::abs(v[1]);
  if (c.type == EffectType::kLinkBending) v[0] = std::abs(v[0]);
  if (c.type == EffectType::kBaseCompliance) v[0] = std::abs(v[0]), v[1] = std::abs(v[1]);
  if (c.type == EffectType::kPayload) v[0] = std::abs(v[0]);
  if (c.type == EffectType::kLateralCompliance) v[0] = std::abs(v[0]), v[1] = std::abs(v[1]);
  return v;
}

// Configurations: the reference, a small step from it, random ones (a fixed seed).
std::vector<Eigen::VectorXd> Configurations(int nq, std::mt19937_64& rng) {
  std::vector<Eigen::VectorXd> qs = {Eigen::VectorXd::Zero(nq),
                                     Eigen::VectorXd::Constant(nq, 1e-3)};
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (int t = 0; t < 6; ++t) {
    Eigen::VectorXd q(nq);
    for (int k = 0; k < nq; ++k) q[k] = u(rng);
    qs.push_back(q);
  }
  return qs;
}

// The pose the corrected declared model gives (what every estimator's kinematics uses).
lie::SE3 AugmentedPose(const sim::DeclaredChain& chain, const Eigen::VectorXd& q) {
  kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
  kin.Update(q);
  kinematics::PpoeData data(chain.model);
  kinematics::ForwardKinematics(kin.model(), data, kin.q());
  return data.T_base_frame[chain.end_effector];
}

void ExpectSamePose(const lie::SE3& a, const lie::SE3& b, const std::string& what) {
  EXPECT_LT((a.translation() - b.translation()).norm(), 1e-9) << what;
  EXPECT_LT((a.rotation() - b.rotation()).cwiseAbs().maxCoeff(), 1e-9) << what;
}

class AugmentedModel : public ::testing::TestWithParam<std::string> {};

TEST_P(AugmentedModel, EachEffectPredictsAsTheIdentificationModel) {
  const auto rig = MakeRig(GetParam());
  std::mt19937_64 rng(15);
  const std::vector<Eigen::VectorXd> qs = Configurations(rig->chain.model.nq(), rng);
  EffectModel::Workspace ws = rig->em->MakeWorkspace();
  int tested = 0;
  for (size_t i = 0; i < rig->em->candidates().size(); ++i) {
    const Candidate& c = rig->em->candidates()[i];
    const std::vector<double> v = Values(c, rng);
    sim::DeclaredModel aug = rig->declared;
    aug.identified_effects.push_back({c.Name(), v, {}, c.unit, "test:1", {}});
    const sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->m, aug);
    // A payload alone moves nothing (it loads compliances that are not there).
    if (c.type != EffectType::kPayload) {
      ASSERT_NE(chain.effects_or_null(), nullptr) << c.Name();
    }
    for (const Eigen::VectorXd& q : qs) {
      const lie::SE3 expected =
          rig->em->PredictPose(q, rig->em->Loads(q), {static_cast<int>(i)}, v.data(), ws);
      ExpectSamePose(AugmentedPose(chain, q), expected, c.Name());
    }
    ++tested;
  }
  EXPECT_GE(tested, 20);
}

TEST_P(AugmentedModel, AllEffectsAtOnce) {
  const auto rig = MakeRig(GetParam());
  std::mt19937_64 rng(16);
  sim::DeclaredModel aug = rig->declared;
  std::vector<int> active;
  std::vector<double> theta;
  for (size_t i = 0; i < rig->em->candidates().size(); ++i) {
    const Candidate& c = rig->em->candidates()[i];
    const std::vector<double> v = Values(c, rng);
    aug.identified_effects.push_back({c.Name(), v, {}, c.unit, "test:1", {}});
    active.push_back(static_cast<int>(i));
    theta.insert(theta.end(), v.begin(), v.end());
  }
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->m, aug);
  EffectModel::Workspace ws = rig->em->MakeWorkspace();
  for (const Eigen::VectorXd& q : Configurations(chain.model.nq(), rng)) {
    const lie::SE3 expected = rig->em->PredictPose(q, rig->em->LoadsFor(q, active, theta.data()),
                                                   active, theta.data(), ws);
    ExpectSamePose(AugmentedPose(chain, q), expected, "all effects");
    // The correction is not nothing: the declared chain alone is millimetres away.
    kinematics::PpoeData plain(chain.model);
    kinematics::ForwardKinematics(chain.model, plain, q);
    EXPECT_GT(
        (plain.T_base_frame[chain.end_effector].translation() - expected.translation()).norm(),
        1e-3);
  }
}

// The fitted parameters' stds (identified_effects' `std`) become sources whose covariance at the
// end effector matches Monte Carlo through the identification's own model: values drawn from
// N(value, std^2), poses from EffectModel::PredictPose (code other than EffectiveChain's).
// Declared sources are removed first so that only the parameters' uncertainty is compared.
TEST_P(AugmentedModel, ParameterStdsMatchMonteCarloThroughTheIdentificationModel) {
  const auto rig = MakeRig(GetParam());
  std::mt19937_64 rng(17);
  std::normal_distribution<double> n(0.0, 1.0);
  EffectModel::Workspace ws = rig->em->MakeWorkspace();
  int compared = 0;
  for (size_t i = 0; i < rig->em->candidates().size(); ++i) {
    const Candidate& c = rig->em->candidates()[i];
    if (c.type == EffectType::kPayload) continue;  // its uncertainty is not carried
    const std::vector<double> v = Values(c, rng);
    std::vector<double> sd(v.size());
    for (size_t k = 0; k < v.size(); ++k) sd[k] = 0.2 * std::abs(v[k]);
    sim::DeclaredModel aug = rig->declared;
    aug.identified_effects.push_back({c.Name(), v, sd, c.unit, "test:1", {}});
    sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->m, aug);
    for (kinematics::FrameId f = 1; f < chain.model.num_frames(); ++f) {
      chain.model.SetSourceCovariance(f, Mat6::Zero());
    }
    std::uniform_real_distribution<double> u(-1.2, 1.2);
    for (int t = 0; t < 2; ++t) {
      Eigen::VectorXd q(chain.model.nq());
      for (int k = 0; k < q.size(); ++k) q[k] = u(rng);
      kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
      kin.Update(q);
      kinematics::PpoeData data(chain.model);
      kinematics::ForwardKinematicsWithCovariance(kin.model(), data, kin.q(),
                                                  lie::CompoundOrder::kSecond);
      const Mat6 Sigma = data.Sigma_frame[chain.end_effector];
      const auto loads = rig->em->Loads(q);
      const lie::SE3 T0 = rig->em->PredictPose(q, loads, {static_cast<int>(i)}, v.data(), ws);
      const int samples = 10000;
      Mat6 mc = Mat6::Zero();
      std::vector<double> vs(v.size());
      for (int s = 0; s < samples; ++s) {
        for (size_t k = 0; k < v.size(); ++k) vs[k] = v[k] + sd[k] * n(rng);
        const Vec6 xi =
            T0.Between(rig->em->PredictPose(q, loads, {static_cast<int>(i)}, vs.data(), ws)).Log();
        mc += xi * xi.transpose() / samples;
      }
      const double scale = std::max(mc.cwiseAbs().maxCoeff(), Sigma.cwiseAbs().maxCoeff());
      if (scale < 1e-18) continue;  // acts off the end effector's path (a camera's offset)
      EXPECT_LT((mc - Sigma).cwiseAbs().maxCoeff(), 0.06 * scale) << c.Name() << "\nMonte Carlo\n"
                                                                  << mc << "\nsources\n"
                                                                  << Sigma;
      ++compared;
    }
  }
  EXPECT_GE(compared, 30);
}

INSTANTIATE_TEST_SUITE_P(Arms, AugmentedModel, ::testing::Values("arm4", "rover_arm"));

// Every row of the effect table has its maths in both layers: the identification offers it as a
// candidate (on rover_arm, with its mast camera and gravity's tilt) with the row's value count,
// unit and bounds, its values move the pose the identification predicts, and a declared file
// holding it builds a chain that predicts the same. A row added without its maths fails to
// build (its kind lacks its cases in the switches of effect_model.cc and declared_effects.cc)
// or fails here (no candidate, or cases that move nothing or disagree). The camera's offset moves
// the camera, not the hand; a row entering through the loads (a payload, gravity's tilt) acts only
// through the load-driven terms (here with j2's gear), and any other load-driven row makes the
// estimators' chain compute the loads.
TEST(EffectTable, EveryRowHasItsMaths) {
  const auto rig = MakeRig("rover_arm");
  EffectModel em(rig->m, rig->chain, rig->chain.end_effector, "mast_camera", {}, true);
  std::mt19937_64 rng(16);
  const std::vector<Eigen::VectorXd> qs = Configurations(rig->chain.model.nq(), rng);
  EffectModel::Workspace ws = em.MakeWorkspace();
  const int gear = em.FindCandidate("joint_compliance@j2");
  ASSERT_GE(gear, 0);
  for (int kind = 0; kind < kinematics::kNumEffectKinds; ++kind) {
    const kinematics::EffectRow& row = kinematics::EffectTable()[kind];
    SCOPED_TRACE(row.name);
    ASSERT_EQ(static_cast<int>(row.kind), kind);
    ASSERT_EQ(kinematics::Row(row.kind).name, row.name);
    int offered = 0;
    double moved = 0.0;
    for (size_t c = 0; c < em.candidates().size(); ++c) {
      const Candidate& cand = em.candidates()[c];
      if (static_cast<int>(cand.type) != kind) continue;
      ++offered;
      // Its value count, unit and bounds are the row's (a slide's where the row has them).
      EXPECT_EQ(cand.num_params, row.num_values);
      const bool slide = row.slide_unit != nullptr && cand.unit == row.slide_unit;
      EXPECT_EQ(cand.unit, slide ? row.slide_unit : row.unit);
      ASSERT_EQ(cand.lower.size(), static_cast<size_t>(row.num_values));
      ASSERT_EQ(cand.upper.size(), static_cast<size_t>(row.num_values));
      for (int k = 0; k < row.num_values; ++k) {
        EXPECT_EQ(cand.lower[k], slide ? -row.slide_bound : row.lower[k]);
        EXPECT_EQ(cand.upper[k], slide ? row.slide_bound : row.upper[k]);
      }
      if (row.kind == kinematics::EffectKind::kCameraOffset) continue;
      const bool through_loads = row.enters == kinematics::EffectEntry::kLoads;
      std::vector<int> set = {static_cast<int>(c)};
      std::vector<double> v = Values(cand, rng);
      sim::DeclaredModel aug = rig->declared;
      aug.identified_effects.push_back({cand.Name(), v, {}, cand.unit, "test:1", {}});
      const std::vector<int> base = through_loads ? std::vector<int>{gear} : std::vector<int>{};
      const std::vector<double> base_v = {-2e-3};
      if (through_loads) {
        set.push_back(gear);
        v.push_back(base_v[0]);
        aug.identified_effects.push_back(
            {"joint_compliance@j2", base_v, {}, "rad/Nm", "test:2", {}});
      }
      const sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->m, aug);
      // The estimators' chain computes the loads for the terms of a load-driven row.
      if (!through_loads) EXPECT_EQ(chain.effects.NeedsLoads(), row.load_driven);
      for (const Eigen::VectorXd& q : qs) {
        const lie::SE3 with = em.PredictPose(q, em.Loads(q), set, v.data(), ws);
        const lie::SE3 without = em.PredictPose(q, em.Loads(q), base, base_v.data(), ws);
        moved = std::max(moved, (with.translation() - without.translation()).norm());
        ExpectSamePose(AugmentedPose(chain, q), with, cand.Name());
      }
    }
    EXPECT_GT(offered, 0) << "no candidate offers it";
    for (int k = 0; k < row.num_values; ++k) EXPECT_LE(row.lower[k], row.upper[k]);
    if (row.kind == kinematics::EffectKind::kCameraOffset) continue;
    EXPECT_GT(moved, 1e-6) << "its values do not move the hand";
  }
}

// Every registered estimator, given the effects, believes what the same estimator believes
// without them when handed the corrected model and joint angles directly.
TEST(AugmentedModelEstimators, EveryEstimatorPredictsWithTheCorrectedModel) {
  const auto rig = MakeRig("arm4");
  sim::DeclaredModel aug = rig->declared;
  aug.identified_effects = {
      {"joint_offset@j2", {0.02}, {}, "rad", "t:1", {}},
      {"joint_compliance@j3", {-0.004}, {}, "rad/Nm", "t:2", {}},
      {"link_bending@j3", {0.003}, {}, "rad/Nm", "t:3", {}},
      {"base_compliance@j1", {0.002, 0.003}, {}, "rad/Nm", "t:4", {}},
      {"link_offset@ee", {0.004, -0.003, 0.002}, {}, "m", "t:5", {}},
      {"lateral_compliance@j2", {0.002, 0.001}, {}, "rad/Nm", "t:6", {}},
  };
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->m, aug);
  const Eigen::VectorXd q = (Eigen::VectorXd(4) << 0.3, -0.6, 0.9, 0.2).finished();
  kinematics::EffectiveChain kin(chain.model, &chain.effects);
  kin.Update(q);
  ASSERT_TRUE(kin.varies());
  const kinematics::PpoeModel corrected = kin.model();  // a plain model: the snapshot
  estimators::JointReading with_effects, direct;
  with_effects.q = q;
  direct.q = kin.q();
  with_effects.std = direct.std = estimators::JointVector::Constant(4, 1e-3);
  int covered = 0;
  for (const estimators::EstimatorEntry& e : estimators::EstimatorRegistry()) {
    estimators::EstimatorSetup a, b;
    a.model = &chain.model;
    a.effects = &chain.effects;
    b.model = &corrected;
    a.end_effector = b.end_effector = chain.end_effector;
    a.seed = b.seed = 7;
    if (std::string(e.name) == "naive_ekf") {
      a.params = b.params =
          estimators::Params({{"std_trans_m", {0.01, 0.01, 0.01}}, {"std_rot_deg", {1, 1, 1}}});
    }
    std::unique_ptr<estimators::Estimator> ea, eb;
    try {
      ea = e.make(a);
      eb = e.make(b);
    } catch (const InputError&) {
      continue;  // needs a sensor this rig has not (IMUs)
    }
    ea->Predict(0.0);
    eb->Predict(0.0);
    ASSERT_EQ(ea->Update(with_effects), eb->Update(direct)) << e.name;
    const estimators::Belief ba = ea->Estimate(), bb = eb->Estimate();
    ExpectSamePose(ba.T_base_ee, bb.T_base_ee, e.name);
    EXPECT_LT((ba.cov - bb.cov).cwiseAbs().maxCoeff(), 1e-12) << e.name;
    ASSERT_EQ(ba.q.size(), 4) << e.name;
    EXPECT_LT((ba.q - bb.q).cwiseAbs().maxCoeff(), 1e-12) << e.name;
    ++covered;
  }
  EXPECT_GE(covered, 5);  // fk, both EKFs, the particle filters without IMUs
}

// The fk estimator with the effects predicts exactly what the identification predicts.
TEST(AugmentedModelEstimators, FkEqualsTheIdentificationPrediction) {
  const auto rig = MakeRig("rover_arm");
  sim::DeclaredModel aug = rig->declared;
  aug.identified_effects = {
      {"joint_offset@j3", {-0.01}, {}, "rad", "t:1", {}},
      {"base_compliance@base_plate", {0.001, 0.0005}, {}, "rad/Nm", "t:2", {}},
      {"lateral_compliance@j3", {4e-4, 3e-4}, {}, "rad/Nm", "t:3", {}}};
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(rig->m, aug);
  estimators::EstimatorSetup s;
  s.model = &chain.model;
  s.effects = chain.effects_or_null();
  s.end_effector = chain.end_effector;
  auto fk = estimators::MakeEstimator("fk", s);
  std::mt19937_64 rng(5);
  EffectModel::Workspace ws = rig->em->MakeWorkspace();
  const std::vector<int> active = {rig->em->FindCandidate("joint_offset@j3"),
                                   rig->em->FindCandidate("base_compliance@base_plate"),
                                   rig->em->FindCandidate("lateral_compliance@j3")};
  ASSERT_GE(active[0], 0);
  ASSERT_GE(active[1], 0);
  ASSERT_GE(active[2], 0);
  const double theta[] = {-0.01, 0.001, 0.0005, 4e-4, 3e-4};
  for (const Eigen::VectorXd& q : Configurations(chain.model.nq(), rng)) {
    estimators::JointReading z;
    z.q = q;
    z.std = estimators::JointVector::Constant(q.size(), 1e-3);
    ASSERT_EQ(fk->Update(z), estimators::UpdateStatus::kAccepted);
    ExpectSamePose(fk->Estimate().T_base_ee,
                   rig->em->PredictPose(q, rig->em->LoadsFor(q, active, theta), active, theta, ws),
                   "fk");
  }
}

std::string ErrorOf(const Rig& rig, const sim::IdentifiedEffect& e) {
  sim::DeclaredModel aug = rig.declared;
  aug.identified_effects = {e};
  try {
    sim::BuildDeclaredChain(rig.m, aug);
  } catch (const InputError& err) {
    return err.what();
  }
  return "";
}

TEST(AugmentedModelBadInput, NamesTheFileLineAndEffect) {
  const auto rig = MakeRig("arm4");
  const auto has = [](const std::string& msg, const std::string& part) {
    return msg.find(part) != std::string::npos;
  };
  std::string e = ErrorOf(*rig, {"joint_offset@j9", {0.01}, {}, "rad", "aug.yaml:7", {}});
  EXPECT_TRUE(has(e, "aug.yaml:7") && has(e, "joint_offset@j9") && has(e, "'j9'")) << e;
  e = ErrorOf(*rig, {"link_offset@nowhere", {0, 0, 0}, {}, "m", "aug.yaml:8", {}});
  EXPECT_TRUE(has(e, "aug.yaml:8") && has(e, "nowhere")) << e;
  e = ErrorOf(*rig, {"link_offset@ee", {0.1, 0.2}, {}, "m", "aug.yaml:9", {}});
  EXPECT_TRUE(has(e, "aug.yaml:9") && has(e, "needs 3 values, got 2")) << e;
  e = ErrorOf(*rig, {"joint_offset@j2", {std::nan("")}, {}, "rad", "aug.yaml:10", {}});
  EXPECT_TRUE(has(e, "aug.yaml:10") && has(e, "finite")) << e;
  e = ErrorOf(*rig, {"warp_drive@j2", {1}, {}, "", "aug.yaml:11", {}});
  EXPECT_TRUE(has(e, "aug.yaml:11") && has(e, "not a known effect type")) << e;
  e = ErrorOf(*rig, {"base_compliance@j2", {0.001, 0.001}, {}, "rad/Nm", "aug.yaml:12", {}});
  EXPECT_TRUE(has(e, "aug.yaml:12") && has(e, "mount")) << e;
  e = ErrorOf(*rig, {"link_bending@j1", {0.001}, {}, "rad/Nm", "aug.yaml:13", {}});
  EXPECT_TRUE(has(e, "aug.yaml:13") && has(e, "5 cm")) << e;
  e = ErrorOf(*rig, {"joint_offset", {0.01}, {}, "rad", "aug.yaml:14", {}});
  EXPECT_TRUE(has(e, "aug.yaml:14") && has(e, "type@location")) << e;

  // A load-driven effect on a model without masses (MuJoCo insists on a little: 2 g, as a URDF
  // without inertials gets).
  constexpr char kMassless[] = R"(
<mujoco model="massless">
  <worldbody>
    <body name="a" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="0.001" diaginertia="1e-6 1e-6 1e-6"/>
      <body name="b" pos="0.3 0 0">
        <joint name="j2" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="0.001" diaginertia="1e-6 1e-6 1e-6"/>
        <site name="ee" pos="0.3 0 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>)";
  Rig bare;
  bare.owned = sim::LoadModelFromString(kMassless, "massless.xml");
  bare.m = bare.owned.get();
  bare.declared.file = "massless.declared.yaml";
  bare.declared.model_path = "massless.xml";
  bare.declared.actuated_joints = {"j1", "j2"};
  bare.declared.end_effector = "ee";
  e = ErrorOf(bare, {"joint_compliance@j2", {-0.001}, {}, "rad/Nm", "aug.yaml:15", {}});
  EXPECT_TRUE(has(e, "aug.yaml:15") && has(e, "no masses")) << e;
  // Geometry needs no masses.
  EXPECT_EQ(ErrorOf(bare, {"joint_offset@j2", {0.01}, {}, "rad", "aug.yaml:16", {}}), "");
}

// A declared file's NaN and wrong-length values are caught when the file is read.
TEST(AugmentedModelBadInput, DeclaredFileValues) {
  testing::TempDir dir;
  const std::string model = testing::SourceDir() + "/models/rover_arm.xml";
  const auto error_of = [&](const std::string& effect_lines) {
    const auto path = dir.path() / "aug.declared.yaml";
    testing::WriteFile(path, "model: " + model +
                                 "\nactuated_joints: [j1, j2, j3, j4, j5, j6]\nend_effector: ee\n"
                                 "identified_effects:\n" +
                                 effect_lines);
    try {
      const sim::DeclaredModel d = sim::LoadDeclaredModel(path.string());
      auto m = sim::LoadModel(d.model_path);
      sim::BuildDeclaredChain(m.get(), d);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  std::string e = error_of("  - {effect: joint_offset@j2, value: [.nan]}\n");
  EXPECT_NE(e.find("aug.declared.yaml:"), std::string::npos) << e;
  EXPECT_NE(e.find("value"), std::string::npos) << e;
  e = error_of("  - {effect: joint_offset@j2, value: [0.01, 0.02]}\n");
  EXPECT_NE(e.find("aug.declared.yaml:5"), std::string::npos) << e;
  EXPECT_NE(e.find("needs 1 values, got 2"), std::string::npos) << e;
  EXPECT_EQ(error_of("  - {effect: joint_offset@j2, value: [0.01]}\n"), "");
}

}  // namespace
}  // namespace flexbench::identify
