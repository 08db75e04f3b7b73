// The gravity direction (a base mounted tilted) as an identification candidate.
// The truth is MuJoCo: the rover arm with an undeclared gear elasticity at j2, its model's
// gravity turned 1.5-3 deg about a random horizontal axis (Eigen's AngleAxis, not the code under
// test), settled at random commands by sim::Simulation's statics; a tracker at an unknown pose
// sees the end effector. A tilt matters only through the loads (the tracker's pose absorbs any
// kinematic tilt), so gravity_tilt@base must be named beside the gear where gravity is tilted,
// and never where it is not.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "estimators/conventions.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "estimators/lie/so3.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/identify/problem.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/simulation.h"
#include "tests/common/identify_test_util.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

namespace fs = std::filesystem;

constexpr double kNoise = 1e-4;  // tracker noise per axis, m

struct Rig {
  std::unique_ptr<sim::Simulation> sim;
  sim::DeclaredModel declared;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;  // with the gravity_tilt candidate
};

// The truth's gravity turned by `tilt` (rad) about a horizontal axis at angle `heading` from x.
std::unique_ptr<Rig> MakeRig(double tilt, double heading, double stiffness = 800.0) {
  auto rig = std::make_unique<Rig>();
  const std::string dir = testing::SourceDir() + "/models/";
  sim::EffectList effects;
  if (stiffness > 0.0) {
    effects.push_back(sim::MakeEffect(
        "joint_compliance", "{stiffness_Nm_per_rad: {j2: " + std::to_string(stiffness) + "}}"));
  }
  rig->sim = sim::Simulation::Load(dir + "rover_arm.xml", effects);
  const Vec3 axis(std::cos(heading), std::sin(heading), 0.0);
  mjModel* m = rig->sim->mutable_model();
  const Vec3 g =
      Eigen::AngleAxisd(tilt, axis) * Vec3(m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]);
  for (int k = 0; k < 3; ++k) m->opt.gravity[k] = g[k];
  rig->declared = sim::LoadDeclaredModel(dir + "rover_arm.declared.yaml");
  rig->chain = sim::BuildDeclaredChain(rig->sim->nominal_model(), rig->declared);
  rig->em = std::make_unique<EffectModel>(rig->sim->nominal_model(), rig->chain,
                                          rig->chain.end_effector, "", std::vector<FrameId>{},
                                          /*gravity_tilt=*/true);
  return rig;
}

// `rows` settled configurations seen by a tracker at T_base_tracker with noise.
DataSet TrackerData(Rig& rig, const lie::SE3& T_base_tracker, int rows, std::mt19937_64& rng) {
  return testing::TrackerData(rig, T_base_tracker, rows, kNoise, rng);
}

lie::SE3 TrackerPose(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vec6 xi;
  for (int k = 0; k < 3; ++k) xi[k] = 0.05 * u(rng);
  for (int k = 3; k < 6; ++k) xi[k] = 5.0 * kDeg * u(rng);
  return lie::SE3::Exp(xi);
}

using testing::NamedCandidates;

