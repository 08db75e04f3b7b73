// Points measured by an external tracker at an unknown (or roughly known) pose. The
// truth is MuJoCo: the rover arm with an undeclared gear elasticity at j2, settled at random
// commands (sim::Simulation, not the identification's kinematics); its end-effector points are
// mapped into a tracker frame a few cm and deg off the base and given noise. Identification fits
// the tracker's pose jointly with the effects: it must name the gear, recover the pose within its
// reported uncertainty, and lower the validation error; the same data read as base-frame points
// (the old format) gives a wrong answer.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>

#include "estimators/error.h"
#include "estimators/lie/so3.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/identify/problem.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/simulation.h"
#include "tests/common/identify_test_util.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

namespace fs = std::filesystem;

constexpr double kNoise = 1e-4;  // tracker noise per axis, m

// The truth (MuJoCo with the gear elasticity) and the declared model's effect kinematics.
struct Rig {
  std::unique_ptr<sim::Simulation> sim;
  sim::DeclaredModel declared;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
};

std::unique_ptr<Rig> MakeRig() {
  auto rig = std::make_unique<Rig>();
  const std::string dir = testing::SourceDir() + "/models/";
  sim::EffectList effects;
  effects.push_back(sim::MakeEffect("joint_compliance", "{stiffness_Nm_per_rad: {j2: 800}}"));
  rig->sim = sim::Simulation::Load(dir + "rover_arm.xml", effects);
  rig->declared = sim::LoadDeclaredModel(dir + "rover_arm.declared.yaml");
  rig->chain = sim::BuildDeclaredChain(rig->sim->nominal_model(), rig->declared);
  rig->em =
      std::make_unique<EffectModel>(rig->sim->nominal_model(), rig->chain, rig->chain.end_effector);
  return rig;
}

// A pose a few cm and a few degrees from `T`.
lie::SE3 Perturbed(const lie::SE3& T, double metres, double degrees, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vec6 xi;
  for (int k = 0; k < 3; ++k) xi[k] = metres * u(rng);
  for (int k = 3; k < 6; ++k) xi[k] = degrees * M_PI / 180.0 * u(rng);
  return T * lie::SE3::Exp(xi);
}

// The helpers' tracker data at this suite's noise.
DataSet TrackerData(Rig& rig, const lie::SE3& T_base_tracker, int rows, std::mt19937_64& rng,
                    const Vec3& d_marker = Vec3::Zero()) {
  return testing::TrackerData(rig, T_base_tracker, rows, kNoise, rng, d_marker);
}

using testing::NamedCandidates;

std::vector<std::string> Names(const IdentifyResult& r) {
  std::vector<std::string> found;
  for (const FittedEffect& e : r.effects) found.push_back(e.name);
  std::sort(found.begin(), found.end());
  return found;
}

// Mean distance between measured and predicted points of `val` (its frames at `T_frames`).
double MeanError(const EffectModel& em, const DataSet& val, const Fit& fit,
                 const std::vector<lie::SE3>& T_frames) {
  const DataSet in_base = InBase(val, T_frames);
  const auto loads = ComputeLoads(em, in_base, fit.active, fit.theta);
  const std::vector<Vec3> p = PredictAll(em, in_base, loads, fit.active, fit.theta);
  const std::vector<double> e = RowErrors(in_base, p);
  double sum = 0.0;
  for (double v : e) sum += v;
  return sum / e.size();
}

struct Outcome {
  bool named = false;
  bool within_3_sigma = false;
  bool val_reduced = false;
  double max_sigmas = 0.0;
  double nees = 0.0;  // e^T C^-1 e of the pose error e in xi, C the reported covariance
};

// How often each claim held over the seeds of one test.
struct Tally {
  int seeds = 0, named = 0, within = 0, reduced = 0;
  double nees_sum = 0.0;
  void Add(const Outcome& o) {
    ++seeds;
    named += o.named;
    within += o.within_3_sigma;
    reduced += o.val_reduced;
    nees_sum += o.nees;
  }
  double MeanNees() const { return nees_sum / seeds; }
  void Print(const char* what) const {
    std::printf(
        "%s: effect named %d/%d, pose within 3 sigma %d/%d, validation < 0.3x %d/%d, mean pose "
        "NEES %.2f (of 6)\n",
        what, named, seeds, within, seeds, reduced, seeds, MeanNees());
  }
};

