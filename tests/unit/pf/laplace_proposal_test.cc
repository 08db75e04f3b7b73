// The proposal that folds every reading into the move (Proposal::kLaplace) keeps the paper's
// posterior: on a planar 2-joint arm with encoders, a tip position and a link-2 orientation, the
// weighted particles after three steps match a brute-force grid posterior written here from the
// arm's closed-form kinematics (Pearson chi-square on the grid's blocks, scaled by the ESS); the
// bootstrap and encoder-conjugate proposals pass the same test, and the new proposal's ESS is
// several times theirs; readings beyond the ones the move keeps still count.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "estimators/kinematics/ppoe_model.h"
#include "estimators/pf/particle_filter.h"
#include "estimators/pf/von_mises.h"

namespace flexbench::pf {
namespace {

constexpr double kL1 = 0.30, kL2 = 0.25;  // link lengths (m): the tip is kL2 along link 2
constexpr double kKappa0 = 2.0, kKappaV = 5.0, kKappaW = 15.0;
constexpr double kPosStd = 0.03;     // R_w = kPosStd^2 I
constexpr double kBinghamA = 100.0;  // lambda = [-a, -a, -a, 0], M = I
constexpr int kGrid = 360;           // 1-degree cells per joint
constexpr int kBlock = 4;            // chi-square bins: 4 x 4 cells
constexpr int kSteps = 3;

struct Reading {
  double u[2];    // encoders
  double px, py;  // tip
  double yaw;     // link 2 about z
};

// Readings of a true path (x1, x2) with fixed errors: encoders off by a few degrees, tip by a
// centimetre, yaw by a few degrees.
Reading MakeReading(double x1, double x2, double du1, double du2, double dp, double dyaw) {
  Reading r;
  r.u[0] = x1 + du1;
  r.u[1] = x2 + du2;
  r.px = kL1 * std::cos(x1) + kL2 * std::cos(x1 + x2) + dp;
  r.py = kL1 * std::sin(x1) + kL2 * std::sin(x1 + x2) - dp;
  r.yaw = x1 + x2 + dyaw;
  return r;
}

const Reading kReadings[kSteps] = {
    MakeReading(0.5, 0.8, 0.05, -0.08, 0.01, 0.03),
    MakeReading(0.6, 0.7, -0.06, 0.04, -0.01, -0.05),
    MakeReading(0.55, 0.9, 0.07, 0.06, 0.015, 0.02),
};

// Planar arm about z: joint 1 at the origin, joint 2 at kL1 along link 1.
struct PlanarArm {
  kinematics::PpoeModel model{"planar2"};
  kinematics::FrameId link2 = -1, tip = -1;
  PlanarArm() {
    using kinematics::Joint;
    const int l1 = model.AddLink(0, "joint1", lie::SE3(), Joint::Revolute(Vec3::UnitZ()));
    link2 = model.AddLink(l1, "joint2", lie::SE3::Translation(Vec3(kL1, 0, 0)),
                          Joint::Revolute(Vec3::UnitZ()));
    tip = model.AddFrame(link2, "tip", lie::SE3::Translation(Vec3(kL2, 0, 0)));
  }
};

// The step's log-likelihood at (x1, x2), up to a constant, from the closed-form kinematics:
// encoders vM(kappa_w), tip N(p, R_w), and a Bingham on the relative rotation about z by phi,
// -a (qx^2 + qy^2 + qz^2) = -a sin^2(phi / 2).
double LogLikelihood(const Reading& r, double x1, double x2) {
  const double tx = kL1 * std::cos(x1) + kL2 * std::cos(x1 + x2);
  const double ty = kL1 * std::sin(x1) + kL2 * std::sin(x1 + x2);
  const double d2 = (tx - r.px) * (tx - r.px) + (ty - r.py) * (ty - r.py);
  const double s = std::sin(0.5 * (r.yaw - x1 - x2));
  return kKappaW * (std::cos(r.u[0] - x1) + std::cos(r.u[1] - x2)) -
         0.5 * d2 / (kPosStd * kPosStd) - kBinghamA * s * s;
}

double CellAngle(int a) { return -M_PI + (a + 0.5) * 2.0 * M_PI / kGrid; }

// p(x_t | readings 1..t) on the grid (row-major [x1][x2], normalised).
std::vector<double> GridPosterior() {
  const int n = kGrid;
  std::vector<double> p(n * n), tmp(n * n), kernel(n);
  const VonMises v0(kKappa0), vv(kKappaV);
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) p[a * n + b] = v0.Density(CellAngle(a)) * v0.Density(CellAngle(b));
  }
  for (int d = 0; d < n; ++d) kernel[d] = vv.Density(d * 2.0 * M_PI / n);
  for (const Reading& r : kReadings) {
    // The system model, separable: convolve along x2, then along x1.
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        double acc = 0.0;
        for (int c = 0; c < n; ++c) acc += p[a * n + c] * kernel[(b - c + n) % n];
        tmp[a * n + b] = acc;
      }
    }
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        double acc = 0.0;
        for (int c = 0; c < n; ++c) acc += tmp[c * n + b] * kernel[(a - c + n) % n];
        p[a * n + b] = acc;
      }
    }
    double mx = -1e300;
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        tmp[a * n + b] = LogLikelihood(r, CellAngle(a), CellAngle(b));
        mx = std::max(mx, tmp[a * n + b]);
      }
    }
    double z = 0.0;
    for (int k = 0; k < n * n; ++k) z += (p[k] *= std::exp(tmp[k] - mx));
    for (double& v : p) v /= z;
  }
  return p;
}

