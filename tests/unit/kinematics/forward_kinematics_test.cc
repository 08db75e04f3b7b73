#include "estimators/kinematics/forward_kinematics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <unsupported/Eigen/MatrixFunctions>
#include <vector>

#include "estimators/error.h"
#include "estimators/kinematics/chain_sampler.h"
#include "estimators/lie/sampling.h"
#include "tests/unit/kinematics/ppoe_test_models.h"
#include "tests/unit/lie/lie_test_util.h"

namespace flexbench::kinematics {
namespace {

using lie::CompoundOrder;
using lie::SE3;

// ---------------------------------------------------------------------------------------------
// Oracles.

// Mean poses by a direct product of 4x4 matrices, [PPOE eqs. 16-17] with xi = 0; the joint factor
// by Eigen's matrix exponential of hat(zeta q), independent of lie::SE3::Exp.
std::vector<Mat4> MeanPosesBy4x4(const PpoeModel& model, const Eigen::VectorXd& q) {
  std::vector<Mat4> T(model.num_frames(), Mat4::Identity());
  for (FrameId i = 1; i < model.num_frames(); ++i) {
    const PpoeFrame& f = model.frame(i);
    const double q_i = f.q_index >= 0 ? q[f.q_index] : 0.0;
    T[i] = T[f.parent] * f.T_parent_ip.Matrix() * lie::SE3Hat(f.zeta * q_i).exp();
  }
  return T;
}

// Monte Carlo over all sources: second moments of Log(mean^-1 * sample) at every frame.
std::vector<Mat6> SampleFrameCovariances(const PpoeModel& model, const Eigen::VectorXd& q, int n,
                                         std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  const int nf = model.num_frames();
  std::vector<lie::GaussianSampler<6>> samplers;
  for (FrameId i = 0; i < nf; ++i) samplers.emplace_back(model.frame(i).source_cov);
  std::vector<SE3> mean(nf), T(nf), joint(nf);
  for (FrameId i = 1; i < nf; ++i) {
    const PpoeFrame& f = model.frame(i);
    const double q_i = f.q_index >= 0 ? q[f.q_index] : 0.0;
    joint[i] = SE3::Exp(f.zeta * q_i);
    mean[i] = mean[f.parent] * f.T_parent_ip * joint[i];
  }
  std::vector<SE3> mean_inv(nf);
  for (FrameId i = 0; i < nf; ++i) mean_inv[i] = mean[i].Inverse();
  std::vector<Mat6> S(nf, Mat6::Zero());
  for (int s = 0; s < n; ++s) {
    for (FrameId i = 1; i < nf; ++i) {
      const PpoeFrame& f = model.frame(i);
      const SE3 source = f.has_source ? SE3::Exp(samplers[i].Sample(rng)) : SE3();
      T[i] = T[f.parent] * f.T_parent_ip * source * joint[i];
      const Vec6 xi = (mean_inv[i] * T[i]).Log();
      S[i] += xi * xi.transpose();
    }
  }
  for (Mat6& m : S) m /= n;
  return S;
}

// Covariance difference in units of the reference's standard deviations, over the DoFs the
// reference excites (a planar arm has exactly-zero out-of-plane moments).
double NormalizedError(const Mat6& S, const Mat6& S_ref) {
  std::vector<int> idx;
  const double max_diag = S_ref.diagonal().maxCoeff();
  for (int k = 0; k < 6; ++k) {
    if (S_ref(k, k) > 1e-12 * max_diag) idx.push_back(k);
  }
  double sum = 0.0;
  for (int a : idx) {
    for (int b : idx) {
      const double e = (S(a, b) - S_ref(a, b)) / std::sqrt(S_ref(a, a) * S_ref(b, b));
      sum += e * e;
    }
  }
  return std::sqrt(sum);
}

void Record(const std::string& key, double value) {
  ::testing::Test::RecordProperty(key, std::to_string(value));
}

// ---------------------------------------------------------------------------------------------
// Mean forward kinematics.

TEST(ForwardKinematics, MeanMatchesProductOf4x4Matrices) {
  std::mt19937_64 rng(1);
  const testing::RandomChainOptions o = testing::EveryFeature(7, 0.01, 0.05);
  const PpoeModel model = testing::RandomChain(rng, o);
  PpoeData data(model);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::VectorXd q = testing::RandomQ(rng, model);
    const std::vector<Mat4> expected = MeanPosesBy4x4(model, q);
    ForwardKinematics(model, data, q);
    for (FrameId i = 0; i < model.num_frames(); ++i) {
      EXPECT_LT((data.T_base_frame[i].Matrix() - expected[i]).cwiseAbs().maxCoeff(), 1e-12)
          << model.frame(i).name;
    }
    // The covariance variant computes the same means.
    PpoeData data_cov(model);
    ForwardKinematicsWithCovariance(model, data_cov, q, CompoundOrder::kFourth);
    for (FrameId i = 0; i < model.num_frames(); ++i) {
      EXPECT_TRUE(data_cov.T_base_frame[i].IsApprox(data.T_base_frame[i], 1e-15));
    }
  }
}

TEST(ForwardKinematics, PlanarArmGeometry) {
  const PpoeModel model = testing::PlanarArm3R(10 * kDeg);
  PpoeData data(model);
  Eigen::VectorXd q(3);
  q << M_PI / 2, -M_PI / 2, 0.0;
  ForwardKinematics(model, data, q);
  // Up 1 m along y, then 2 m along x.
  const SE3& T_base_ee = data.T_base_frame[model.FindFrame("ee")];
  EXPECT_LT((T_base_ee.translation() - Vec3(2.0, 1.0, 0.0)).norm(), 1e-15);
  EXPECT_LT((T_base_ee.rotation() - Mat3::Identity()).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_EQ(model.nq(), 3);
  EXPECT_EQ(model.num_frames(), 5);  // base, 3 links, ee
}

TEST(ForwardKinematics, JointTypes) {
  PpoeModel model("joints");
  const FrameId slide = model.AddLink(kBaseFrame, "slide", SE3(), Joint::Prismatic(Vec3(0, 0, 2)));
  const FrameId hinge = model.AddLink(slide, "hinge", SE3::Translation(Vec3(1, 0, 0)),
                                      Joint::Revolute(Vec3::UnitZ(), Vec3(0, 1, 0)));
  const FrameId fixed = model.AddFrame(hinge, "tip", SE3::Translation(Vec3(0, 0, 0.5)));
  EXPECT_EQ(model.nq(), 2);
  EXPECT_EQ(model.frame(fixed).q_index, -1);
  EXPECT_EQ(model.joint_frame(1), hinge);
  // The axis is normalised and the twist is [r x w; w].
  EXPECT_TRUE(model.frame(slide).joint.axis.isApprox(Vec3::UnitZ(), 0.0));
  EXPECT_TRUE(model.frame(hinge).zeta.isApprox(
      (Vec6() << Vec3(0, 1, 0).cross(Vec3::UnitZ()), Vec3::UnitZ()).finished(), 0.0));
  PpoeData data(model);
  Eigen::VectorXd q(2);
  q << 0.3, M_PI;  // slide up 0.3 m; rotate 180 deg about the axis through (0, 1, 0)
  ForwardKinematics(model, data, q);
  // The hinge frame origin (1, 0, 0.3) rotates about (1, 1, *) to (1, 2, 0.3).
  EXPECT_LT((data.T_base_frame[hinge].translation() - Vec3(1.0, 2.0, 0.3)).norm(), 1e-15);
  EXPECT_LT((data.T_base_frame[fixed].translation() - Vec3(1.0, 2.0, 0.8)).norm(), 1e-15);
}

// ---------------------------------------------------------------------------------------------
// Covariances.

TEST(ForwardKinematicsCovariance, SecondOrderIsTheSumOfAdjointMappedSources) {
  // [PPOE eq. 18] unrolled: Sigma_frame = sum over upstream sources s of
  // Ad_{T_frame^-1 T_{s,p}} Sigma_s Ad^T, with T_{s,p} the source's mean frame.
  std::mt19937_64 rng(2);
  const testing::RandomChainOptions o = testing::EveryFeature(7, 0.01, 0.05);
  const PpoeModel model = testing::RandomChain(rng, o);
  PpoeData data(model);
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kSecond);
  for (FrameId i = 1; i < model.num_frames(); ++i) {
    Mat6 expected = Mat6::Zero();
    const SE3 T_frame_base = data.T_base_frame[i].Inverse();
    for (FrameId s = i; s != kBaseFrame; s = model.frame(s).parent) {
      const PpoeFrame& f = model.frame(s);
      const SE3 T_base_sp = data.T_base_frame[f.parent] * f.T_parent_ip;
      const Mat6 Ad = (T_frame_base * T_base_sp).Adjoint();
      expected += Ad * f.source_cov * Ad.transpose();
    }
    EXPECT_LT((data.Sigma_frame[i] - expected).cwiseAbs().maxCoeff(),
              1e-12 * expected.cwiseAbs().maxCoeff())
        << model.frame(i).name;
  }
}

TEST(ForwardKinematicsCovariance, SameBitsAsTheBaselineRecursion) {
  // ForwardKinematicsWithCovariance runs as an AVX2 clone where the CPU has it
  // (estimators/target_clones.h); this file is compiled for the baseline only. Redo [PPOE eq. 18]'s
  // recursion here with the same inline transports: every bit must agree, or "same seed, same
  // bytes" would depend on the machine.
  std::mt19937_64 rng(21);
  const testing::RandomChainOptions o = testing::EveryFeature(12, 0.01, 0.05);
  const PpoeModel model = testing::RandomChain(rng, o);
  PpoeData data(model);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd q = testing::RandomQ(rng, model);
    ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kSecond);
    std::vector<Mat6> Sigma(model.num_frames(), Mat6::Zero());
    for (FrameId i = 1; i < model.num_frames(); ++i) {
      const PpoeFrame& f = model.frame(i);
      const SE3& T_parent_i = data.T_parent_frame[i];
      if (f.has_source) {
        lie::TransportCovarianceSum(T_parent_i, Sigma[f.parent], f.source_cov_parent, &Sigma[i]);
      } else {
        lie::TransportCovariance(T_parent_i, Sigma[f.parent], &Sigma[i]);
      }
      EXPECT_TRUE(data.Sigma_frame[i] == Sigma[i]) << model.frame(i).name << " trial " << trial;
    }
  }
}

