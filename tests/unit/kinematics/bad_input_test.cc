// Every invalid input names its culprit in an InputError.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "tests/unit/kinematics/ppoe_test_models.h"

namespace flexbench::kinematics {
namespace {

using lie::CompoundOrder;
using lie::SE3;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Runs f, expects an InputError whose message contains every one of `parts`.
template <class F>
void ExpectInputError(const F& f, std::initializer_list<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    const std::string what = e.what();
    for (const std::string& p : parts) {
      EXPECT_NE(what.find(p), std::string::npos) << "'" << p << "' not in: " << what;
    }
  }
}

// Runs f, expects a caller's bug (std::invalid_argument, an internal error) naming `parts`: never
// an InputError, which would tell the user their file is wrong.
template <class F>
void ExpectCallerBug(const F& f, std::initializer_list<std::string> parts) {
  try {
    f();
    ADD_FAILURE() << "nothing thrown";
  } catch (const InputError& e) {
    ADD_FAILURE() << "a caller's bug reported as bad input: " << e.what();
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    for (const std::string& p : parts) {
      EXPECT_NE(what.find(p), std::string::npos) << "'" << p << "' not in: " << what;
    }
  }
}

TEST(PpoeModelInput, NonSymmetricCovarianceNamesTheFrame) {
  PpoeModel model("arm");
  Mat6 cov = 1e-4 * Mat6::Identity();
  cov(0, 3) = 1e-5;
  ExpectInputError(
      [&] { model.AddLink(kBaseFrame, "shoulder", SE3(), Joint::Revolute(Vec3::UnitZ()), cov); },
      {"arm", "shoulder", "not symmetric"});
  EXPECT_FALSE(model.HasFrame("shoulder"));  // nothing half-added
}

TEST(PpoeModelInput, NonPsdCovarianceNamesTheFrame) {
  PpoeModel model("arm");
  Mat6 cov = 1e-4 * Mat6::Identity();
  cov(4, 4) = -1e-6;
  ExpectInputError([&] { model.AddFrame(kBaseFrame, "grasp", SE3(), cov); },
                   {"grasp", "not positive semi-definite"});
  // Symmetric with positive diagonal but indefinite.
  Mat6 indefinite = Mat6::Identity();
  indefinite(0, 1) = indefinite(1, 0) = 2.0;
  ExpectInputError([&] { model.AddFrame(kBaseFrame, "plate", SE3(), indefinite); },
                   {"plate", "not positive semi-definite"});
}

TEST(PpoeModelInput, SingularPsdCovarianceIsAccepted) {
  PpoeModel model("arm");
  const FrameId f = model.AddLink(kBaseFrame, "j1", SE3(), Joint::Revolute(Vec3::UnitZ()),
                                  testing::AxisSource(Vec3::UnitZ(), 0.1));
  EXPECT_TRUE(model.frame(f).has_source);
  const FrameId g = model.AddFrame(f, "tip", SE3());
  EXPECT_FALSE(model.frame(g).has_source);
}

TEST(PpoeModelInput, NanCovarianceNamesTheFrame) {
  PpoeModel model("arm");
  Mat6 cov = Mat6::Identity();
  cov(2, 2) = kNaN;
  ExpectInputError([&] { model.AddFrame(kBaseFrame, "tag7", SE3(), cov); }, {"tag7", "NaN"});
}

TEST(PpoeModelInput, ZeroLengthAxisNamesTheFrame) {
  PpoeModel model("arm");
  ExpectInputError(
      [&] { model.AddLink(kBaseFrame, "elbow", SE3(), Joint::Revolute(Vec3::Zero())); },
      {"elbow", "joint axis"});
  ExpectInputError(
      [&] { model.AddLink(kBaseFrame, "slider", SE3(), Joint::Prismatic(Vec3(kNaN, 0, 1))); },
      {"slider", "joint axis"});
  EXPECT_EQ(model.nq(), 0);
}

TEST(PpoeModelInput, StructuralErrors) {
  PpoeModel model("arm");
  model.AddFrame(kBaseFrame, "a", SE3());
  ExpectInputError([&] { model.AddFrame(7, "b", SE3()); }, {"'b'", "parent frame id 7"});
  ExpectInputError([&] { model.AddFrame(kBaseFrame, "a", SE3()); }, {"'a'", "already exists"});
  ExpectInputError([&] { model.AddFrame(kBaseFrame, "", SE3()); }, {"name is empty"});
  ExpectInputError([&] { model.FindFrame("nope"); }, {"arm", "nope"});
  Mat3 not_rotation = Mat3::Identity();
  not_rotation(0, 0) = -1.0;  // a reflection
  ExpectInputError([&] { model.AddFrame(kBaseFrame, "mirror", SE3(not_rotation, Vec3::Zero())); },
                   {"mirror", "rotation"});
}

class FkInput : public ::testing::Test {
 protected:
  FkInput() : model_(testing::PlanarArm3R(0.1)), data_(model_), q_(3) { q_ << 0.1, 0.2, 0.3; }
  PpoeModel model_;
  PpoeData data_;
  Eigen::VectorXd q_;
};

TEST_F(FkInput, NanJointAngleNamesTheJoint) {
  q_[1] = kNaN;
  ExpectInputError([&] { ForwardKinematics(model_, data_, q_); }, {"q[1]", "link2", "nan"});
  q_[1] = std::numeric_limits<double>::infinity();
  ExpectInputError(
      [&] { ForwardKinematicsWithCovariance(model_, data_, q_, CompoundOrder::kSecond); },
      {"q[1]", "link2", "inf"});
}

TEST_F(FkInput, WrongQSize) {
  Eigen::VectorXd q(4);
  q.setZero();
  ExpectInputError([&] { ForwardKinematics(model_, data_, q); }, {"q has 4 entries", "3 joints"});
  ExpectInputError(
      [&] { ForwardKinematicsWithCovariance(model_, data_, q, CompoundOrder::kFourth); },
      {"q has 4 entries", "planar3r"});
}

TEST_F(FkInput, DataOfAnotherModel) {
  PpoeModel other("other");
  other.AddLink(kBaseFrame, "j", SE3(), Joint::Revolute(Vec3::UnitX()));
  PpoeData wrong(other);
  ExpectCallerBug([&] { ForwardKinematics(model_, wrong, q_); }, {"PpoeData", "planar3r"});
}

TEST_F(FkInput, BadOrderAndJacobianShape) {
  ExpectCallerBug(
      [&] { ForwardKinematicsWithCovariance(model_, data_, q_, static_cast<CompoundOrder>(3)); },
      {"order"});
  ForwardKinematics(model_, data_, q_);
  Matrix6Xd J(6, 2);
  ExpectCallerBug([&] { ComputeFrameJacobian(model_, data_, 1, J); }, {"2 columns", "3 joints"});
  Matrix6Xd J3(6, 3);
  ExpectInputError([&] { ComputeFrameJacobian(model_, data_, 42, J3); }, {"frame id 42"});
}

}  // namespace
}  // namespace flexbench::kinematics
