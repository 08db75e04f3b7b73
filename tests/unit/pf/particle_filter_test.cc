// The particle filter (PF paper sec. III): one step against a grid-computed posterior and
// evidence (both proposals), convergence with every sensor, hidden sensors, yaw invariance of the
// axis-symmetric Bingham, outliers (no NaN, recovery in a bounded number of steps), bad input,
// determinism, ESS-triggered resampling.
#include "estimators/pf/particle_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>
#include <utility>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::pf {
namespace {

double AngleDiff(double a, double b) { return std::remainder(a - b, 2.0 * M_PI); }

struct Truth {
  Eigen::VectorXd q;
  lie::SE3 T_imu2, T_imu3, T_grasp;
};

Truth MakeTruth(const testing::JskLikeArm& arm, const Eigen::VectorXd& q) {
  kinematics::PpoeData data(arm.model);
  kinematics::ForwardKinematics(arm.model, data, q);
  return Truth{q, data.T_base_frame[arm.imu2], data.T_base_frame[arm.imu3],
               data.T_base_frame[arm.grasp]};
}

ParticleFilterConfig AllSensors(const testing::JskLikeArm& arm) {
  ParticleFilterConfig c;
  c.position_frames = {arm.grasp};
  c.orientation_frames = {arm.imu2, arm.imu3};
  c.end_effector = arm.grasp;
  return c;
}

void Feed(ParticleFilter& pf, const testing::JskLikeArm& arm, const Truth& truth,
          const Eigen::VectorXd& u, bool position = true) {
  ASSERT_EQ(pf.UpdateReference(u.data(), static_cast<int>(u.size())), PfStatus::kAccepted);
  ASSERT_EQ(pf.UpdateOrientation(arm.imu2, Quat(truth.T_imu2.rotation())), PfStatus::kAccepted);
  ASSERT_EQ(pf.UpdateOrientation(arm.imu3, Quat(truth.T_imu3.rotation())), PfStatus::kAccepted);
  if (position) {
    ASSERT_EQ(pf.UpdatePosition(arm.grasp, Vec3::Zero(), truth.T_grasp.translation()),
              PfStatus::kAccepted);
  }
}

// Posterior of one joint after one step from vM(kappa0, 0), reference-only, on a grid: mean,
// circular std and the evidence p(u).
struct GridPosterior {
  double mean, std, log_evidence;
};
GridPosterior OneStepPosterior(double kappa0, double kappa_v, double kappa_w, double u) {
  const int n = 2048;
  const double h = 2.0 * M_PI / n;
  const VonMises v0(kappa0), vv(kappa_v), vw(kappa_w, u);
  std::vector<double> prior(n), pred(n, 0.0);
  for (int a = 0; a < n; ++a) prior[a] = v0.Density(-M_PI + a * h);
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) pred[a] += prior[b] * vv.Density((a - b) * h) * h;
  }
  double z = 0.0, sc = 0.0, ss = 0.0;
  for (int a = 0; a < n; ++a) {
    const double x = -M_PI + a * h;
    const double p = pred[a] * vw.Density(x) * h;
    z += p;
    sc += p * std::cos(x);
    ss += p * std::sin(x);
  }
  const double r = std::hypot(sc, ss) / z;
  return {std::atan2(ss, sc), std::sqrt(-2.0 * std::log(r)), std::log(z)};
}

class OneStepTest : public ::testing::TestWithParam<Proposal> {};