TEST(ForwardKinematicsCovariance, BaselineCpuPathHasTheDispatchedPathsBits) {
  // On an AVX2 machine the dispatched call runs the vector transports; the baseline entry runs
  // the scalar ones that CPUs without AVX2 get. Both orders, every frame, every bit.
  std::mt19937_64 rng(22);
  const testing::RandomChainOptions o = testing::EveryFeature(12, 0.01, 0.05);
  const PpoeModel model = testing::RandomChain(rng, o);
  PpoeData dispatched(model), baseline(model);
  for (const CompoundOrder order : {CompoundOrder::kSecond, CompoundOrder::kFourth}) {
    for (int trial = 0; trial < 5; ++trial) {
      const Eigen::VectorXd q = testing::RandomQ(rng, model);
      ForwardKinematicsWithCovariance(model, dispatched, q, order);
      internal::ForwardKinematicsWithCovarianceBaseline(model, baseline, q, order);
      for (FrameId i = 1; i < model.num_frames(); ++i) {
        EXPECT_TRUE(dispatched.Sigma_frame[i] == baseline.Sigma_frame[i])
            << model.frame(i).name << " order " << static_cast<int>(order) << " trial " << trial;
        EXPECT_TRUE(dispatched.T_base_frame[i].Matrix() == baseline.T_base_frame[i].Matrix());
      }
    }
  }
}