// Identification of one seed's data with the tracker declared as `frame` (its T_ref, guess and
// prior); the recovered pose is compared with the truth in the fit's own parametrisation
// (xi = Log(T_ref^-1 T)).
Outcome RunSeed(Rig& rig, int seed, const MeasurementFrame& frame_template,
                const lie::SE3& T_base_tracker) {
  std::mt19937_64 rng(1000 + seed);
  DataSet cal = TrackerData(rig, T_base_tracker, 90, rng);
  DataSet val = TrackerData(rig, T_base_tracker, 40, rng);
  MeasurementFrame frame = frame_template;
  frame.name = "tracker";
  cal.frames = {frame};
  const auto cal_loads = ComputeLoads(*rig.em, cal);
  RegisterFrames(*rig.em, cal_loads, &cal);
  val.frames = cal.frames;
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  const IdentifyResult res = Identify(*rig.em, cal, cal_loads, NamedCandidates(*rig.em), opt);
  // The oracle: the same rows mapped into the base frame with the true pose (no nuisance).
  DataSet oracle = InBase(cal, {T_base_tracker});
  oracle.frames.clear();
  const IdentifyResult res_oracle =
      Identify(*rig.em, oracle, cal_loads, NamedCandidates(*rig.em), opt);
  Outcome out;
  // One effect, the gear's (named with the candidates this data cannot tell from it: on the
  // rover arm a bend of the short link below j2 acts like j2's gear, with or without a tracker),
  // and what the exact registration names.
  out.named = Names(res).size() == 1 && Names(res)[0].rfind("joint_compliance@j2", 0) == 0 &&
              Names(res) == Names(res_oracle);
  std::printf("oracle (true pose, base frame) finds %s\n",
              Names(res_oracle).empty() ? "-" : Names(res_oracle)[0].c_str());
  const Vec6 xi_true = (cal.frames[0].T_ref.Inverse() * T_base_tracker).Log();
  const Vec6 xi_fit = (cal.frames[0].T_ref.Inverse() * res.after.T_base_frames[0]).Log();
  for (int k = 0; k < 6; ++k) {
    const double sigma = std::sqrt(res.frame_cov[0](k, k));
    out.max_sigmas = std::max(out.max_sigmas, std::abs(xi_fit[k] - xi_true[k]) / sigma);
  }
  out.within_3_sigma = out.max_sigmas < 3.0;
  const Vec6 e = xi_fit - xi_true;
  out.nees = e.dot(res.frame_cov[0].ldlt().solve(e));
  const double before = MeanError(*rig.em, val, res.before, res.before.T_base_frames);
  const double after = MeanError(*rig.em, val, res.after, res.after.T_base_frames);
  out.val_reduced = after < 0.3 * before;
  std::printf("seed %d: found %s, tracker pose within %.2f sigma, validation %.3g -> %.3g mm\n",
              seed, Names(res).empty() ? "-" : Names(res)[0].c_str(), out.max_sigmas, before * 1e3,
              after * 1e3);
  for (const std::string& u : res.unidentifiable) std::printf("  unidentifiable: %s\n", u.c_str());
  return out;
}

// The tracker's pose in the base frame: a few cm and deg off a nominal mounting.
lie::SE3 TruePose(int seed) {
  std::mt19937_64 rng(seed);
  const lie::SE3 nominal(Mat3::Identity(), Vec3(0.0, 0.0, 0.0));
  return Perturbed(nominal, 0.05, 5.0, rng);
}

TEST(TrackerFrame, UnknownPoseIsFittedWithTheGearElasticityOverSeeds) {
  auto rig = MakeRig();
  Tally t;
  for (int seed = 0; seed < 20; ++seed) {
    t.Add(RunSeed(*rig, seed, MeasurementFrame{}, TruePose(seed)));
  }
  t.Print("unknown tracker");
  // The reported covariance is neither optimistic nor pessimistic: 20 runs' mean of a 6-dof
  // chi-square lies in [4.05, 8.41] with 99.5% probability (Wilson-Hilferty).
  EXPECT_GT(t.MeanNees(), 4.05);
  EXPECT_LT(t.MeanNees(), 8.41);
  EXPECT_EQ(t.named, t.seeds);
  EXPECT_EQ(t.reduced, t.seeds);
  EXPECT_GE(t.within, t.seeds - 2);  // 6 components at 3 sigma: ~1.6% of runs have one beyond
}

// The backward step refits only removals whose linearised rise of the sum of squares
// (RemovalRises: the Schur complement of the others, here with the tracker's pose among them)
// could pass BIC's test even at half its size. On MuJoCo's rows the refit's rise is that
// linearised rise to within a few percent, for the gear that explains most of the data and
// for effects that explain noise, so half of it leaves room to spare.
TEST(TrackerFrame, LinearisedRemovalRisesMatchRefits) {
  auto rig = MakeRig();
  const EffectModel& em = *rig->em;
  std::mt19937_64 rng(77);
  DataSet cal = TrackerData(*rig, TruePose(3), 90, rng);
  const auto loads = ComputeLoads(em, cal);
  RegisterFrames(em, loads, &cal);
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  std::vector<int> active;
  for (const char* name : {"joint_compliance@j2", "joint_offset@j3", "link_bending@j3",
                           "joint_axis_tilt_a@j4", "link_offset@j5"}) {
    active.push_back(em.FindCandidate(name));
    ASSERT_GE(active.back(), 0) << name;
  }
  const Fit fit = FitEffects(em, cal, loads, active, Eigen::VectorXd(), opt);
  const Problem pr(em, cal, loads, fit.active, fit.basis, opt);
  const std::vector<double> rises = RemovalRises(pr, fit);
  ASSERT_EQ(rises.size(), active.size());
  double largest = 0.0;
  for (size_t e = 0; e < active.size(); ++e) {
    const double refit = FitWithout(em, cal, loads, fit, e, opt).rss - fit.rss;
    std::printf("%s: linearised rise %.6g, refitted %.6g\n",
                em.candidates()[active[e]].Name().c_str(), rises[e], refit);
    ASSERT_TRUE(std::isfinite(rises[e]));
    EXPECT_GE(refit, 0.5 * rises[e]);  // what the backward step relies on
    EXPECT_NEAR(refit, rises[e], 0.05 * std::max(refit, rises[e]) + 1e-3);
    largest = std::max(largest, refit);
  }
  EXPECT_GT(largest, 1e3);  // not vacuous: the gear's removal costs the fit much
}