TEST_P(OneStepTest, ReferenceOnlyMatchesGridPosteriorAndEvidence) {
  testing::JskLikeArm arm;
  ParticleFilterConfig c;
  c.num_particles = 20000;
  c.kappa_0 = 2.0;
  c.kappa_v = 5.0;
  c.kappa_w = 15.0;
  c.proposal = GetParam();
  const double u[4] = {0.7, -0.3, 2.9, 0.1};
  double expected_evidence = 0.0;
  std::vector<GridPosterior> grid;
  for (double uj : u) {
    grid.push_back(OneStepPosterior(c.kappa_0, c.kappa_v, c.kappa_w, uj));
    expected_evidence += grid.back().log_evidence;
  }
  // Average over a few seeds; tolerances follow the effective sample size.
  const int seeds = 4;
  c.num_particles = 100000;
  std::vector<double> mean_err(4, 0.0);
  double evidence = 0.0, ess = 0.0;
  for (int seed = 0; seed < seeds; ++seed) {
    ParticleFilter pf(arm.model, c, 100 + seed);
    pf.Predict();
    ASSERT_EQ(pf.UpdateReference(u, 4), PfStatus::kAccepted);
    pf.CompleteStep();
    const ParticleSummary& s = pf.Summary();
    ess += s.ess / seeds;
    const double rel = 5.0 / std::sqrt(2.0 * s.ess);
    for (int j = 0; j < 4; ++j) {
      mean_err[j] += AngleDiff(s.mean[j], grid[j].mean) / seeds;
      EXPECT_NEAR(s.circular_std[j], grid[j].std, rel * grid[j].std) << j;
      EXPECT_LT(s.lower95[j], s.mean[j]);
      EXPECT_GT(s.upper95[j], s.mean[j]);
      // ~ +-1.96 sigma for this near-Gaussian posterior.
      EXPECT_NEAR(s.upper95[j] - s.lower95[j], 3.92 * grid[j].std,
                  (0.03 + rel) * 3.92 * grid[j].std);
    }
    evidence += pf.StepLogLikelihood() / seeds;
  }
  for (int j = 0; j < 4; ++j) {
    EXPECT_NEAR(mean_err[j], 0.0, 5.0 * grid[j].std / std::sqrt(ess * seeds)) << j;
  }
  EXPECT_NEAR(evidence, expected_evidence, 5.0 / std::sqrt(ess * seeds));
}