bool Named(const IdentifyResult& r, const std::string& prefix) {
  for (const FittedEffect& e : r.effects) {
    if (e.name.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

double MeanError(const EffectModel& em, const DataSet& val, const Fit& fit) {
  const DataSet in_base = InBase(val, fit.T_base_frames);
  const auto loads = ComputeLoads(em, in_base, fit.active, fit.theta);
  const std::vector<double> e =
      RowErrors(in_base, PredictAll(em, in_base, loads, fit.active, fit.theta));
  double sum = 0.0;
  for (double v : e) sum += v;
  return sum / e.size();
}

struct Outcome {
  IdentifyResult res;
  double val_before = 0.0, val_after = 0.0;
  std::string verdict;
};

Outcome RunSeed(Rig& rig, int seed, const std::vector<std::string>& banned = {}) {
  std::mt19937_64 rng(3000 + seed);
  const lie::SE3 T_tracker = TrackerPose(rng);
  DataSet cal = TrackerData(rig, T_tracker, 90, rng);
  DataSet val = TrackerData(rig, T_tracker, 40, rng);
  const auto loads = ComputeLoads(*rig.em, cal);
  RegisterFrames(*rig.em, loads, &cal);
  val.frames = cal.frames;
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  Outcome out;
  out.res = Identify(*rig.em, cal, loads, NamedCandidates(*rig.em, banned), opt);
  // Validation rows in the frame at the calibration's fitted pose, as the closed_loop kind does.
  Fit before = out.res.before, after = out.res.after;
  out.val_before = MeanError(*rig.em, val, before);
  out.val_after = MeanError(*rig.em, val, after);
  out.verdict = Verdict(out.res, out.val_before, out.val_after);
  return out;
}

// The fitted tilt's value and std (rad), or false when gravity_tilt is not among the effects.
bool FittedTilt(const IdentifyResult& r, Eigen::Vector2d* value, Eigen::Vector2d* sd) {
  for (const FittedEffect& e : r.effects) {
    if (e.name.rfind("gravity_tilt@base", 0) != 0) continue;
    *value = Eigen::Vector2d(e.value[0], e.value[1]);
    *sd = Eigen::Vector2d(e.std[0], e.std[1]);
    return true;
  }
  return false;
}

// The tilted loads (three gravity directions combined with GravityTiltWeights) against MuJoCo's
// own gravity torque with the model's gravity turned: a gear compliance c at j2 under the tilt
// must predict the pose of j2 turned by c times MuJoCo's qfrc_bias there. And the declared
// model's identified gravity_tilt@base (what estimators use) predicts the same.
TEST(GravityTilt, TiltedLoadsAreMujocosGravityTorques) {
  auto rig = MakeRig(0.0, 0.0);
  const EffectModel& em = *rig->em;
  const mjModel* m = rig->sim->nominal_model();
  sim::MjModelPtr tilted(mj_copyModel(nullptr, m));
  sim::MjDataPtr d = sim::MakeData(tilted.get());
  const int c_gear = em.FindCandidate("joint_compliance@j2");
  const int c_tilt = em.FindCandidate("gravity_tilt@base");
  const int c_off = em.FindCandidate("joint_offset@j2");
  ASSERT_GE(c_tilt, 0);
  const int k2 = rig->chain.QIndex("j2");
  const int dof2 = m->jnt_dofadr[mj_name2id(m, mjOBJ_JOINT, "j2")];
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  EffectModel::Workspace ws = em.MakeWorkspace();
  double worst = 0.0, worst_aug = 0.0;
  for (int t = 0; t < 20; ++t) {
    Eigen::VectorXd q(rig->chain.model.nq());
    for (int k = 0; k < q.size(); ++k) q[k] = 1.5 * u(rng);
    const double phi1 = 5.0 * kDeg * u(rng), phi2 = 5.0 * kDeg * u(rng);
    // MuJoCo: gravity turned by the rotation vector (phi1, phi2, 0) (x, y: the base is world).
    const Vec3 g = Eigen::AngleAxisd(std::hypot(phi1, phi2), Vec3(phi1, phi2, 0.0).normalized()) *
                   Vec3(m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]);
    for (int k = 0; k < 3; ++k) tilted->opt.gravity[k] = g[k];
    mju_copy(d->qpos, m->qpos0, m->nq);
    rig->chain.WriteQpos(q, d->qpos);
    mju_zero(d->qvel, m->nv);
    mj_kinematics(tilted.get(), d.get());
    mj_comPos(tilted.get(), d.get());
    mj_rne(tilted.get(), d.get(), 0, d->qfrc_bias);
    const double tau = d->qfrc_bias[dof2];
    const double c = -2e-3;
    const ConfigLoads L = em.Loads(q);
    const double th[3] = {c, phi1, phi2};
    const Vec3 p = em.Predict(q, L, {c_gear, c_tilt}, th, ws);
    const double off = c * tau;
    const Vec3 p_ref = em.Predict(q, L, {c_off}, &off, ws);
    ASSERT_TRUE(p.allFinite() && p_ref.allFinite());
    // Without the tilt the gear's deflection differs by the tilt's share of the torque.
    const Vec3 p_level = em.Predict(q, L, {c_gear}, th, ws);
    if (t == 0) std::printf("without the tilt: %.3g m\n", (p_level - p_ref).norm());
    worst = std::max(worst, (p - p_ref).norm());
    // The augmented declared model.
    sim::DeclaredModel aug = rig->declared;
    aug.identified_effects = {{"joint_compliance@j2", {c}, {}, "rad/Nm", "t:1", {}},
                              {"gravity_tilt@base", {phi1, phi2}, {}, "rad", "t:2", {}}};
    const sim::DeclaredChain chain = sim::BuildDeclaredChain(m, aug);
    kinematics::EffectiveChain kin(chain.model, chain.effects_or_null());
    kin.Update(q);
    kinematics::PpoeData pd(chain.model);
    kinematics::ForwardKinematics(kin.model(), pd, kin.q());
    worst_aug = std::max(worst_aug, (pd.T_base_frame[chain.end_effector].translation() - p).norm());
    EXPECT_NEAR(kin.tau()[k2], tau, 1e-9 * (1.0 + std::abs(tau)));
  }
  std::printf("tilted loads vs MuJoCo: %.3g m; augmented model vs identification: %.3g m\n", worst,
              worst_aug);
  EXPECT_LT(worst, 1e-12);
  EXPECT_LT(worst_aug, 1e-9);
}

// The tilt's finite-difference columns against a difference of MuJoCo's torques: with a gear
// compliance c at j2 active, d p / d phi_k = (d p / d q2) c d tau_MuJoCo / d phi_k.
TEST(GravityTilt, ColumnsMatchMujocosTorqueDerivative) {
  auto rig = MakeRig(0.0, 0.0);
  const EffectModel& em = *rig->em;
  const mjModel* m = rig->sim->nominal_model();
  sim::MjModelPtr tilted(mj_copyModel(nullptr, m));
  sim::MjDataPtr d = sim::MakeData(tilted.get());
  const int dof2 = m->jnt_dofadr[mj_name2id(m, mjOBJ_JOINT, "j2")];
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  DataSet data;
  data.sets = {"s"};
  for (int r = 0; r < 8; ++r) {
    Observation o;
    o.q.resize(rig->chain.model.nq());
    for (int k = 0; k < o.q.size(); ++k) o.q[k] = 1.5 * u(rng);
    data.rows.push_back(o);
  }
  const auto loads = ComputeLoads(em, data);
  const double c = -2e-3;
  const std::vector<int> active = {em.FindCandidate("joint_compliance@j2")};
  IdentifyOptions opt;
  opt.point_std_m = 1.0;  // whitened residuals in metres
  const Problem pr(em, data, loads, active, {}, opt);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(pr.num_params());
  x[0] = c;
  const Eigen::MatrixXd J = pr.CandidateColumns(x, em.FindCandidate("gravity_tilt@base"));
  const Eigen::MatrixXd J_q2 = pr.CandidateColumns(x, em.FindCandidate("joint_offset@j2"));
  const auto tau = [&](const Eigen::VectorXd& q, const Vec3& rot) {
    const Vec3 g = lie::SO3Exp(rot) * Vec3(m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]);
    for (int k = 0; k < 3; ++k) tilted->opt.gravity[k] = g[k];
    mju_copy(d->qpos, m->qpos0, m->nq);
    rig->chain.WriteQpos(q, d->qpos);
    mju_zero(d->qvel, m->nv);
    mj_kinematics(tilted.get(), d.get());
    mj_comPos(tilted.get(), d.get());
    mj_rne(tilted.get(), d.get(), 0, d->qfrc_bias);
    return d->qfrc_bias[dof2];
  };
  double worst = 0.0, scale = 0.0;
  for (int k = 0; k < 2; ++k) {
    for (size_t r = 0; r < data.rows.size(); ++r) {
      const double h = 1e-5;
      const double dtau =
          (tau(data.rows[r].q, h * Vec3::Unit(k)) - tau(data.rows[r].q, -h * Vec3::Unit(k))) /
          (2 * h);
      const Eigen::Vector3d ref = J_q2.block<3, 1>(3 * r, 0) * c * dtau;
      worst = std::max(worst, (J.block<3, 1>(3 * r, k) - ref).norm());
      scale = std::max(scale, ref.norm());
    }
  }
  std::printf("gravity_tilt columns vs MuJoCo: %.3g (largest column entry %.3g)\n", worst, scale);
  EXPECT_GT(scale, 1e-4);
  EXPECT_LT(worst, 1e-6 * scale);
}

// Tilted truth: the gear and the tilt are named, the tilt recovered within its reported
// uncertainty, the validation error lowered.
TEST(GravityTilt, NamedBesideTheGearWhenTheBaseIsTiltedOverSeeds) {
  const int kSeeds = 10;
  int named = 0, gear = 0, within = 0, reduced = 0;
  double sum_nees = 0.0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    std::mt19937_64 rng(100 + seed);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    const double tilt = (1.5 + 1.5 * u(rng)) * kDeg, heading = 2.0 * M_PI * u(rng);
    auto rig = MakeRig(tilt, heading);
    const Outcome o = RunSeed(*rig, seed);
    gear += Named(o.res, "joint_compliance@j2");
    Eigen::Vector2d v, sd;
    const bool has = FittedTilt(o.res, &v, &sd);
    named += has;
    // The rotation vector of the truth's tilt: tilt about (cos h, sin h, 0) = (x, y) axes.
    const Eigen::Vector2d truth(tilt * std::cos(heading), tilt * std::sin(heading));
    double sigmas = -1.0;
    if (has) {
      sigmas = std::max(std::abs(v[0] - truth[0]) / sd[0], std::abs(v[1] - truth[1]) / sd[1]);
      within += sigmas < 3.0;
      sum_nees += std::pow((v[0] - truth[0]) / sd[0], 2) + std::pow((v[1] - truth[1]) / sd[1], 2);
    }
    reduced += o.val_after < 0.3 * o.val_before;
    std::printf(
        "tilted %.2f deg, seed %d: %s (%s); tilt (%.3f, %.3f) deg vs true (%.3f, %.3f), %.2f "
        "sigma; validation %.3g -> %.3g mm\n",
        tilt / kDeg, seed, testing::EffectNames(o.res).c_str(), o.verdict.c_str(),
        has ? v[0] / kDeg : 0.0, has ? v[1] / kDeg : 0.0, truth[0] / kDeg, truth[1] / kDeg, sigmas,
        o.val_before * 1e3, o.val_after * 1e3);
    std::printf("  left: %s\n", o.res.finding.message.c_str());
  }
  std::printf(
      "tilted base: gravity_tilt named %d/%d, gear named %d/%d, tilt within 3 sigma %d/%d (mean "
      "NEES %.2f of 2), validation < 0.3x %d/%d\n",
      named, kSeeds, gear, kSeeds, within, kSeeds, named ? sum_nees / named : 0.0, reduced, kSeeds);
  EXPECT_EQ(named, kSeeds);
  EXPECT_EQ(gear, kSeeds);
  EXPECT_GE(within, kSeeds - 1);
  EXPECT_EQ(reduced, kSeeds);
}

