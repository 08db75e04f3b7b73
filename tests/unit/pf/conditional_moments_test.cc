// The Rao-Blackwellised moments against brute force: on random revolute chains, joint j of a
// particle swept over the circle with the others held, its conditional density taken from the
// PPOE forward kinematics and the Bingham density of [PF eq. 27] written as a quaternion product,
// then integrated numerically. ConditionalMoments' closed form must give the same first moment.
#include "estimators/pf/conditional_moments.h"

#include <gtest/gtest.h>

#include <Eigen/QR>
#include <cmath>
#include <complex>
#include <functional>
#include <random>
#include <vector>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/sampling.h"
#include "estimators/lie/so3.h"
#include "estimators/pf/batch_kinematics.h"
#include "estimators/pf/bingham.h"
#include "estimators/pf/particle_filter.h"
#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::pf {
namespace {

constexpr double kKappaV = 5.0, kKappaW = 15.0;
constexpr double kPosStd = 0.08;
constexpr int kParticles = 6;

Vec4 Xyzw(const Quat& q) { return Vec4(q.x(), q.y(), q.z(), q.w()); }

struct Reading {
  FrameId frame;
  Vec3 p_frame, p_base;  // position readings
  Quat q_obs;            // orientation readings
};

struct Case {
  kinematics::PpoeModel model;
  std::vector<FrameId> position_frames, orientation_frames;
  std::vector<Reading> positions, orientations;
};

// A 5-joint random chain: a position reading on its end effector and on one middle frame, a
// Bingham reading on another, each read near the chain's pose at a random configuration.
Case MakeCase(std::uint64_t seed, Mat3* info) {
  std::mt19937_64 rng(seed);
  std::vector<FrameId> frames;
  Case c{testing::RandomRevoluteChain(rng, 5, &frames), {}, {}, {}, {}};
  kinematics::PpoeData data(c.model);
  Eigen::VectorXd q = Eigen::VectorXd::Random(c.model.nq()) * M_PI;
  kinematics::ForwardKinematics(c.model, data, q);
  std::normal_distribution<double> n(0.0, 1.0);
  const auto position = [&](FrameId f) {
    const Vec3 p_frame(0.05 * n(rng), 0.05 * n(rng), 0.05 * n(rng));
    const Vec3 noise(n(rng), n(rng), n(rng));
    c.position_frames.push_back(f);
    c.positions.push_back({f, p_frame, data.T_base_frame[f] * p_frame + 0.05 * noise, Quat()});
  };
  position(frames.back());
  position(frames[1]);
  const FrameId fq = frames[2];
  c.orientation_frames.push_back(fq);
  const Quat q_true(data.T_base_frame[fq].rotation());
  c.orientations.push_back({fq, Vec3::Zero(), Vec3::Zero(),
                            q_true * Quat(lie::SO3Exp(0.1 * Vec3(n(rng), n(rng), n(rng))))});
  *info = Mat3::Identity() / (kPosStd * kPosStd);
  return c;
}

// log of the step's target at q, up to a constant, written from the definitions.
double LogTarget(const Case& c, const Bingham& bingham, const Eigen::VectorXd& q,
                 const Eigen::VectorXd& prev, const Eigen::VectorXd& u) {
  kinematics::PpoeData data(c.model);
  kinematics::ForwardKinematics(c.model, data, q);
  double l = 0.0;
  for (int j = 0; j < q.size(); ++j) {
    l += kKappaV * std::cos(q(j) - prev(j)) + kKappaW * std::cos(u(j) - q(j));
  }
  for (const Reading& r : c.positions) {
    l -= 0.5 * (r.p_base - data.T_base_frame[r.frame] * r.p_frame).squaredNorm() /
         (kPosStd * kPosStd);
  }
  for (const Reading& r : c.orientations) {
    const Quat q_pred(data.T_base_frame[r.frame].rotation());
    l += bingham.UnnormalisedLogDensity(Xyzw(r.q_obs * q_pred.inverse()));
  }
  return l;
}

// E[e^{i x}] of the density exp(log_density(x)) on the circle, by the rectangle rule on 8,192
// nodes (spectrally accurate for a smooth periodic integrand).
std::complex<double> NumericalMoment(const std::function<double(double)>& log_density) {
  constexpr int kNodes = 8192;
  std::vector<double> logs(kNodes);
  double mx = -1e300;
  for (int k = 0; k < kNodes; ++k) {
    logs[k] = log_density(-M_PI + 2.0 * M_PI * k / kNodes);
    mx = std::max(mx, logs[k]);
  }
  std::complex<double> m1 = 0.0;
  double z = 0.0;
  for (int k = 0; k < kNodes; ++k) {
    const double w = std::exp(logs[k] - mx);
    z += w;
    m1 += w * std::polar(1.0, -M_PI + 2.0 * M_PI * k / kNodes);
  }
  return m1 / z;
}

class ConditionalMomentsTest : public ::testing::TestWithParam<std::uint64_t> {};

TEST_P(ConditionalMomentsTest, MatchTheNumericalConditionalMoment) {
  Mat3 info;
  const Case c = MakeCase(GetParam(), &info);
  const int nq = c.model.nq();
  std::mt19937_64 rng(GetParam() + 100);
  std::normal_distribution<double> g(0.0, 1.0);
  Mat4 G;
  for (int k = 0; k < 16; ++k) G(k / 4, k % 4) = g(rng);
  const Mat4 M = Eigen::HouseholderQR<Mat4>(G).householderQ();  // a random orthogonal M
  const Bingham bingham(Vec4(-60.0, -25.0, -4.0, 0.0), M);
  const std::size_t stride = kParticles;
  ConditionalMoments cm(c.model, c.position_frames, c.orientation_frames, info, stride);
  std::vector<FrameId> outputs = c.position_frames;
  outputs.insert(outputs.end(), c.orientation_frames.begin(), c.orientation_frames.end());
  for (FrameId f : cm.joint_frames()) outputs.push_back(f);
  BatchKinematics fk(c.model, outputs, kParticles);
  cm.Bind(fk);
  for (int j = 0; j < nq; ++j) EXPECT_TRUE(cm.exact(j)) << j;

  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  std::vector<Eigen::VectorXd> q(kParticles, Eigen::VectorXd(nq)), prev = q;
  Eigen::VectorXd u(nq);
  std::vector<double> qc(nq * stride), qs(nq * stride), pc(nq * stride), ps(nq * stride);
  for (int j = 0; j < nq; ++j) u(j) = angle(rng);
  for (int i = 0; i < kParticles; ++i) {
    for (int j = 0; j < nq; ++j) {
      q[i](j) = angle(rng);
      prev[i](j) = angle(rng);
      qc[j * stride + i] = std::cos(q[i](j));
      qs[j * stride + i] = std::sin(q[i](j));
      pc[j * stride + i] = std::cos(prev[i](j));
      ps[j * stride + i] = std::sin(prev[i](j));
    }
  }
  fk.Compute(qc.data(), qs.data(), static_cast<int>(stride), kParticles);
  cm.Begin(c.model, fk, pc.data(), ps.data(), u.data(), kKappaV, kKappaW, kParticles);
  for (size_t a = 0; a < c.positions.size(); ++a) {
    cm.AddPosition(fk, static_cast<int>(a), fk.OutputIndex(c.positions[a].frame),
                   c.positions[a].p_frame, c.positions[a].p_base, kParticles);
  }
  for (size_t a = 0; a < c.orientations.size(); ++a) {
    cm.AddOrientation(fk, static_cast<int>(a), fk.OutputIndex(c.orientations[a].frame),
                      bingham.RotationForm(c.orientations[a].q_obs).C, kParticles);
  }
  cm.Finish(qc.data(), qs.data(), kParticles);

  for (int i = 0; i < kParticles; ++i) {
    for (int j = 0; j < nq; ++j) {
      Eigen::VectorXd x = q[i];
      const std::complex<double> m1 = NumericalMoment([&](double xj) {
        x(j) = xj;
        return LogTarget(c, bingham, x, prev[i], u);
      });
      EXPECT_NEAR(cm.moment_c(j)[i], m1.real(), 1e-9) << "particle " << i << " joint " << j;
      EXPECT_NEAR(cm.moment_s(j)[i], m1.imag(), 1e-9) << "particle " << i << " joint " << j;
    }
  }
}

// The filter's glue: after a step, Summary's joint means are the weighted circular means of each
// particle's conditional moment, computed here by numerical integration from the particle's own
// angles, its parent (no resampling: particle i's parent is particle i) and the step's readings
// (encoders, two orientations, one of them on a joint frame, and the grasp point).
TEST(ConditionalMoments, FilterMeansAreTheWeightedMomentsOfItsParticles) {
  const testing::JskLikeArm arm;
  ParticleFilterConfig c;
  c.num_particles = 8;
  c.kappa_0 = 2.0;
  c.kappa_v = kKappaV;
  c.kappa_w = kKappaW;
  c.position_frames = {arm.grasp};
  c.position_cov = kPosStd * kPosStd * Mat3::Identity();
  c.orientation_frames = {arm.imu2, arm.finger};
  c.bingham_lambda = Vec4(-300.0, -300.0, -40.0, 0.0);
  c.ess_threshold = 1e-9;  // never resample
  c.proposal = Proposal::kLaplace;
  ParticleFilter pf(arm.model, c, 7);
  const Bingham bingham(c.bingham_lambda);
  Eigen::VectorXd q_true(4), u(4);
  q_true << 0.3, 0.7, -0.4, 0.2;
  u << 0.35, 0.62, -0.3, 0.28;
  kinematics::PpoeData data(arm.model);
  kinematics::ForwardKinematics(arm.model, data, q_true);
  const Quat q2(data.T_base_frame[arm.imu2].rotation()),
      qf(data.T_base_frame[arm.finger].rotation());
  const Vec3 p = data.T_base_frame[arm.grasp].translation() + Vec3(0.02, -0.01, 0.03);
  std::vector<Eigen::VectorXd> prev(c.num_particles, Eigen::VectorXd(4));
  for (int step = 0; step < 2; ++step) {
    for (int i = 0; i < c.num_particles; ++i) {
      for (int j = 0; j < 4; ++j) prev[i](j) = pf.Angle(j, i);
    }
    pf.Predict();
    ASSERT_EQ(pf.UpdateReference(u.data(), 4), PfStatus::kAccepted);
    ASSERT_EQ(pf.UpdateOrientation(arm.imu2, q2), PfStatus::kAccepted);
    ASSERT_EQ(pf.UpdateOrientation(arm.finger, qf), PfStatus::kAccepted);
    ASSERT_EQ(pf.UpdatePosition(arm.grasp, Vec3::Zero(), p), PfStatus::kAccepted);
    pf.CompleteStep();
  }
  ASSERT_EQ(pf.resample_count(), 0);
  const auto log_target = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& parent) {
    kinematics::ForwardKinematics(arm.model, data, x);
    double l =
        -0.5 * (p - data.T_base_frame[arm.grasp].translation()).squaredNorm() / (kPosStd * kPosStd);
    for (const auto& [frame, q_obs] : {std::pair{arm.imu2, q2}, std::pair{arm.finger, qf}}) {
      const Quat q_pred(data.T_base_frame[frame].rotation());
      l += bingham.UnnormalisedLogDensity(Xyzw(q_obs * q_pred.inverse()));
    }
    for (int j = 0; j < 4; ++j) {
      l += kKappaV * std::cos(x(j) - parent(j)) + kKappaW * std::cos(u(j) - x(j));
    }
    return l;
  };
  for (int j = 0; j < 4; ++j) {
    std::complex<double> sum = 0.0;
    for (int i = 0; i < c.num_particles; ++i) {
      Eigen::VectorXd x(4);
      for (int k = 0; k < 4; ++k) x(k) = pf.Angle(k, i);
      sum += pf.Weight(i) * NumericalMoment([&](double xj) {
               x(j) = xj;
               return log_target(x, prev[i]);
             });
    }
    EXPECT_NEAR(pf.Summary().mean[j], std::arg(sum), 1e-8) << "joint " << j;
  }
}

INSTANTIATE_TEST_SUITE_P(RandomChains, ConditionalMomentsTest, ::testing::Values(1, 2, 3, 4));

// With R_w not a multiple of I the position term has second harmonics in a joint's angle: the
// joints above a position frame keep the particles' own angles, the others stay exact.
TEST(ConditionalMoments, NonIsotropicPositionNoiseLeavesTheJointsAboveItUnsmoothed) {
  const testing::JskLikeArm arm;
  const Mat3 info = Vec3(100.0, 100.0, 400.0).asDiagonal();
  ConditionalMoments cm(arm.model, {arm.grasp}, {arm.imu2}, info, 4);
  EXPECT_FALSE(cm.exact(0));  // yaw, above the grasp point
  EXPECT_FALSE(cm.exact(1));
  EXPECT_FALSE(cm.exact(2));
  EXPECT_TRUE(cm.exact(3));  // the gripper joint: nothing reads below it
  ConditionalMoments iso(arm.model, {arm.grasp}, {arm.imu2}, 100.0 * Mat3::Identity(), 4);
  for (int j = 0; j < 4; ++j) EXPECT_TRUE(iso.exact(j)) << j;
}

}  // namespace
}  // namespace flexbench::pf