// initial_at_first_reading: the initial particles vM(kappa_0, u_0), so one step from them is
// the grid posterior of a prior about u_0, which by symmetry is the u = 0 posterior turned by u_0
// (mean u_0). About 0 instead, a tight kappa_0 pulls the mean far off the reading: the same
// check then fails, so it tells the two apart.
TEST_P(OneStepTest, InitialAtFirstReadingIsThePriorAboutTheReading) {
  testing::JskLikeArm arm;
  ParticleFilterConfig c;
  c.num_particles = 50000;
  c.kappa_0 = 400.0;  // 2.9 deg
  c.kappa_v = 2000.0;
  c.kappa_w = 400.0;
  c.proposal = GetParam();
  const double u[4] = {0.7, -0.3, 2.9, 0.1};
  const GridPosterior grid = OneStepPosterior(c.kappa_0, c.kappa_v, c.kappa_w, 0.0);
  for (const bool at_reading : {true, false}) {
    c.initial_at_first_reading = at_reading;
    ParticleFilter pf(arm.model, c, 7);
    pf.Predict();
    ASSERT_EQ(pf.UpdateReference(u, 4), PfStatus::kAccepted);
    pf.CompleteStep();
    const ParticleSummary& s = pf.Summary();
    const double tol = 5.0 * grid.std / std::sqrt(s.ess);
    for (int j = 0; j < 4; ++j) {
      if (at_reading) {
        EXPECT_NEAR(AngleDiff(s.mean[j], u[j]), 0.0, tol) << j;
        EXPECT_NEAR(s.circular_std[j], grid.std, 5.0 / std::sqrt(2.0 * s.ess) * grid.std) << j;
      } else {
        // The posterior of a prior about 0: half way between 0 and the reading here.
        EXPECT_GT(std::abs(AngleDiff(s.mean[j], u[j])), 0.3 * std::abs(u[j])) << j;
      }
    }
    // Reset starts over from the prior about the next reading.
    pf.Reset();
    pf.Predict();
    const double v[4] = {-1.0, 1.0, 0.5, -2.5};
    ASSERT_EQ(pf.UpdateReference(v, 4), PfStatus::kAccepted);
    pf.CompleteStep();
    if (at_reading) {
      for (int j = 0; j < 4; ++j) {
        EXPECT_NEAR(AngleDiff(pf.Summary().mean[j], v[j]), 0.0, tol) << j;
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Proposals, OneStepTest,
                         ::testing::Values(Proposal::kBootstrap, Proposal::kEncoderConjugate,
                                           Proposal::kLaplace));

class ConvergenceTest : public ::testing::TestWithParam<Proposal> {};

TEST_P(ConvergenceTest, AllSensorsRecoverDeflectedAngles) {
  testing::JskLikeArm arm;
  ParticleFilterConfig c = AllSensors(arm);
  c.proposal = GetParam();
  ParticleFilter pf(arm.model, c, 7);
  Eigen::VectorXd q(4);
  q << 0.4, 0.9, 0.6, 0.2;
  Eigen::VectorXd u = q;
  u(1) -= 4.0 * kDeg;  // the deflection the reference does not know
  u(2) -= 3.0 * kDeg;
  const Truth truth = MakeTruth(arm, q);
  double sq[4] = {0, 0, 0, 0};
  int counted = 0;
  for (int step = 0; step < 60; ++step) {
    pf.Predict();
    Feed(pf, arm, truth, u);
    pf.CompleteStep();
    if (step < 20) continue;
    const ParticleSummary& s = pf.Summary();
    for (int j = 0; j < 4; ++j) sq[j] += std::pow(AngleDiff(s.mean[j], q(j)), 2);
    ++counted;
    ASSERT_TRUE(std::isfinite(s.mean[0]) && std::isfinite(s.ess));
  }
  for (int j = 1; j <= 2; ++j) {
    EXPECT_LT(std::sqrt(sq[j] / counted), 1.0 * kDeg) << j;  // the IMUs fix the pitch joints
  }
  const ParticleSummary& s = pf.Summary();
  EXPECT_TRUE(s.has_end_effector);
  EXPECT_LT((s.T_base_ee.translation() - truth.T_grasp.translation()).norm(), 0.02);
  EXPECT_GT(s.cov_ee.diagonal().minCoeff(), 0.0);
  EXPECT_TRUE(s.cov_ee.isApprox(s.cov_ee.transpose()));
}

INSTANTIATE_TEST_SUITE_P(Proposals, ConvergenceTest,
                         ::testing::Values(Proposal::kBootstrap, Proposal::kEncoderConjugate,
                                           Proposal::kLaplace));

// The summary's means and 95% intervals (no sort, bands guessed from the circular
// std) against their definitions on the raw particles: [PF eq. 5], and the weighted 2.5% / 97.5%
// quantiles of the sorted deviations (midpoint walk), from the diffuse start to convergence, per
// seed, with and without the position readings.
class SummaryDefinitionTest : public ::testing::TestWithParam<std::tuple<int, bool>> {};

double SortedQuantile(const std::vector<std::pair<double, double>>& sorted, double kept, double p) {
  const double target = p * kept;
  double cum = 0.0, prev_mid = -1.0, prev_d = sorted.front().first;
  for (const auto& [d, wi] : sorted) {
    const double mid = cum + 0.5 * wi;
    if (mid >= target) {
      return prev_mid < 0.0 ? d : prev_d + (d - prev_d) * (target - prev_mid) / (mid - prev_mid);
    }
    cum += wi;
    prev_mid = mid;
    prev_d = d;
  }
  return sorted.back().first;
}

TEST_P(SummaryDefinitionTest, MeansAndIntervalsEqualTheDefinitions) {
  const auto [seed, position] = GetParam();
  testing::JskLikeArm arm;
  ParticleFilterConfig c = AllSensors(arm);
  c.num_particles = 1000;
  ParticleFilter pf(arm.model, c, seed);
  Eigen::VectorXd q(4);
  q << 0.4, 0.9, 0.6, 3.1;  // the last joint near +-pi: deviations wrap
  const Truth truth = MakeTruth(arm, q);
  for (int step = 0; step < 12; ++step) {
    pf.Predict();
    Feed(pf, arm, truth, q, position);
    const ParticleSummary& s = pf.Summary();
    std::vector<double> w(pf.num_particles());
    for (int i = 0; i < pf.num_particles(); ++i) w[i] = pf.Weight(i);
    for (int j = 0; j < 4; ++j) {
      double sc = 0.0, ss = 0.0;
      for (int i = 0; i < pf.num_particles(); ++i) {
        sc += w[i] * std::cos(pf.Angle(j, i));
        ss += w[i] * std::sin(pf.Angle(j, i));
      }
      EXPECT_NEAR(AngleDiff(s.mean[j], std::atan2(ss, sc)), 0.0, 1e-12) << step << " " << j;
      std::vector<std::pair<double, double>> sorted;
      double kept = 0.0;
      for (int i = 0; i < pf.num_particles(); ++i) {
        if (w[i] < 1e-14) continue;
        sorted.emplace_back(AngleDiff(pf.Angle(j, i), s.mean[j]), w[i]);
        kept += w[i];
      }
      std::sort(sorted.begin(), sorted.end());
      EXPECT_NEAR(s.lower95[j] - s.mean[j], SortedQuantile(sorted, kept, 0.025), 1e-9)
          << "step " << step << " joint " << j;
      EXPECT_NEAR(s.upper95[j] - s.mean[j], SortedQuantile(sorted, kept, 0.975), 1e-9)
          << "step " << step << " joint " << j;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(SeedsAndSensors, SummaryDefinitionTest,
                         ::testing::Combine(::testing::Values(1, 2, 3), ::testing::Bool()));

TEST(ParticleFilter, HiddenSensorContributesNothing) {
  // A filter whose end-effector marker is hidden this run gives the same particles and weights
  // as a filter without that sensor (log-likelihood 0, sec. III-D).
  testing::JskLikeArm arm;
  ParticleFilterConfig with = AllSensors(arm);
  ParticleFilterConfig without = with;
  without.position_frames.clear();
  ParticleFilter a(arm.model, with, 3), b(arm.model, without, 3);
  Eigen::VectorXd q(4);
  q << -0.2, 0.5, 0.3, 0.0;
  const Truth truth = MakeTruth(arm, q);
  for (int step = 0; step < 5; ++step) {
    a.Predict();
    b.Predict();
    Feed(a, arm, truth, q, /*position=*/false);
    Feed(b, arm, truth, q, /*position=*/false);
    // A reading of a frame that is not observed is ignored.
    EXPECT_EQ(b.UpdatePosition(arm.grasp, Vec3::Zero(), Vec3::Zero()), PfStatus::kIgnored);
    EXPECT_EQ(a.UpdateOrientation(arm.finger, Quat::Identity()), PfStatus::kIgnored);
  }
  for (int j = 0; j < 4; ++j) EXPECT_EQ(a.Summary().mean[j], b.Summary().mean[j]);
  for (int i = 0; i < a.num_particles(); i += 97) {
    EXPECT_EQ(a.Angle(2, i), b.Angle(2, i));
    EXPECT_EQ(a.Weight(i), b.Weight(i));
  }
}

TEST(ParticleFilter, AxisSymmetricBinghamIgnoresImuYaw) {
  testing::JskLikeArm arm;
  Eigen::VectorXd q(4);
  q << 0.3, 0.8, -0.4, 0.0;
  const Truth truth = MakeTruth(arm, q);
  const Quat yaw(Eigen::AngleAxisd(0.5, Vec3::UnitZ()));  // a drifted IMU yaw
  for (bool axisym : {true, false}) {
    ParticleFilterConfig c;
    c.orientation_frames = {arm.imu2, arm.imu3};
    c.bingham_lambda = axisym ? Vec4(-800, -800, 0, 0) : Vec4(-800, -800, -800, 0);
    ParticleFilter clean(arm.model, c, 5), drifted(arm.model, c, 5);
    for (int step = 0; step < 10; ++step) {
      for (ParticleFilter* pf : {&clean, &drifted}) {
        pf->Predict();
        pf->UpdateReference(q.data(), 4);
        const Quat y = pf == &drifted ? yaw : Quat::Identity();
        pf->UpdateOrientation(arm.imu2, y * Quat(truth.T_imu2.rotation()));
        pf->UpdateOrientation(arm.imu3, y * Quat(truth.T_imu3.rotation()));
      }
    }
    const double d0 = std::abs(AngleDiff(drifted.Summary().mean[0], clean.Summary().mean[0]));
    if (axisym) {
      EXPECT_LT(d0, 1e-6);
    } else {
      EXPECT_GT(d0, 0.3);  // the unimodal Bingham explains the yaw with joint 1
    }
  }
}

TEST(ParticleFilter, OutlierNeverGivesNanAndRecoversInBoundedSteps) {
  testing::JskLikeArm arm;
  ParticleFilterConfig c = AllSensors(arm);
  c.num_particles = 1024;
  ParticleFilter pf(arm.model, c, 11);
  Eigen::VectorXd q(4);
  q << 0.1, 0.7, 0.5, 0.0;
  const Truth truth = MakeTruth(arm, q);
  for (int step = 0; step < 20; ++step) {
    pf.Predict();
    Feed(pf, arm, truth, q);
  }
  const double settled = std::abs(AngleDiff(pf.Summary().mean[1], q(1)));
  ASSERT_LT(settled, 2.0 * kDeg);
  // A marker 1 km away: every weight but one underflows in linear terms; the log-domain
  // normalisation [PF eq. 21] keeps the best particle at weight 1.
  pf.Predict();
  EXPECT_EQ(pf.UpdatePosition(arm.grasp, Vec3::Zero(), Vec3(1000.0, -500.0, 3.0)),
            PfStatus::kAccepted);
  const ParticleSummary& hit = pf.Summary();
  EXPECT_GE(hit.ess, 1.0);
  for (int j = 0; j < 4; ++j) ASSERT_TRUE(std::isfinite(hit.mean[j]));
  EXPECT_TRUE(hit.cov_ee.allFinite());
  // A marker at 1e200 m: every log-likelihood is -inf; the reading is rejected, nothing changes.
  const double before = pf.Summary().mean[1];
  EXPECT_EQ(pf.UpdatePosition(arm.grasp, Vec3::Zero(), Vec3(1e200, 0.0, 0.0)),
            PfStatus::kRejectedAllZero);
  EXPECT_EQ(pf.Summary().mean[1], before);
  // Recovery: good readings bring the estimate back within a bounded number of steps.
  int steps = 0;
  for (; steps < 10; ++steps) {
    pf.Predict();
    Feed(pf, arm, truth, q);
    if (std::abs(AngleDiff(pf.Summary().mean[1], q(1))) < 2.0 * kDeg &&
        std::abs(AngleDiff(pf.Summary().mean[2], q(2))) < 2.0 * kDeg) {
      break;
    }
  }
  EXPECT_LE(steps, 3) << "steps to recover from the outlier";
}

TEST(ParticleFilter, BadReadingsAreRejected) {
  testing::JskLikeArm arm;
  ParticleFilter pf(arm.model, AllSensors(arm), 1);
  pf.Predict();
  const double nan_u[4] = {0.0, NAN, 0.0, 0.0};
  EXPECT_EQ(pf.UpdateReference(nan_u, 4), PfStatus::kRejectedNonFinite);
  const double u[3] = {0.0, 0.0, 0.0};
  EXPECT_THROW(pf.UpdateReference(u, 3), InputError);
  EXPECT_EQ(pf.UpdateOrientation(arm.imu2, Quat(1.2, 0.0, 0.0, 0.0)), PfStatus::kRejectedOutside);
  EXPECT_EQ(pf.UpdateOrientation(arm.imu2, Quat(NAN, 0.0, 0.0, 0.0)), PfStatus::kRejectedNonFinite);
  EXPECT_EQ(pf.UpdatePosition(arm.grasp, Vec3::Zero(), Vec3(NAN, 0, 0)),
            PfStatus::kRejectedNonFinite);
  for (int j = 0; j < 4; ++j) EXPECT_TRUE(std::isfinite(pf.Summary().mean[j]));
}

TEST(ParticleFilter, BadParametersAreClearErrors) {
  testing::JskLikeArm arm;
  const auto message = [&](const ParticleFilterConfig& c) {
    try {
      ParticleFilter pf(arm.model, c, 1);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  ParticleFilterConfig c;
  c.kappa_v = 0.0;
  EXPECT_NE(message(c).find("kappa_v must be finite and > 0"), std::string::npos);
  c = {};
  c.kappa_w = -3.0;
  EXPECT_NE(message(c).find("kappa_w"), std::string::npos);
  c = {};
  c.kappa_0 = NAN;
  EXPECT_NE(message(c).find("kappa_0"), std::string::npos);
  c = {};
  c.bingham_lambda = Vec4(0, 0, -800, -800);
  EXPECT_NE(message(c).find("sorted ascending"), std::string::npos);
  c = {};
  c.bingham_lambda = Vec4(-700, -700, 100, 100);
  EXPECT_NE(message(c).find("shifted"), std::string::npos);
  c = {};
  c.num_particles = 1;
  EXPECT_NE(message(c).find("number of particles"), std::string::npos);
  c = {};
  c.ess_threshold = 1.5;
  EXPECT_NE(message(c).find("ess_threshold"), std::string::npos);
  c = {};
  c.position_cov(0, 0) = -1.0;
  EXPECT_NE(message(c).find("positive definite"), std::string::npos);
  c = {};
  c.orientation_frames = {42};
  EXPECT_NE(message(c).find("does not exist"), std::string::npos);
}

TEST(ParticleFilter, DeterministicAndResettable) {
  testing::JskLikeArm arm;
  Eigen::VectorXd q(4);
  q << 0.2, 0.3, 0.4, 0.5;
  const Truth truth = MakeTruth(arm, q);
  ParticleFilter a(arm.model, AllSensors(arm), 42), b(arm.model, AllSensors(arm), 42);
  std::vector<double> first;
  for (int run = 0; run < 2; ++run) {
    a.Reset();
    for (int step = 0; step < 5; ++step) {
      a.Predict();
      Feed(a, arm, truth, q);
      if (run == 0) {
        b.Predict();
        Feed(b, arm, truth, q);
        EXPECT_EQ(a.Summary().mean[1], b.Summary().mean[1]);
        first.push_back(a.Summary().mean[1]);
      } else {
        EXPECT_EQ(a.Summary().mean[1], first[step]);
      }
    }
  }
}

TEST(ParticleFilter, ResamplingFollowsTheEssThreshold) {
  testing::JskLikeArm arm;
  Eigen::VectorXd q(4);
  q << 0.2, 0.3, 0.4, 0.5;
  const Truth truth = MakeTruth(arm, q);
  for (double threshold : {1e-9, 1.0}) {
    ParticleFilterConfig c = AllSensors(arm);
    c.ess_threshold = threshold;
    ParticleFilter pf(arm.model, c, 1);
    for (int step = 0; step < 5; ++step) {
      pf.Predict();
      Feed(pf, arm, truth, q);
    }
    if (threshold < 1e-6) {
      EXPECT_EQ(pf.resample_count(), 0);
    } else {
      EXPECT_EQ(pf.resample_count(), 4);  // every step after the first update
    }
  }
}

}  // namespace
}  // namespace flexbench::pf