int Cell(double x) {
  const int a = static_cast<int>(std::floor((x + M_PI) / (2.0 * M_PI) * kGrid));
  return std::clamp(a, 0, kGrid - 1);
}

struct Fit {
  double chi2 = 0.0;
  int dof = 0;
  double ess = 0.0;
};

// The filter after the three steps of kReadings.
void RunSteps(const PlanarArm& arm, ParticleFilter& pf) {
  for (const Reading& r : kReadings) {
    pf.Predict();
    EXPECT_EQ(pf.UpdateReference(r.u, 2), PfStatus::kAccepted);
    EXPECT_EQ(pf.UpdatePosition(arm.tip, Vec3::Zero(), Vec3(r.px, r.py, 0.0)), PfStatus::kAccepted);
    const Quat q(Eigen::AngleAxisd(r.yaw, Vec3::UnitZ()));
    EXPECT_EQ(pf.UpdateOrientation(arm.link2, q), PfStatus::kAccepted);
    pf.CompleteStep();
  }
}

ParticleFilterConfig GridConfig(const PlanarArm& arm, Proposal proposal, int n_particles) {
  ParticleFilterConfig c;
  c.num_particles = n_particles;
  c.kappa_0 = kKappa0;
  c.kappa_v = kKappaV;
  c.kappa_w = kKappaW;
  c.position_frames = {arm.tip};
  c.position_cov = kPosStd * kPosStd * Mat3::Identity();
  c.orientation_frames = {arm.link2};
  c.bingham_lambda = Vec4(-kBinghamA, -kBinghamA, -kBinghamA, 0.0);
  c.ess_threshold = 1.0;  // resample every step: the weights below are one step's
  c.proposal = proposal;
  return c;
}

Fit RunAndCompare(Proposal proposal, int n_particles, std::uint64_t seed,
                  const std::vector<double>& grid) {
  PlanarArm arm;
  ParticleFilter pf(arm.model, GridConfig(arm, proposal, n_particles), seed);
  RunSteps(arm, pf);
  // Blocks of the grid: particle mass against grid mass.
  const int nb = kGrid / kBlock;
  std::vector<double> expected(nb * nb, 0.0), observed(nb * nb, 0.0);
  for (int a = 0; a < kGrid; ++a) {
    for (int b = 0; b < kGrid; ++b) expected[(a / kBlock) * nb + b / kBlock] += grid[a * kGrid + b];
  }
  Fit fit;
  double sw = 0.0, sw2 = 0.0;
  for (int i = 0; i < n_particles; ++i) {
    const double w = pf.Weight(i);
    sw += w;
    sw2 += w * w;
    observed[(Cell(pf.Angle(0, i)) / kBlock) * nb + Cell(pf.Angle(1, i)) / kBlock] += w;
  }
  fit.ess = sw * sw / sw2;
  // Bins with at least 5 expected effective samples; the rest lumped into one.
  double rest_e = 0.0, rest_o = 0.0;
  for (int k = 0; k < nb * nb; ++k) {
    if (expected[k] * fit.ess >= 5.0) {
      fit.chi2 += fit.ess * std::pow(observed[k] / sw - expected[k], 2) / expected[k];
      ++fit.dof;
    } else {
      rest_e += expected[k];
      rest_o += observed[k] / sw;
    }
  }
  if (rest_e * fit.ess >= 5.0) {
    fit.chi2 += fit.ess * std::pow(rest_o - rest_e, 2) / rest_e;
  }
  return fit;  // dof counts the bins; the statistic has dof degrees of freedom then
}

TEST(LaplaceProposal, WeightedParticlesMatchTheGridPosterior) {
  const std::vector<double> grid = GridPosterior();
  double ess[3] = {0, 0, 0};
  const Proposal proposals[3] = {Proposal::kBootstrap, Proposal::kEncoderConjugate,
                                 Proposal::kLaplace};
  for (int p = 0; p < 3; ++p) {
    for (std::uint64_t seed = 1; seed <= 2; ++seed) {
      const Fit fit = RunAndCompare(proposals[p], 20000, seed, grid);
      ASSERT_GT(fit.dof, 20) << p;
      // chi-square(dof) exceeds dof + 4.5 sqrt(2 dof) with probability < 1e-4.
      EXPECT_LT(fit.chi2, fit.dof + 4.5 * std::sqrt(2.0 * fit.dof))
          << "proposal " << p << " seed " << seed << " ess " << fit.ess;
      ess[p] += fit.ess / 2.0;
    }
  }
  EXPECT_GT(ess[2], 3.0 * ess[1]);
  EXPECT_GT(ess[2], 0.5 * 20000);
}