TEST(TrackerFrame, PoseKnownWithinAPriorGivesTheSame) {
  auto rig = MakeRig();
  Tally t;
  for (int seed = 0; seed < 10; ++seed) {
    const lie::SE3 T_true = TruePose(seed);
    // The stated pose is off the truth by about its stated uncertainty, 5 mm and 0.5 deg.
    std::mt19937_64 rng(77 + seed);
    std::normal_distribution<double> n(0.0, 1.0);
    Vec6 e;
    for (int k = 0; k < 3; ++k) e[k] = 0.005 * n(rng);
    for (int k = 3; k < 6; ++k) e[k] = 0.5 * M_PI / 180.0 * n(rng);
    MeasurementFrame prior;
    prior.T_ref = T_true * lie::SE3::Exp(-e);
    prior.has_guess = prior.has_prior = true;
    prior.prior_std_m = 0.005;
    prior.prior_std_rad = 0.5 * M_PI / 180.0;
    t.Add(RunSeed(*rig, seed, prior, T_true));
  }
  t.Print("tracker with prior");
  EXPECT_EQ(t.named, t.seeds);
  EXPECT_EQ(t.reduced, t.seeds);
  EXPECT_GE(t.within, t.seeds - 1);
}

// A marker 2-3 cm off the declared end effector (where it was stuck on), its offset unknown:
// 3 nuisance parameters beside the tracker's 6. The tool's link_offset candidate is then
// absorbed (reported unidentifiable); the gear is still named, the offset and pose recovered.
// Declared (offset_unknown off), the same data makes link_offset@ee an effect.
TEST(MarkerOffset, UnknownOffsetIsFittedWithTheTrackerAndTheGear) {
  auto rig = MakeRig();
  const int kSeeds = 5;
  int named = 0, within = 0, reduced = 0, absorbed = 0, declared_picks_tool = 0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    std::mt19937_64 rng(700 + seed);
    std::uniform_real_distribution<double> u(-0.03, 0.03);
    const Vec3 d_true(u(rng), u(rng), u(rng));
    const lie::SE3 T_true = TruePose(seed);
    DataSet cal = TrackerData(*rig, T_true, 90, rng, d_true);
    DataSet val = TrackerData(*rig, T_true, 40, rng, d_true);
    cal.points = val.points = {"ee"};
    cal.offset_unknown = val.offset_unknown = {1};
    const auto loads = ComputeLoads(*rig->em, cal);
    RegisterFrames(*rig->em, loads, &cal);
    val.frames = cal.frames;
    IdentifyOptions opt;
    opt.point_std_m = kNoise;
    const IdentifyResult res = Identify(*rig->em, cal, loads, NamedCandidates(*rig->em), opt);
    const std::vector<std::string> found = Names(res);
    const bool ok = found.size() == 1 && found[0].rfind("joint_compliance@j2", 0) == 0;
    named += ok;
    for (size_t k = 0; k < 4 && k < res.steps.size() && !ok; ++k) {
      std::printf("  %s\n", res.steps[k].c_str());
    }
    absorbed += std::count(res.unidentifiable.begin(), res.unidentifiable.end(), "link_offset@ee");
    double worst = 0.0;
    for (int k = 0; k < 3; ++k) {
      worst = std::max(worst, std::abs(res.after.marker_offsets[0][k] - d_true[k]) /
                                  std::sqrt(res.marker_offset_cov[0](k, k)));
    }
    const Vec6 e = (cal.frames[0].T_ref.Inverse() * res.after.T_base_frames[0]).Log() -
                   (cal.frames[0].T_ref.Inverse() * T_true).Log();
    for (int k = 0; k < 6; ++k)
      worst = std::max(worst, std::abs(e[k]) / std::sqrt(res.frame_cov[0](k, k)));
    within += worst < 3.0;
    const auto val_error = [&](const Fit& fit) {
      const DataSet vb = InBase(val, fit.T_base_frames);
      const auto L = ComputeLoads(*rig->em, vb, fit.active, fit.theta);
      const std::vector<double> err = RowErrors(vb, PredictMarkers(*rig->em, vb, L, fit));
      double sum = 0.0;
      for (double v : err) sum += v;
      return sum / err.size();
    };
    const double before = val_error(res.before), after = val_error(res.after);
    reduced += after < 0.3 * before;
    // Declared offset: the same rows.
    DataSet declared = cal;
    declared.offset_unknown.clear();
    const IdentifyResult res_d =
        Identify(*rig->em, declared, loads, NamedCandidates(*rig->em), opt);
    for (const std::string& n : Names(res_d))
      declared_picks_tool += n.find("link_offset@ee") != std::string::npos;
    std::printf(
        "marker offset, seed %d: found %s, offset and pose within %.2f sigma, validation "
        "%.3g -> %.3g mm; declared offset finds %zu effects\n",
        seed, found.empty() ? "-" : found[0].c_str(), worst, before * 1e3, after * 1e3,
        Names(res_d).size());
  }
  std::printf(
      "unknown marker offset: gear named %d/%d, tool absorbed %d/%d, within 3 sigma "
      "%d/%d, validation < 0.3x %d/%d; declared offset chose link_offset@ee %d/%d\n",
      named, kSeeds, absorbed, kSeeds, within, kSeeds, reduced, kSeeds, declared_picks_tool,
      kSeeds);
  // Measured: 4/5; on seed 703 backlash@j2 joins the compliance (BIC -13, held-out 1.19 ->
  // 1.11: MuJoCo's statics beyond the linear gear), the compliance still chosen first.
  EXPECT_GE(named, kSeeds - 1);
  EXPECT_EQ(absorbed, kSeeds);
  EXPECT_EQ(reduced, kSeeds);
  EXPECT_GE(within, kSeeds - 1);
  EXPECT_EQ(declared_picks_tool, kSeeds);  // without the nuisance the offset is an "effect"
}