TEST(ForwardKinematicsCovariance, SingleSourceIsExactAtBothOrders) {
  // Only the first joint is uncertain (paper Fig. 3a): every frame's covariance is the exactly
  // transported source, so both orders agree with each other and with Monte Carlo.
  PpoeModel model("one_source");
  FrameId parent = kBaseFrame;
  for (int i = 0; i < 3; ++i) {
    const SE3 p = i == 0 ? SE3() : SE3::Translation(Vec3(1.0, 0.0, 0.0));
    const Mat6 cov = i == 0 ? testing::AxisSource(Vec3::UnitZ(), 10 * kDeg) : Mat6::Zero();
    parent = model.AddLink(parent, "link" + std::to_string(i + 1), p,
                           Joint::Revolute(Vec3::UnitZ()), cov);
  }
  const FrameId ee = model.AddFrame(parent, "ee", SE3::Translation(Vec3(1.0, 0.0, 0.0)));
  Eigen::VectorXd q(3);
  q << 0.3, 0.6, -0.4;
  PpoeData d2(model), d4(model);
  ForwardKinematicsWithCovariance(model, d2, q, CompoundOrder::kSecond);
  ForwardKinematicsWithCovariance(model, d4, q, CompoundOrder::kFourth);
  EXPECT_LT((d2.Sigma_frame[ee] - d4.Sigma_frame[ee]).cwiseAbs().maxCoeff(), 1e-15);
  const std::vector<Mat6> mc = SampleFrameCovariances(model, q, 200000, 3);
  Record("err", NormalizedError(d2.Sigma_frame[ee], mc[ee]));
  EXPECT_LT(NormalizedError(d2.Sigma_frame[ee], mc[ee]), 0.03);
}