// Level truth: the tilt is never named (the gear is).
TEST(GravityTilt, NotNamedWhenGravityIsNotTiltedOverSeeds) {
  const int kSeeds = 10;
  auto rig = MakeRig(0.0, 0.0);
  int tilt = 0, gear = 0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    const Outcome o = RunSeed(*rig, 50 + seed);
    tilt += Named(o.res, "gravity_tilt");
    gear += Named(o.res, "joint_compliance@j2");
    std::printf("level, seed %d: %s (%s), validation %.3g -> %.3g mm; %s\n", 50 + seed,
                testing::EffectNames(o.res).c_str(), o.verdict.c_str(), o.val_before * 1e3,
                o.val_after * 1e3, o.res.finding.message.c_str());
  }
  std::printf("level base: gravity_tilt named %d/%d, gear named %d/%d\n", tilt, kSeeds, gear,
              kSeeds);
  EXPECT_EQ(tilt, 0);
  EXPECT_EQ(gear, kSeeds);
}

// A tilt alone, with no compliance in the truth: nothing carries the load, so neither the tilt
// nor any load-driven effect may be named (the tracker's pose absorbs the tilted kinematics).
TEST(GravityTilt, ATiltWithoutCompliancesIsNotNamed) {
  const int kSeeds = 10;
  int named = 0, none = 0, loaded = 0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    auto rig = MakeRig(3.0 * kDeg, 0.7 * seed, /*stiffness=*/0.0);
    const Outcome o = RunSeed(*rig, 200 + seed);
    named += Named(o.res, "gravity_tilt");
    none += o.res.effects.empty();
    for (const char* f : {"joint_compliance", "link_bending", "base_compliance", "backlash",
                          "payload", "stiffening_spring"}) {
      loaded += Named(o.res, f);
    }
    std::printf("rigid, seed %d: %s (%s)\n", 200 + seed, testing::EffectNames(o.res).c_str(),
                o.verdict.c_str());
  }
  std::printf(
      "tilt without compliance: gravity_tilt named %d/%d, a load-driven effect named %d/%d, "
      "nothing named %d/%d\n",
      named, kSeeds, loaded, kSeeds, none, kSeeds);
  EXPECT_EQ(named, 0);
  EXPECT_EQ(loaded, 0);
}