// With many rows every stage goes by blocks of rows (normal equations, screening, equivalences,
// covariances: from the triangular factor of their columns). With the tracker's pose and the
// marker's offset among the unknowns, small blocks find what the rows whole do.
TEST(TrackerFrame, RowBlocksFitWhatTheWholeRowsDo) {
  auto rig = MakeRig();
  std::mt19937_64 rng(91);
  const lie::SE3 T_true = TruePose(3);
  DataSet cal = TrackerData(*rig, T_true, 90, rng, Vec3(0.02, -0.01, 0.015));
  cal.points = {"ee"};
  cal.offset_unknown = {1};
  const auto loads = ComputeLoads(*rig->em, cal);
  RegisterFrames(*rig->em, loads, &cal);
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  const IdentifyResult whole = Identify(*rig->em, cal, loads, NamedCandidates(*rig->em), opt);
  opt.row_block = 20;  // four blocks
  ASSERT_TRUE(Problem(*rig->em, cal, loads, {}, {}, opt).InRowBlocks());
  const IdentifyResult blocks = Identify(*rig->em, cal, loads, NamedCandidates(*rig->em), opt);
  ASSERT_EQ(Names(blocks), Names(whole));
  ASSERT_FALSE(Names(whole).empty());
  EXPECT_LT((blocks.after.theta - whole.after.theta).norm(), 1e-8 * whole.after.theta.norm());
  const Vec6 d_pose =
      (whole.after.T_base_frames[0].Inverse() * blocks.after.T_base_frames[0]).Log();
  EXPECT_LT(d_pose.norm(), 1e-9);
  EXPECT_LT((blocks.after.marker_offsets[0] - whole.after.marker_offsets[0]).norm(), 1e-9);
  EXPECT_LT((blocks.frame_cov[0] - whole.frame_cov[0]).norm(), 1e-6 * whole.frame_cov[0].norm());
  EXPECT_LT((blocks.marker_offset_cov[0] - whole.marker_offset_cov[0]).norm(),
            1e-6 * whole.marker_offset_cov[0].norm());
  EXPECT_LT((blocks.theta_cov - whole.theta_cov).norm(), 1e-6 * whole.theta_cov.norm());
  EXPECT_EQ(blocks.unidentifiable, whole.unidentifiable);
  EXPECT_NE(std::count(whole.unidentifiable.begin(), whole.unidentifiable.end(), "link_offset@ee"),
            0);
  EXPECT_NEAR(blocks.overlap, whole.overlap, 1e-9);
  ASSERT_EQ(blocks.equivalence.size(), whole.equivalence.size());
  for (size_t e = 0; e < whole.equivalence.size(); ++e) {
    EXPECT_EQ(blocks.equivalence[e].name, whole.equivalence[e].name);
  }
  std::printf("found %s; %zu unidentifiable\n", Names(whole)[0].c_str(),
              whole.unidentifiable.size());
}

// A rough guess (5 cm and 5 deg off the truth) instead of the registration as the start.
TEST(TrackerFrame, ARoughGuessStartsTheSameJointFit) {
  auto rig = MakeRig();
  Tally t;
  for (int seed = 0; seed < 5; ++seed) {
    std::mt19937_64 rng(500 + seed);
    MeasurementFrame guess;
    guess.T_ref = Perturbed(TruePose(seed), 0.05, 5.0, rng);
    guess.has_guess = true;
    t.Add(RunSeed(*rig, seed, guess, TruePose(seed)));
  }
  t.Print("rough guess");
  EXPECT_EQ(t.named, t.seeds);
  EXPECT_EQ(t.reduced, t.seeds);
  EXPECT_GE(t.within, t.seeds - 1);
}

// The same data read as base-frame points (the format without frames; the tracker taken to sit
// at the base, the user's rough guess): the registration error is reported as effects.
TEST(TrackerFrame, WithoutTheFrameTheSameDataGivesAWrongAnswer) {
  auto rig = MakeRig();
  std::mt19937_64 rng(1000);
  DataSet cal = TrackerData(*rig, TruePose(0), 90, rng);
  for (Observation& o : cal.rows) {
    o.p_base = o.p_frame;
    o.frame = -1;
  }
  cal.frames.clear();
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  const IdentifyResult res =
      Identify(*rig->em, cal, ComputeLoads(*rig->em, cal), NamedCandidates(*rig->em), opt);
  for (const std::string& n : Names(res)) std::printf("found without the frame: %s\n", n.c_str());
  EXPECT_NE(Names(res), std::vector<std::string>{"joint_compliance@j2"});
}

// An effect the tracker's pose absorbs (the whole arm shifted or turned about the first axis)
// is reported unidentifiable, never chosen, when the tracker's pose is unknown.
TEST(TrackerFrame, AnEffectTheRegistrationAbsorbsIsReportedNotChosen) {
  auto rig = MakeRig();
  std::mt19937_64 rng(5);
  DataSet cal = TrackerData(*rig, TruePose(3), 90, rng);
  const auto loads = ComputeLoads(*rig->em, cal);
  RegisterFrames(*rig->em, loads, &cal);
  IdentifyOptions opt;
  opt.point_std_m = kNoise;
  const IdentifyResult res = Identify(*rig->em, cal, loads, NamedCandidates(*rig->em), opt);
  EXPECT_NE(std::find(res.unidentifiable.begin(), res.unidentifiable.end(), "joint_offset@j1"),
            res.unidentifiable.end());
  EXPECT_NE(std::find(res.unidentifiable.begin(), res.unidentifiable.end(), "link_offset@j1"),
            res.unidentifiable.end());
}