// The paper's planar 3R example with 10 deg perturbations about every joint axis: the 4th
// order is closer to Monte Carlo than [PPOE eq. 18] in the stretched (singular, Fig. 3b) and bent
// (Fig. 3c, d) configurations.
class PlanarArmMonteCarlo : public ::testing::TestWithParam<Eigen::Vector3d> {};

TEST_P(PlanarArmMonteCarlo, FourthOrderIsCloserThanSecond) {
  const PpoeModel model = testing::PlanarArm3R(10 * kDeg);
  const Eigen::VectorXd q = GetParam();
  PpoeData d2(model), d4(model);
  ForwardKinematicsWithCovariance(model, d2, q, CompoundOrder::kSecond);
  ForwardKinematicsWithCovariance(model, d4, q, CompoundOrder::kFourth);
  // 10^6 samples: sampling error ~0.004 in this metric, well below the 2nd-order bias.
  const std::vector<Mat6> mc = SampleFrameCovariances(model, q, 1000000, 4);
  const FrameId ee = model.FindFrame("ee");
  const double err2 = NormalizedError(d2.Sigma_frame[ee], mc[ee]);
  const double err4 = NormalizedError(d4.Sigma_frame[ee], mc[ee]);
  Record("err2", err2);
  Record("err4", err4);
  EXPECT_LT(err4, 0.5 * err2) << "2nd: " << err2 << " 4th: " << err4;
  EXPECT_LT(err4, 0.01);
  // The planar structure is kept exactly: no out-of-plane moments.
  for (int k : {2, 3, 4}) {
    EXPECT_EQ(d4.Sigma_frame[ee].row(k).cwiseAbs().maxCoeff(), 0.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Configurations, PlanarArmMonteCarlo,
                         ::testing::Values(Eigen::Vector3d(0.0, 0.0, 0.0),
                                           Eigen::Vector3d(0.5, 0.5, 0.5),
                                           Eigen::Vector3d(1.0, -1.5, 1.2)));

TEST(ForwardKinematicsCovariance, SevenDofChainSmallPerturbationsAllFrames) {
  // 1 mm / 0.5 deg sources, a passive base compliance and an uncertain grasp: both orders match
  // Monte Carlo at every frame within sampling error.
  std::mt19937_64 rng(5);
  const testing::RandomChainOptions o = testing::EveryFeature(7, 1e-3, 0.5 * kDeg);
  const PpoeModel model = testing::RandomChain(rng, o);
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  PpoeData d2(model), d4(model);
  ForwardKinematicsWithCovariance(model, d2, q, CompoundOrder::kSecond);
  ForwardKinematicsWithCovariance(model, d4, q, CompoundOrder::kFourth);
  const std::vector<Mat6> mc = SampleFrameCovariances(model, q, 100000, 6);
  for (FrameId i = 1; i < model.num_frames(); ++i) {
    EXPECT_LT(NormalizedError(d2.Sigma_frame[i], mc[i]), 0.06) << model.frame(i).name;
    EXPECT_LT(NormalizedError(d4.Sigma_frame[i], mc[i]), 0.06) << model.frame(i).name;
  }
}

TEST(ForwardKinematicsCovariance, SevenDofChainLargePerturbationsFourthIsCloser) {
  std::mt19937_64 rng(7);
  testing::RandomChainOptions o;
  o.trans_sd = 0.01;
  o.rot_sd = 10 * kDeg;
  o.fixed_base_source = true;
  o.grasp = true;
  const PpoeModel model = testing::RandomChain(rng, o);
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  PpoeData d2(model), d4(model);
  ForwardKinematicsWithCovariance(model, d2, q, CompoundOrder::kSecond);
  ForwardKinematicsWithCovariance(model, d4, q, CompoundOrder::kFourth);
  const std::vector<Mat6> mc = SampleFrameCovariances(model, q, 200000, 8);
  for (const char* name : {"ee", "grasp"}) {
    const FrameId f = model.FindFrame(name);
    const double err2 = NormalizedError(d2.Sigma_frame[f], mc[f]);
    const double err4 = NormalizedError(d4.Sigma_frame[f], mc[f]);
    Record(std::string(name) + "_err2", err2);
    Record(std::string(name) + "_err4", err4);
    EXPECT_LT(err4, 0.5 * err2) << name << " 2nd: " << err2 << " 4th: " << err4;
  }
}

TEST(ForwardKinematicsCovariance, TreeBranchesShareOnlyTheTrunk) {
  // Two arms on a common torso: a tip's covariance depends on its own branch and the trunk only,
  // exactly as in the chain made of those links.
  std::mt19937_64 rng(9);
  const auto build = [&](bool with_left) {
    std::mt19937_64 r(10);
    PpoeModel m("tree");
    FrameId torso = m.AddLink(kBaseFrame, "torso", lie::RandomSE3(r, 0.3),
                              Joint::Revolute(Vec3::UnitZ()), testing::RandomSource(r, 0.01, 0.05));
    std::mt19937_64 r_left(11);
    if (with_left) {
      FrameId p = torso;
      for (int i = 0; i < 3; ++i) {
        p = m.AddLink(p, "left" + std::to_string(i), lie::RandomSE3(r_left, 0.3),
                      Joint::Revolute(testing::UniformVec3(r_left)),
                      testing::RandomSource(r_left, 0.01, 0.05));
      }
      m.AddFrame(p, "left_tip", SE3::Translation(Vec3(0.1, 0, 0)));
    }
    FrameId p = torso;
    for (int i = 0; i < 3; ++i) {
      p = m.AddLink(p, "right" + std::to_string(i), lie::RandomSE3(r, 0.3),
                    Joint::Revolute(testing::UniformVec3(r)), testing::RandomSource(r, 0.01, 0.05));
    }
    m.AddFrame(p, "right_tip", SE3::Translation(Vec3(0.1, 0, 0)));
    return m;
  };
  const PpoeModel tree = build(true);
  const PpoeModel chain = build(false);
  ASSERT_EQ(tree.nq(), 7);
  ASSERT_EQ(chain.nq(), 4);
  Eigen::VectorXd q_tree = testing::RandomQ(rng, tree);
  Eigen::VectorXd q_chain(4);
  q_chain << q_tree[0], q_tree.tail<3>();
  for (CompoundOrder order : {CompoundOrder::kSecond, CompoundOrder::kFourth}) {
    PpoeData dt(tree), dc(chain);
    ForwardKinematicsWithCovariance(tree, dt, q_tree, order);
    ForwardKinematicsWithCovariance(chain, dc, q_chain, order);
    const FrameId rt = tree.FindFrame("right_tip");
    const FrameId rc = chain.FindFrame("right_tip");
    EXPECT_TRUE(dt.T_base_frame[rt].IsApprox(dc.T_base_frame[rc], 1e-15));
    EXPECT_LT((dt.Sigma_frame[rt] - dc.Sigma_frame[rc]).cwiseAbs().maxCoeff(), 1e-15);
  }
  PpoeData d4(tree);
  ForwardKinematicsWithCovariance(tree, d4, q_tree, CompoundOrder::kFourth);
  const std::vector<Mat6> mc = SampleFrameCovariances(tree, q_tree, 100000, 12);
  for (const char* name : {"left_tip", "right_tip"}) {
    const FrameId f = tree.FindFrame(name);
    EXPECT_LT(NormalizedError(d4.Sigma_frame[f], mc[f]), 0.06) << name;
  }
}

TEST(ForwardKinematicsCovariance, SingularSourcesStayPsdAndSymmetric) {
  const PpoeModel model = testing::PlanarArm3R(10 * kDeg);
  PpoeData data(model);
  Eigen::VectorXd q(3);
  q << 0.2, -0.7, 1.1;
  ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kFourth);
  for (FrameId i = 1; i < model.num_frames(); ++i) {
    const Mat6& S = data.Sigma_frame[i];
    EXPECT_LT((S - S.transpose()).cwiseAbs().maxCoeff(), 1e-15);
    const double min_eig = Eigen::SelfAdjointEigenSolver<Mat6>(S).eigenvalues().minCoeff();
    EXPECT_GT(min_eig, -1e-15 * S.norm()) << model.frame(i).name;
  }
}

// ---------------------------------------------------------------------------------------------
// Jacobian w.r.t. q.

TEST(FrameJacobian, MatchesFiniteDifferencesOnTheManifold) {
  std::mt19937_64 rng(13);
  testing::RandomChainOptions o;
  o.mixed_joints = true;
  o.fixed_base_source = true;
  o.grasp = true;
  const PpoeModel model = testing::RandomChain(rng, o);
  PpoeData data(model), data_h(model);
  Matrix6Xd J(6, model.nq());
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::VectorXd q = testing::RandomQ(rng, model);
    ForwardKinematics(model, data, q);
    for (FrameId f = 0; f < model.num_frames(); ++f) {
      ComputeFrameJacobian(model, data, f, J);
      const auto pose = [&](const Eigen::VectorXd& q_in) {
        ForwardKinematics(model, data_h, q_in);
        return data_h.T_base_frame[f];
      };
      for (double h : lie::testing::kFdSteps) {
        const Eigen::MatrixXd J_num = lie::testing::NumericalJacobian(pose, q, h);
        EXPECT_LT(lie::testing::JacobianError(J, J_num), 1e-7)
            << model.frame(f).name << " h = " << h;
      }
    }
  }
}

