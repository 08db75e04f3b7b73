// Batch forward kinematics (SoA, from (cos q, sin q)) against the PPOE kinematics of
// estimators/kinematics (which tests/integration/declared_chain/ checks against MuJoCo).
#include "estimators/pf/batch_kinematics.h"

#include <gtest/gtest.h>

#include <random>
#include <stdexcept>
#include <vector>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "tests/unit/pf/pf_test_models.h"

namespace flexbench::pf {
namespace {

void CheckAgainstPpoe(const kinematics::PpoeModel& model, const std::vector<FrameId>& outputs,
                      int n, std::mt19937_64& rng) {
  BatchKinematics batch(model, outputs, n);
  const int nq = model.nq();
  std::vector<double> c(nq * n), s(nq * n);
  std::vector<Eigen::VectorXd> qs(n, Eigen::VectorXd(nq));
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < nq; ++j) {
      const double q = u(rng);
      qs[i](j) = q;
      c[j * n + i] = std::cos(q);
      s[j * n + i] = std::sin(q);
    }
  }
  batch.Compute(c.data(), s.data(), n, n);
  kinematics::PpoeData data(model);
  for (int i = 0; i < n; ++i) {
    kinematics::ForwardKinematics(model, data, qs[i]);
    for (int k = 0; k < batch.num_outputs(); ++k) {
      const lie::SE3 expected = data.T_base_frame[outputs[k]];
      const lie::SE3 got = batch.Pose(k, i);
      EXPECT_LT((got.rotation() - expected.rotation()).cwiseAbs().maxCoeff(), 1e-13);
      EXPECT_LT((got.translation() - expected.translation()).cwiseAbs().maxCoeff(), 1e-13);
    }
  }
}

TEST(BatchKinematics, MatchesPpoeKinematicsOnTheArm) {
  testing::JskLikeArm arm;
  std::mt19937_64 rng(1);
  // 150 particles: two full blocks and a partial one.
  CheckAgainstPpoe(arm.model, {arm.imu2, arm.imu3, arm.grasp, arm.finger, 0}, 150, rng);
}

TEST(BatchKinematics, MatchesPpoeKinematicsOnRandomChains) {
  std::mt19937_64 rng(2);
  for (int trial = 0; trial < 5; ++trial) {
    std::vector<FrameId> outputs;
    const kinematics::PpoeModel model = testing::RandomRevoluteChain(rng, 7, &outputs);
    CheckAgainstPpoe(model, outputs, 70, rng);
  }
}

TEST(BatchKinematics, OutputsAndErrors) {
  testing::JskLikeArm arm;
  BatchKinematics batch(arm.model, {arm.grasp, arm.imu2}, 8);
  EXPECT_EQ(batch.OutputIndex(arm.imu2), 1);
  EXPECT_EQ(batch.OutputIndex(arm.imu3), -1);
  EXPECT_THROW(BatchKinematics(arm.model, {99}, 8), InputError);
  std::vector<double> c(4 * 8, 1.0), s(4 * 8, 0.0);
  // More particles than the capacity is the caller's bug, not bad input.
  EXPECT_THROW(batch.Compute(c.data(), s.data(), 8, 9), std::invalid_argument);
  kinematics::PpoeModel prismatic("p");
  const int f =
      prismatic.AddLink(0, "slide", lie::SE3(), kinematics::Joint::Prismatic(Vec3::UnitX()));
  try {
    BatchKinematics b(prismatic, {f}, 4);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("prismatic"), std::string::npos);
  }
}

}  // namespace
}  // namespace flexbench::pf