// The frame and marker-offset columns of the Jacobian (points and poses, with a prior), and an
// effect's analytic column with the offset's lever, against central differences in x.
TEST(TrackerFrame, FrameJacobianMatchesDifferences) {
  auto rig = MakeRig();
  std::mt19937_64 rng(9);
  DataSet d = TrackerData(*rig, TruePose(1), 6, rng);
  for (size_t r = 0; r < 3; ++r) {
    d.rows[r].type = ObservationType::kPose;
    d.rows[r].R_frame = lie::SO3Exp(Vec3(0.3, -0.2, 0.1 * r));
  }
  d.points = {"ee"};
  d.offset_unknown = {1};
  d.frames[0].T_ref = Perturbed(TruePose(1), 0.01, 1.0, rng);
  d.frames[0].has_prior = true;
  d.frames[0].prior_std_m = 0.005;
  d.frames[0].prior_std_rad = 0.01;
  const auto loads = ComputeLoads(*rig->em, d);
  const std::vector<int> active = {rig->em->FindCandidate("joint_compliance@j2")};
  IdentifyOptions opt;
  const Problem pr(*rig->em, d, loads, active, {}, opt);
  Eigen::VectorXd x(pr.num_params());
  x << -1e-3, 0.02, -0.01, 0.03, 0.05, -0.04, 0.02, 0.01, -0.02, 0.015;
  const Eigen::MatrixXd J = pr.Jacobian(x);
  for (int k = pr.frame_col(0); k < pr.num_params(); ++k) {
    Eigen::VectorXd xp = x, xm = x;
    xp[k] += 1e-6;
    xm[k] -= 1e-6;
    const Eigen::VectorXd col = (pr.Residuals(xp) - pr.Residuals(xm)) / 2e-6;
    EXPECT_LT((J.col(k) - col).norm(), 1e-5 * (1.0 + col.norm())) << "column " << k;
  }
  // The effect's analytic column with the pose rows measured in the frame.
  Eigen::VectorXd xp = x, xm = x;
  xp[0] += 1e-7;
  xm[0] -= 1e-7;
  const Eigen::VectorXd col = (pr.Residuals(xp) - pr.Residuals(xm)) / 2e-7;
  EXPECT_LT((J.col(0) - col).norm(), 1e-4 * (1.0 + col.norm()));
}

// Bad input: a row naming an undeclared frame, a declared frame no row uses, a prior with a
// non-positive standard deviation; one line naming the file, key or column, and line.
TEST(TrackerFrame, BadInputIsOneLineNamingFileKeyAndLine) {
  const fs::path dir = fs::temp_directory_path() / ("flexbench_tf_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  DataSet d;
  MeasurementFrame t;
  t.name = "tracker";
  t.where = "s.yaml:4";
  d.frames = {t};
  testing::WriteFile(dir / "a.csv", "j1,x,y,z,frame\n0,1,2,3,base\n0,1,2,3,laser\n");
  try {
    ReadCalibrationCsv((dir / "a.csv").string(), {"j1"}, &d);
    ADD_FAILURE() << "accepted an undeclared frame";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("a.csv:3: column 'frame': 'laser' is not a declared"),
              std::string::npos)
        << e.what();
  }
  DataSet u;
  u.frames = {t};
  testing::WriteFile(dir / "b.csv", "j1,x,y,z,frame\n0,1,2,3,base\n");
  ReadCalibrationCsv((dir / "b.csv").string(), {"j1"}, &u);
  try {
    CheckFramesUsed(u, "calibration");
    ADD_FAILURE() << "accepted an unused frame";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("s.yaml:4: frame 'tracker' is declared but no"),
              std::string::npos)
        << e.what();
  }
  DataSet m;
  m.points = {"l_hand", "r_hand"};
  testing::WriteFile(dir / "m.csv", "j1,x,y,z,marker\n0,1,2,3,r_hand\n0,1,2,3,l_foot\n");
  try {
    ReadCalibrationCsv((dir / "m.csv").string(), {"j1"}, &m);
    ADD_FAILURE() << "accepted a marker the model lacks";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("m.csv:3: column 'marker': 'l_foot' is not a measured"),
              std::string::npos)
        << e.what();
  }
  testing::WriteFile(dir / "c.csv", "j1,group,frame\n0,g,tracker\n");
  DataSet g;
  g.frames = {t};
  EXPECT_THROW(ReadCalibrationCsv((dir / "c.csv").string(), {"j1"}, &g), InputError);
  for (const char* bad : {"prior_std_m: 0", "prior_std_m: -1", "prior_std_m: .nan"}) {
    const std::string yaml = std::string(
                                 "frames:\n  tracker:\n    T_base_frame: [0, 0, 0, 1, 0, "
                                 "0, 0]\n    prior_std_deg: 0.5\n    ") +
                             bad + "\n";
    const ConfigNode root = ConfigNode::LoadString(yaml, "s.yaml");
    try {
      ParseMeasurementFrames(root.Child("frames"));
      ADD_FAILURE() << "accepted " << bad;
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("s.yaml:"), std::string::npos) << what;
      EXPECT_NE(what.find("prior_std_m"), std::string::npos) << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
    }
  }
  fs::remove_all(dir);
}

// Item 2: two hands on one torso whose waist gear is elastic (undeclared, 2000 N m/rad: about
// 0.5 deg of sag), both seen by one tracker at an unknown pose. (At 300 N m/rad, 5 deg of sag,
// the linear compliance at the reading's loads no longer fits MuJoCo's statics: backlash is
// chosen and the tracker is off by 5-9 sigma.) The right hand's rows join the left's through the
// `marker` index (EffectModel points); the waist compliance is seen by both.
constexpr char kTwoArms[] = R"(
<mujoco model="two_arms">
  <compiler angle="radian" autolimits="true"/>
  <custom>
    <text name="effect:joint_compliance" data="waist"/>
    <numeric name="effect:joint_compliance:stiffness" data="2000"/>
  </custom>
  <worldbody>
    <body name="pelvis" pos="0 0 0.5">
      <joint name="waist" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.4" size="0.05" mass="5"/>
      <body name="l_upper" pos="0 0.2 0.4">
        <joint name="l_sh" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="2"/>
        <body name="l_fore" pos="0.3 0 0">
          <joint name="l_el" axis="0 0 1"/>
          <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.025" mass="1"/>
          <site name="l_hand" pos="0.25 0 0.02"/>
        </body>
      </body>
      <body name="r_upper" pos="0 -0.2 0.4">
        <joint name="r_sh" axis="1 0 0"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="2"/>
        <body name="r_fore" pos="0.3 0 0">
          <joint name="r_el" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.025" mass="1"/>
          <site name="r_hand" pos="0.25 0 -0.02"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position joint="waist" kp="2000"/>
    <position joint="l_sh" kp="2000"/>
    <position joint="l_el" kp="2000"/>
    <position joint="r_sh" kp="2000"/>
    <position joint="r_el" kp="2000"/>
  </actuator>