TEST(FrameJacobian, ColumnsOfOtherBranchesAreZero) {
  const PpoeModel model = testing::PlanarArm3R(0.0);
  PpoeData data(model);
  Eigen::VectorXd q(3);
  q << 0.1, 0.2, 0.3;
  ForwardKinematics(model, data, q);
  Matrix6Xd J(6, 3);
  ComputeFrameJacobian(model, data, model.FindFrame("link1"), J);
  EXPECT_TRUE(J.rightCols<2>().isZero(0.0));
  EXPECT_FALSE(J.col(0).isZero(0.0));
  ComputeFrameJacobian(model, data, kBaseFrame, J);
  EXPECT_TRUE(J.isZero(0.0));
}

}  // namespace
}  // namespace flexbench::kinematics

namespace flexbench::kinematics {
namespace {

// A torso with a source, and two arms with sources on it: the "camera" tip of one and the
// "hand" tip of the other, as the mast camera and the arm of a rover share its body.
PpoeModel TwoArmTree(double trunk_rot_sd, double branch_trans_sd, double branch_rot_sd) {
  std::mt19937_64 r(21);
  PpoeModel m("two_arm_tree");
  FrameId torso =
      m.AddLink(kBaseFrame, "torso", lie::RandomSE3(r, 0.3), Joint::Revolute(Vec3::UnitZ()),
                testing::RandomSource(r, 0.002, trunk_rot_sd));
  for (const char* side : {"camera", "hand"}) {
    FrameId p = torso;
    for (int i = 0; i < 3; ++i) {
      p = m.AddLink(p, std::string(side) + std::to_string(i), lie::RandomSE3(r, 0.3),
                    Joint::Revolute(testing::UniformVec3(r)),
                    testing::RandomSource(r, branch_trans_sd, branch_rot_sd));
    }
    m.AddFrame(p, std::string(side) + "_tip", SE3::Translation(Vec3(0.1, 0, 0)));
  }
  return m;
}

TEST(RelativeCovariance, FromTheBaseItIsTheSecondOrderCovariance) {
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 5; ++trial) {
    testing::RandomChainOptions o;
    o.dof = 7;
    o.trans_sd = 0.005;
    o.rot_sd = 0.05;
    const PpoeModel model = testing::RandomChain(rng, o);
    PpoeData data(model);
    ForwardKinematicsWithCovariance(model, data, testing::RandomQ(rng, model),
                                    CompoundOrder::kSecond);
    for (FrameId f = 0; f < model.num_frames(); ++f) {
      Mat6 rel;
      RelativeCovariance(model, data, kBaseFrame, f, &rel);
      const double scale = std::max(1e-300, data.Sigma_frame[f].cwiseAbs().maxCoeff());
      EXPECT_LT((rel - data.Sigma_frame[f]).cwiseAbs().maxCoeff(), 1e-12 * scale) << "frame " << f;
    }
  }
}

TEST(RelativeCovariance, TrunkSourcesCancelExactly) {
  const PpoeModel model = TwoArmTree(0.05, 0.0, 0.0);  // only the torso is uncertain
  PpoeData data(model);
  std::mt19937_64 rng(6);
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kSecond);
  const FrameId cam = model.FindFrame("camera_tip");
  const FrameId hand = model.FindFrame("hand_tip");
  ASSERT_GT(data.Sigma_frame[hand].norm(), 1e-4);  // uncertain in the base frame...
  Mat6 rel;
  RelativeCovariance(model, data, cam, hand, &rel);
  EXPECT_EQ(rel, Mat6::Zero());  // ...but not seen from the camera
  // The sampled chain agrees: every draw of the torso leaves T_cam_hand where it was.
  ChainSampler sampler(model);
  std::vector<SE3> poses(model.num_frames());
  const SE3 nominal = data.T_base_frame[cam].Between(data.T_base_frame[hand]);
  for (int i = 0; i < 100; ++i) {
    sampler.Sample(q, rng, &poses);
    EXPECT_LT(nominal.Between(poses[cam].Between(poses[hand])).Log().norm(), 1e-12);
  }
}