// A load path the library is denied (the truth's gear at j2, with the gear, bending, spring and
// backlash families taken out): the tilt must not stand in for it, and the verdict must not say
// "explained".
TEST(GravityTilt, AnUnknownLoadPathIsNotPassedOffAsATilt) {
  const int kSeeds = 5;
  const std::vector<std::string> banned = {"joint_compliance", "link_bending", "stiffening_spring",
                                           "backlash"};
  int tilt_named = 0, explained = 0;
  for (int level = 0; level < 2; ++level) {
    for (int seed = 0; seed < kSeeds; ++seed) {
      auto rig = MakeRig(level ? 0.0 : 2.0 * kDeg, 1.1 * seed);
      const Outcome o = RunSeed(*rig, 300 + seed, banned);
      tilt_named += level == 1 && Named(o.res, "gravity_tilt");
      explained += o.verdict == "explained";
      std::printf("gear denied, %s, seed %d: %s (%s), validation %.3g -> %.3g mm\n",
                  level ? "level" : "tilted 2 deg", 300 + seed, testing::EffectNames(o.res).c_str(),
                  o.verdict.c_str(), o.val_before * 1e3, o.val_after * 1e3);
    }
  }
  std::printf(
      "gear denied: gravity_tilt named on a level base %d/%d, verdict explained %d/%d runs\n",
      tilt_named, kSeeds, explained, 2 * kSeeds);
  EXPECT_EQ(tilt_named, 0);
  EXPECT_EQ(explained, 0);
}