</mujoco>)";

struct TwoArms {
  std::unique_ptr<sim::Simulation> sim;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
};

std::unique_ptr<TwoArms> MakeTwoArms() {
  auto r = std::make_unique<TwoArms>();
  sim::EffectList effects;
  effects.push_back(sim::MakeEffect("joint_compliance", "{}"));
  r->sim = sim::Simulation::FromString(kTwoArms, "two_arms.xml", effects);
  sim::DeclaredModel d;
  d.file = "two_arms.declared";
  d.actuated_joints = {"waist", "l_sh", "l_el", "r_sh", "r_el"};
  d.end_effector = "l_hand";
  d.observed_frames = {"r_hand"};
  r->chain = sim::BuildDeclaredChain(r->sim->nominal_model(), d);
  r->em = std::make_unique<EffectModel>(r->sim->nominal_model(), r->chain, r->chain.end_effector,
                                        "", std::vector<FrameId>{r->chain.ObservedFrame("r_hand")});
  return r;
}

// Rows alternating between the hands (marker 0: l_hand, 1: r_hand), in the tracker's frame.
DataSet TwoHandData(TwoArms& r, const lie::SE3& T_base_tracker, int rows, std::mt19937_64& rng) {
  DataSet d;
  d.sets = {"s"};
  d.points = {"l_hand", "r_hand"};
  MeasurementFrame tracker;
  tracker.name = "tracker";
  d.frames = {tracker};
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  std::normal_distribution<double> n(0.0, kNoise);
  const auto& names = r.sim->actuated_joints();
  for (int i = 0; i < rows; ++i) {
    Eigen::VectorXd cmd(r.sim->num_actuated());
    Observation o;
    o.q.resize(r.chain.model.nq());
    for (int k = 0; k < o.q.size(); ++k) {
      const int a = std::find(names.begin(), names.end(), r.chain.q_joints[k]) - names.begin();
      cmd[a] = o.q[k] = (r.chain.q_joints[k] == "waist" ? 0.4 : 1.0) * u(rng);
    }
    r.sim->SetCommand(cmd);
    r.sim->Settle();
    o.point = i % 2;
    const Vec3 p_base(r.sim->Pose(o.point == 0 ? "l_hand" : "r_hand").translation());
    o.frame = 0;
    o.p_frame = T_base_tracker.Inverse() * p_base + Vec3(n(rng), n(rng), n(rng));
    d.rows.push_back(o);
  }
  return d;
}

TEST(TwoMarkers, BothHandsShareTheWaistGearAndTheTracker) {
  auto r = MakeTwoArms();
  ASSERT_EQ(r->em->points().size(), 2u);
  // Each hand's own tool offset is a candidate; the waist's compliance too.
  EXPECT_GE(r->em->FindCandidate("link_offset@r_hand"), 0);
  EXPECT_GE(r->em->FindCandidate("joint_compliance@waist"), 0);
  EXPECT_GE(r->em->FindCandidate("joint_offset@r_el"), 0);
  const int kSeeds = 5;
  int named = 0, within = 0, reduced = 0;
  for (int seed = 0; seed < kSeeds; ++seed) {
    std::mt19937_64 rng(300 + seed);
    const lie::SE3 T_true = Perturbed(lie::SE3(), 0.05, 5.0, rng);
    DataSet cal = TwoHandData(*r, T_true, 80, rng);
    DataSet val = TwoHandData(*r, T_true, 40, rng);
    const auto loads = ComputeLoads(*r->em, cal);
    RegisterFrames(*r->em, loads, &cal);
    val.frames = cal.frames;
    IdentifyOptions opt;
    opt.point_std_m = kNoise;
    const IdentifyResult res = Identify(*r->em, cal, loads, NamedCandidates(*r->em), opt);
    const std::vector<std::string> found = Names(res);
    // One effect, the waist's gear: named with the mount tilt about the same axis (the waist is
    // the first joint, its anchor the mount: the data cannot tell them apart, both are named).
    const bool ok =
        found.size() == 1 && found[0].find("joint_compliance@waist") != std::string::npos;
    named += ok;
    const Vec6 e = (cal.frames[0].T_ref.Inverse() * res.after.T_base_frames[0]).Log() -
                   (cal.frames[0].T_ref.Inverse() * T_true).Log();
    double worst = 0.0;
    for (int k = 0; k < 6; ++k)
      worst = std::max(worst, std::abs(e[k]) / std::sqrt(res.frame_cov[0](k, k)));
    within += worst < 3.0;
    const double before = MeanError(*r->em, val, res.before, res.before.T_base_frames);
    const double after = MeanError(*r->em, val, res.after, res.after.T_base_frames);
    reduced += after < 0.3 * before;
    std::printf(
        "two hands, seed %d: found %s, tracker within %.2f sigma, validation %.3g -> %.3g "
        "mm\n",
        seed, found.empty() ? "-" : found[0].c_str(), worst, before * 1e3, after * 1e3);
  }
  std::printf(
      "two hands: waist named %d/%d, tracker within 3 sigma %d/%d, validation < 0.3x "
      "%d/%d\n",
      named, kSeeds, within, kSeeds, reduced, kSeeds);
  EXPECT_EQ(named, kSeeds);
  EXPECT_EQ(reduced, kSeeds);
  EXPECT_GE(within, kSeeds - 1);
}