// The joint means from the particles' conditional moments (rao_blackwell) estimate the grid's
// posterior circular mean without bias, with no larger a spread over seeds than the particles' own
// angles give (the same particles: the moments draw no random numbers). Joint 0 given joint 1 is
// nearly fixed by the tip and the orientation, so its moment varies as the particle does.
TEST(LaplaceProposal, ConditionalMomentMeansMatchTheGridWithLessSpread) {
  const std::vector<double> grid = GridPosterior();
  double grid_mean[2];
  for (int j = 0; j < 2; ++j) {
    double sc = 0.0, ss = 0.0;
    for (int a = 0; a < kGrid; ++a) {
      for (int b = 0; b < kGrid; ++b) {
        const double x = CellAngle(j == 0 ? a : b);
        sc += grid[a * kGrid + b] * std::cos(x);
        ss += grid[a * kGrid + b] * std::sin(x);
      }
    }
    grid_mean[j] = std::atan2(ss, sc);
  }
  PlanarArm arm;
  constexpr int kSeeds = 40;
  double sum[2][2] = {}, sum2[2][2] = {};  // [rao_blackwell][joint]
  for (std::uint64_t seed = 1; seed <= kSeeds; ++seed) {
    for (int rb = 0; rb < 2; ++rb) {
      ParticleFilterConfig c = GridConfig(arm, Proposal::kLaplace, 400);
      c.rao_blackwell = rb == 1;
      ParticleFilter pf(arm.model, c, seed);
      RunSteps(arm, pf);
      for (int j = 0; j < 2; ++j) {
        const double err = std::remainder(pf.Summary().mean[j] - grid_mean[j], 2.0 * M_PI);
        sum[rb][j] += err;
        sum2[rb][j] += err * err;
      }
    }
  }
  for (int j = 0; j < 2; ++j) {
    double sd[2];
    for (int rb = 0; rb < 2; ++rb) {
      const double mean = sum[rb][j] / kSeeds;
      sd[rb] = std::sqrt(sum2[rb][j] / kSeeds - mean * mean);
      // Unbiased: within 4 standard errors, plus the grid's half-cell quadrature.
      EXPECT_LT(std::abs(mean), 4.0 * sd[rb] / std::sqrt(kSeeds) + 1e-3)
          << "joint " << j << " rao_blackwell " << rb;
    }
    // Measured 1.00x (joint 0) and 0.71x (joint 1).
    EXPECT_LT(sd[1], (j == 0 ? 1.1 : 0.85) * sd[0]) << "joint " << j;
  }
}

// A second orientation reading of the same frame in a step (more than the filter keeps): the
// move takes the first, the second becomes a weight; both count. Against the conjugate proposal
// fed the same readings.
TEST(LaplaceProposal, ReadingsBeyondTheKeptOnesStillCount) {
  PlanarArm arm;
  const Reading& r = kReadings[0];
  const Quat q(Eigen::AngleAxisd(r.yaw, Vec3::UnitZ()));
  double mean[2][2], std_dev[2][2];
  const Proposal proposals[2] = {Proposal::kEncoderConjugate, Proposal::kLaplace};
  for (int p = 0; p < 2; ++p) {
    ParticleFilterConfig c;
    c.num_particles = 100000;
    c.kappa_0 = kKappa0;
    c.kappa_v = kKappaV;
    c.kappa_w = kKappaW;
    c.orientation_frames = {arm.link2};
    c.bingham_lambda = Vec4(-kBinghamA, -kBinghamA, -kBinghamA, 0.0);
    c.proposal = proposals[p];
    ParticleFilter pf(arm.model, c, 3);
    pf.Predict();
    ASSERT_EQ(pf.UpdateReference(r.u, 2), PfStatus::kAccepted);
    ASSERT_EQ(pf.UpdateOrientation(arm.link2, q), PfStatus::kAccepted);
    ASSERT_EQ(pf.UpdateOrientation(arm.link2, q), PfStatus::kAccepted);
    pf.CompleteStep();
    const ParticleSummary& s = pf.Summary();
    for (int j = 0; j < 2; ++j) {
      mean[p][j] = s.mean[j];
      std_dev[p][j] = s.circular_std[j];
    }
  }
  for (int j = 0; j < 2; ++j) {
    EXPECT_NEAR(mean[1][j], mean[0][j], 0.05 * std_dev[0][j]) << j;
    EXPECT_NEAR(std_dev[1][j], std_dev[0][j], 0.05 * std_dev[0][j]) << j;
  }
}

}  // namespace
}  // namespace flexbench::pf