// The closed_loop kind end to end: tracker rows in CSV files (every declared joint, x, y, z,
// frame) of the tilted truth; with `frames:` the tilt is a candidate by default, is named, goes
// into declared_augmented.yaml, and that file loads as an estimator's model; `gravity_tilt:
// false` leaves it out of the library.
TEST(GravityTilt, ClosedLoopScenarioNamesItAndWritesItOut) {
  auto rig = MakeRig(2.5 * kDeg, 0.6);
  std::mt19937_64 rng(11);
  const lie::SE3 T_tracker = TrackerPose(rng);
  testing::TempDir dir;
  const auto write = [&](const DataSet& d, const std::string& name) {
    std::string csv;
    for (const std::string& j : rig->chain.q_joints) csv += j + ",";
    csv += "x,y,z,frame\n";
    char b[64];
    for (const Observation& o : d.rows) {
      for (int k = 0; k < o.q.size(); ++k) {
        std::snprintf(b, sizeof(b), "%.17g,", o.q[k]);
        csv += b;
      }
      for (int k = 0; k < 3; ++k) {
        std::snprintf(b, sizeof(b), "%.17g,", o.p_frame[k]);
        csv += b;
      }
      csv += "tracker\n";
    }
    testing::WriteFile(dir.path() / name, csv);
  };
  write(TrackerData(*rig, T_tracker, 90, rng), "cal.csv");
  write(TrackerData(*rig, T_tracker, 40, rng), "val.csv");
  const std::string models = testing::SourceDir() + "/models/";
  testing::WriteFile(dir.path() / "s.yaml", "scenario: tilt\nkind: closed_loop\nseed: 1\nmodel: " +
                                                models + "rover_arm.xml\ndeclared: " + models +
                                                "rover_arm.declared.yaml\nframes:\n  tracker: "
                                                "{}\ncalibration: {csv: cal.csv}\nvalidation: "
                                                "{csv: val.csv}\npoint_std_m: 1.0e-4\n");
  const auto run = [&](const std::string& extra, const std::string& out) {
    return testing::RunCommand(testing::BinDir() + "/flexbench run " +
                               (dir.path() / "s.yaml").string() + " --out " +
                               (dir.path() / out).string() + " --quiet " + extra);
  };
  const testing::CommandResult r = run("", "out");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string summary = testing::ReadFile(dir.path() / "out" / "summary.json");
  EXPECT_NE(summary.find("\"effect\": \"gravity_tilt@base\""), std::string::npos);
  const fs::path aug = dir.path() / "out" / "declared_augmented.yaml";
  EXPECT_NE(testing::ReadFile(aug).find("- effect: gravity_tilt@base"), std::string::npos);
  const sim::DeclaredModel d = sim::LoadDeclaredModel(aug.string());
  const sim::MjModelPtr m = sim::LoadModel(d.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d);
  EXPECT_GT(std::hypot(chain.effects.g_base.x(), chain.effects.g_base.y()), 0.2);  // ~2.5 deg
  // Same seed, same bytes, whatever the number of threads.
  const testing::CommandResult one = run("--set threads=1", "out_1");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  nlohmann::json a = nlohmann::json::parse(summary), b = nlohmann::json::parse(testing::ReadFile(
                                                         dir.path() / "out_1" / "summary.json"));
  EXPECT_EQ(a["metrics"], b["metrics"]);
  EXPECT_EQ(a["identification"], b["identification"]);
  EXPECT_EQ(testing::ReadFile(aug),
            testing::ReadFile(dir.path() / "out_1" / "declared_augmented.yaml"));
  const testing::CommandResult off = run("--set gravity_tilt=false", "out_off");
  ASSERT_EQ(off.exit_code, 0) << off.err;
  EXPECT_EQ(testing::ReadFile(dir.path() / "out_off" / "summary.json").find("gravity_tilt@base"),
            std::string::npos);
}

}  // namespace
}  // namespace flexbench::identify