// Each hand's prediction is MuJoCo's forward kinematics of that hand; a candidate on the other
// arm does not move it, and the analytic Jacobian matches differences for rows of both hands.
TEST(TwoMarkers, EachPointIsItsOwnBranch) {
  auto r = MakeTwoArms();
  std::mt19937_64 rng(8);
  const DataSet d = TwoHandData(*r, lie::SE3(), 10, rng);
  EffectModel::Workspace ws = r->em->MakeWorkspace();
  const auto& names = r->sim->actuated_joints();
  for (const Observation& o : d.rows) {
    Eigen::VectorXd cmd(r->sim->num_actuated());
    for (int k = 0; k < o.q.size(); ++k) {
      cmd[std::find(names.begin(), names.end(), r->chain.q_joints[k]) - names.begin()] = o.q[k];
    }
    for (int pt = 0; pt < 2; ++pt) {
      const Vec3 p = r->em->Predict(o.q, r->em->Loads(o.q), {}, nullptr, ws, pt);
      EXPECT_LT((p - r->sim->NominalPose(pt ? "r_hand" : "l_hand", cmd).translation()).norm(),
                1e-9);
    }
  }
  const std::vector<int> active = {r->em->FindCandidate("joint_compliance@waist"),
                                   r->em->FindCandidate("joint_offset@r_el"),
                                   r->em->FindCandidate("link_offset@l_hand")};
  const auto loads = ComputeLoads(*r->em, d);
  const Problem pr(*r->em, d, loads, active, {}, IdentifyOptions{});
  Eigen::VectorXd x = Eigen::VectorXd::Zero(pr.num_params());
  x.head(5) << -2e-3, 0.01, 0.003, -0.002, 0.001;
  const Eigen::MatrixXd J = pr.Jacobian(x), Jn = pr.NumericJacobian(x);
  EXPECT_LT((J - Jn).norm(), 1e-5 * Jn.norm());
  // r_el's offset moves no left-hand row, l_hand's tool no right-hand row.
  for (size_t i = 0; i < d.rows.size(); ++i) {
    const int o = pr.row_offset(i);
    if (d.rows[i].point == 0) {
      EXPECT_EQ(J.block(o, 1, 3, 1).norm(), 0.0);
    }
    if (d.rows[i].point == 1) {
      EXPECT_EQ(J.block(o, 2, 3, 3).norm(), 0.0);
    }
  }
}

// The rows as the README's CSV: every actuated joint, x, y, z in the tracker's frame, `frame`.
std::string TrackerCsv(const Rig& rig, const DataSet& d) {
  std::string csv;
  for (const std::string& j : rig.chain.q_joints) csv += j + ",";
  csv += "x,y,z,frame\n";
  char cell[128];
  for (const Observation& o : d.rows) {
    for (int k = 0; k < o.q.size(); ++k) {
      std::snprintf(cell, sizeof(cell), "%.12g,", o.q[k]);
      csv += cell;
    }
    std::snprintf(cell, sizeof(cell), "%.12g,%.12g,%.12g,tracker\n", o.p_frame.x(), o.p_frame.y(),
                  o.p_frame.z());
    csv += cell;
  }
  return csv;
}

// `flexbench identify --frame tracker` on the CSVs: the gear is found, the frame reported; a
// prior with a zero standard deviation and a frame no row uses are exit 2 with one line.
TEST(TrackerFrame, IdentifyCommandFitsTheFrameAndRefusesBadFrames) {
  auto rig = MakeRig();
  const fs::path dir = fs::temp_directory_path() / ("flexbench_tfc_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::mt19937_64 rng(2024);
  const lie::SE3 T_true = TruePose(2);
  testing::WriteFile(dir / "cal.csv", TrackerCsv(*rig, TrackerData(*rig, T_true, 90, rng)));
  testing::WriteFile(dir / "val.csv", TrackerCsv(*rig, TrackerData(*rig, T_true, 40, rng)));
  const std::string cmd =
      testing::BinDir() + "/flexbench identify --quiet --declared " + testing::SourceDir() +
      "/models/rover_arm.declared.yaml --calibration " + (dir / "cal.csv").string() +
      " --validation " + (dir / "val.csv").string() + " --point-std 1e-4 --candidates " +
      "joint_offset link_offset joint_compliance link_length --out " + (dir / "out").string();
  const testing::CommandResult ok = testing::RunCommand(cmd + " --frame tracker");
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  const nlohmann::json summary =
      nlohmann::json::parse(testing::ReadFile(dir / "out" / "summary.json"));
  ASSERT_EQ(summary["metrics"]["effects_found"].size(), 1u);
  EXPECT_EQ(
      summary["metrics"]["effects_found"][0].get<std::string>().rfind("joint_compliance@j2", 0), 0u)
      << summary["metrics"]["effects_found"];
  const nlohmann::json& frame = summary["identification"]["frames"][0];
  EXPECT_EQ(frame["name"], "tracker");
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(frame["T_base_frame"][k].get<double>(), T_true.translation()[k],
                4.0 * frame["std_m"][k].get<double>() + 1e-6);
  }
  EXPECT_LT(summary["metrics"]["val_err_after_m"].get<double>(),
            0.3 * summary["metrics"]["val_err_before_m"].get<double>());
  const testing::CommandResult zero = testing::RunCommand(
      cmd +
      "0 --frame tracker --set 'frames.tracker.T_base_frame=[0, 0, 0, 1, 0, 0, 0]' --set "
      "frames.tracker.prior_std_m=0 --set frames.tracker.prior_std_deg=0.5");
  EXPECT_EQ(zero.exit_code, 2) << zero.err;
  EXPECT_NE(zero.err.find("frames.tracker.prior_std_m"), std::string::npos) << zero.err;
  const testing::CommandResult unused =
      testing::RunCommand(cmd + "1 --frame tracker --frame mocap");
  EXPECT_EQ(unused.exit_code, 2) << unused.err;
  EXPECT_NE(unused.err.find("frame 'mocap' is declared but no calibration row"), std::string::npos)
      << unused.err;
  const testing::CommandResult undeclared = testing::RunCommand(cmd + "2");
  EXPECT_EQ(undeclared.exit_code, 2) << undeclared.err;
  EXPECT_NE(undeclared.err.find("cal.csv:2: column 'frame': 'tracker' is not a declared"),
            std::string::npos)
      << undeclared.err;
  fs::remove_all(dir);
}