// Both branches uncertain: the relative covariance against the sampled chain, for small
// sources (where 2nd order is exact up to sampling error) in both directions of the pair.
TEST(RelativeCovariance, MatchesMonteCarloAcrossTwoBranches) {
  const PpoeModel model = TwoArmTree(0.05, 0.002, 0.5 * kDeg);
  PpoeData data(model);
  std::mt19937_64 rng(7);
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kSecond);
  const FrameId cam = model.FindFrame("camera_tip");
  const FrameId hand = model.FindFrame("hand_tip");
  ChainSampler sampler(model);
  std::vector<SE3> poses(model.num_frames());
  for (const auto& [a, b] : {std::pair{cam, hand}, std::pair{hand, cam}}) {
    Mat6 rel;
    RelativeCovariance(model, data, a, b, &rel);
    const SE3 nominal = data.T_base_frame[a].Between(data.T_base_frame[b]);
    Mat6 mc = Mat6::Zero();
    // 36 normalised entries with sampling sd ~sqrt(1.5/n) each: ~0.015 expected at this n.
    const int n = 160000;
    for (int i = 0; i < n; ++i) {
      sampler.Sample(q, rng, &poses);
      const Vec6 xi = nominal.Between(poses[a].Between(poses[b])).Log();
      mc += xi * xi.transpose() / n;
    }
    EXPECT_LT(NormalizedError(rel, mc), 0.03) << "ref " << a << ", frame " << b;
    // The trunk's large source is gone: far smaller than the frame's own covariance.
    EXPECT_LT(rel.trace(), 0.2 * data.Sigma_frame[b].trace());
  }
}

