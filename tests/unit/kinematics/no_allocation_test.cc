// The FK calls must not touch the heap once PpoeData exists. This binary replaces the global
// operator new/delete with counting versions (they forward to malloc/free, so sanitizers still
// see every allocation).
#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "estimators/kinematics/forward_kinematics.h"
#include "tests/common/counting_new.h"
#include "tests/unit/kinematics/ppoe_test_models.h"

namespace flexbench::kinematics {
namespace {

using lie::CompoundOrder;

using flexbench::testing::CountAllocations;

TEST(NoAllocation, CounterSeesAllocations) {
  // The check has teeth: a vector growing inside the counted region is seen.
  EXPECT_GE(CountAllocations([] {
              std::vector<double> v;
              v.push_back(1.0);
            }),
            1);
}

TEST(NoAllocation, ForwardKinematicsCallsDoNotAllocate) {
  std::mt19937_64 rng(1);
  const testing::RandomChainOptions o = testing::EveryFeature(27, 0.01, 0.05);
  const PpoeModel model = testing::RandomChain(rng, o);
  PpoeData data(model);
  const Eigen::VectorXd q = testing::RandomQ(rng, model);
  Matrix6Xd J(6, model.nq());
  const FrameId ee = model.FindFrame("ee");

  EXPECT_EQ(CountAllocations([&] { ForwardKinematics(model, data, q); }), 0);
  EXPECT_EQ(CountAllocations(
                [&] { ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kSecond); }),
            0);
  EXPECT_EQ(CountAllocations(
                [&] { ForwardKinematicsWithCovariance(model, data, q, CompoundOrder::kFourth); }),
            0);
  EXPECT_EQ(CountAllocations([&] { ComputeFrameJacobian(model, data, ee, J); }), 0);
  // A segment of a larger vector binds to Eigen::Ref without a copy.
  Eigen::VectorXd q_long(model.nq() + 3);
  q_long.setZero();
  EXPECT_EQ(CountAllocations([&] { ForwardKinematics(model, data, q_long.head(model.nq())); }), 0);
}

}  // namespace
}  // namespace flexbench::kinematics