// `flexbench identify --marker r_hand --frame tracker` on a two-hand CSV: the waist is found;
// a marker the declared model does not observe is exit 2 with one line.
TEST(TwoMarkers, IdentifyCommandReadsTheMarkerColumn) {
  auto r = MakeTwoArms();
  const fs::path dir = fs::temp_directory_path() / ("flexbench_tm_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  // The model file without the truth's elasticity (the declared side never simulates it).
  testing::WriteFile(dir / "two_arms.xml", kTwoArms);
  testing::WriteFile(dir / "two_arms.declared.yaml",
                     "model: two_arms.xml\nactuated_joints: [waist, l_sh, l_el, r_sh, r_el]\n"
                     "end_effector: l_hand\nobserved_frames: [r_hand]\n");
  std::mt19937_64 rng(41);
  const lie::SE3 T_true = Perturbed(lie::SE3(), 0.05, 5.0, rng);
  for (const char* name : {"cal.csv", "val.csv"}) {
    const DataSet d = TwoHandData(*r, T_true, std::string(name) == "cal.csv" ? 80 : 40, rng);
    std::string csv = "waist,l_sh,l_el,r_sh,r_el,x,y,z,marker,frame\n";
    char row[256];
    for (const Observation& o : d.rows) {
      std::snprintf(row, sizeof(row),
                    "%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%s,tracker\n", o.q[0], o.q[1],
                    o.q[2], o.q[3], o.q[4], o.p_frame.x(), o.p_frame.y(), o.p_frame.z(),
                    o.point == 0 ? "l_hand" : "r_hand");
      csv += row;
    }
    testing::WriteFile(dir / name, csv);
  }
  const std::string cmd = testing::BinDir() + "/flexbench identify --quiet --declared " +
                          (dir / "two_arms.declared.yaml").string() + " --calibration " +
                          (dir / "cal.csv").string() + " --validation " +
                          (dir / "val.csv").string() + " --frame tracker --out " +
                          (dir / "out").string();
  const testing::CommandResult ok = testing::RunCommand(cmd + " --marker r_hand");
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  const nlohmann::json summary =
      nlohmann::json::parse(testing::ReadFile(dir / "out" / "summary.json"));
  ASSERT_EQ(summary["metrics"]["effects_found"].size(), 1u) << summary["metrics"];
  EXPECT_NE(
      summary["metrics"]["effects_found"][0].get<std::string>().find("joint_compliance@waist"),
      std::string::npos);
  EXPECT_LT(summary["metrics"]["val_err_after_m"].get<double>(),
            0.3 * summary["metrics"]["val_err_before_m"].get<double>());
  const testing::CommandResult bad = testing::RunCommand(cmd + "1 --marker pelvis");
  EXPECT_EQ(bad.exit_code, 2) << bad.err;
  EXPECT_NE(bad.err.find("markers: 'pelvis' is neither the end effector nor an observed frame"),
            std::string::npos)
      << bad.err;
  // Both hands' offsets unknown (the truth's are zero): fitted near zero, the waist still found.
  const testing::CommandResult both = testing::RunCommand(
      cmd + "4 --marker r_hand --set 'unknown_marker_offsets=[l_hand, r_hand]'");
  ASSERT_EQ(both.exit_code, 0) << both.err;
  const nlohmann::json s4 = nlohmann::json::parse(testing::ReadFile(dir / "out4" / "summary.json"));
  ASSERT_EQ(s4["identification"]["marker_offsets"].size(), 2u);
  for (const nlohmann::json& m : s4["identification"]["marker_offsets"]) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_LT(std::abs(m["offset_m"][k].get<double>()), 4.0 * m["std_m"][k].get<double>() + 1e-6)
          << m;
    }
  }
  EXPECT_NE(s4["metrics"]["effects_found"][0].get<std::string>().find("joint_compliance@waist"),
            std::string::npos)
      << s4["metrics"]["effects_found"];
  const testing::CommandResult offset =
      testing::RunCommand(cmd + "3 --marker r_hand --set 'unknown_marker_offsets=[pelvis]'");
  EXPECT_EQ(offset.exit_code, 2) << offset.err;
  EXPECT_NE(offset.err.find("unknown_marker_offsets: 'pelvis' is neither the end effector nor"),
            std::string::npos)
      << offset.err;
  const testing::CommandResult none = testing::RunCommand(cmd + "2");
  EXPECT_EQ(none.exit_code, 2) << none.err;
  EXPECT_NE(none.err.find("cal.csv:3: column 'marker': 'r_hand' is not a measured frame"),
            std::string::npos)
      << none.err;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace flexbench::identify