TEST(RelativeCovariance, UnknownFrameIsAClearError) {
  const PpoeModel model = TwoArmTree(0.05, 0.002, 0.01);
  PpoeData data(model);
  Mat6 rel;
  EXPECT_THROW(RelativeCovariance(model, data, 0, model.num_frames(), &rel), InputError);
  EXPECT_THROW(RelativeCovariance(model, data, -1, 1, &rel), InputError);
}

}  // namespace
}  // namespace flexbench::kinematics

namespace flexbench::kinematics {
namespace {

// The readings' noise on the end effector (fk/ppoe_ekf `reading_noise`) against Monte Carlo:
// the sample covariance of Log(T(q)^-1 T(q + dq)), dq ~ N(0, diag(std^2)), no sources.
TEST(AddJointNoiseCovariance, MatchesMonteCarlo) {
  std::mt19937_64 rng(11);
  testing::RandomChainOptions o = testing::EveryFeature(7, 0.0, 0.0);
  o.fixed_base_source = false;
  o.grasp = false;
  const PpoeModel model = testing::RandomChain(rng, o);
  const FrameId ee = model.FindFrame("ee");
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  Eigen::VectorXd std_q(model.nq());
  for (int k = 0; k < model.nq(); ++k) std_q[k] = 1e-3 * (1 + k % 3);
  PpoeData data(model);
  ForwardKinematics(model, data, q);
  const lie::SE3 T0 = data.T_base_frame[ee];
  Matrix6Xd J(6, model.nq());
  Mat6 Sigma = Mat6::Zero();
  AddJointNoiseCovariance(model, data, ee, std_q, J, &Sigma);
  std::normal_distribution<double> n(0.0, 1.0);
  const int samples = 20000;
  Mat6 mc = Mat6::Zero();
  PpoeData d2(model);
  for (int s = 0; s < samples; ++s) {
    Eigen::VectorXd qs = q;
    for (int k = 0; k < model.nq(); ++k) qs[k] += std_q[k] * n(rng);
    ForwardKinematics(model, d2, qs);
    const Vec6 xi = T0.Between(d2.T_base_frame[ee]).Log();
    mc += xi * xi.transpose() / samples;
  }
  // Relative to the largest entry: the sampling error of 20000 draws is ~1%.
  EXPECT_LT((mc - Sigma).cwiseAbs().maxCoeff(), 0.03 * Sigma.cwiseAbs().maxCoeff());
  // Zero std adds nothing; a wrong size is an input error.
  Mat6 same = Sigma;
  AddJointNoiseCovariance(model, data, ee, Eigen::VectorXd::Zero(model.nq()), J, &same);
  EXPECT_EQ(same, Sigma);
  EXPECT_THROW(AddJointNoiseCovariance(model, data, ee, Eigen::VectorXd::Zero(2), J, &same),
               InputError);
}

}  // namespace
}  // namespace flexbench::kinematics
