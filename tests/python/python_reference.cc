// The C++ side of tests/python/test_module.py: the library calls the Python module wraps, made
// directly, with every double printed as a C99 hex float (%a, exact). The pytest runs this
// program and compares the module's results with it (FK and its covariance bit-equal, an EKF
// update to 1e-12, error messages equal).
//
//   python_reference <declared.yaml>
//
// Output, one item per line: "<name> <n> <n hex floats>" or "<name>_message <text>".
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <string>

#include "estimators/error.h"
#include "estimators/estimator.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

using namespace flexbench;

namespace {

template <typename M>
void Print(const char* name, const M& m) {
  // Row-major, as numpy arrays are read in the test.
  std::printf("%s %d", name, static_cast<int>(m.rows() * m.cols()));
  for (int i = 0; i < m.rows(); ++i) {
    for (int j = 0; j < m.cols(); ++j) std::printf(" %a", m(i, j));
  }
  std::printf("\n");
}

Mat4 Matrix(const lie::SE3& T) {
  Mat4 M = Mat4::Identity();
  M.topLeftCorner<3, 3>() = T.rotation();
  M.topRightCorner<3, 1>() = T.translation();
  return M;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: python_reference <declared.yaml>\n");
    return 2;
  }
  try {
    const sim::DeclaredModel declared = sim::LoadDeclaredModel(argv[1]);
    const sim::MjModelPtr mj = sim::LoadModel(declared.model_path);
    const sim::DeclaredChain chain = sim::BuildDeclaredChain(mj.get(), declared);
    const kinematics::PpoeModel& model = chain.model;
    kinematics::PpoeData data(model);
    const kinematics::FrameId ee = chain.end_effector;

    // A fixed configuration away from zero (the test passes these exact doubles).
    Eigen::VectorXd q(model.nq());
    for (int k = 0; k < model.nq(); ++k) q[k] = 0.3 * std::sin(1.7 * k + 0.4) + 0.05 * k;
    Print("q", q.transpose());

    kinematics::ForwardKinematics(model, data, q);
    Print("fk", Matrix(data.T_base_frame[ee]));
    kinematics::Matrix6Xd J(6, model.nq());
    kinematics::ComputeFrameJacobian(model, data, ee, J);
    Print("jacobian", J);
    for (const auto order : {lie::CompoundOrder::kSecond, lie::CompoundOrder::kFourth}) {
      const std::string n = order == lie::CompoundOrder::kSecond ? "2" : "4";
      kinematics::ForwardKinematicsWithCovariance(model, data, q, order);
      Print(("fk_cov" + n + "_T").c_str(), Matrix(data.T_base_frame[ee]));
      Print(("fk_cov" + n + "_S").c_str(), data.Sigma_frame[ee]);
    }

    // One EKF update: ppoe_ekf, prior at an encoder reading, then an end-effector position 1 cm
    // off the prior's mean.
    estimators::EstimatorSetup setup;
    setup.model = &model;
    setup.effects = chain.effects_or_null();
    setup.end_effector = ee;
    setup.params = estimators::Params({{"covariance_order", {2.0}}});
    auto ekf = estimators::MakeEstimator("ppoe_ekf", setup);
    estimators::JointReading joints;
    joints.t = 0.5;
    joints.q = q;
    joints.std = estimators::JointVector::Constant(model.nq(), 1e-3);
    ekf->Predict(0.5);
    std::printf("status_joints %s\n", estimators::ToString(ekf->Update(joints)));
    kinematics::ForwardKinematics(model, data, q);
    estimators::PositionReading pos;
    pos.t = 0.5;
    pos.frame = ee;
    pos.p_frame = Vec3(0.0, 0.0, 0.0);
    pos.p_base = data.T_base_frame[ee].translation() + Vec3(0.01, -0.005, 0.003);
    pos.cov = 1e-4 * Mat3::Identity();
    std::printf("status_position %s\n", estimators::ToString(ekf->Update(pos)));
    const estimators::Belief b = ekf->Estimate();
    Print("ekf_T", Matrix(b.T_base_ee));
    Print("ekf_cov", b.cov);

    // What the library says about a NaN joint angle.
    Eigen::VectorXd q_nan = q;
    q_nan[2] = std::numeric_limits<double>::quiet_NaN();
    try {
      kinematics::ForwardKinematics(model, data, q_nan);
      std::printf("nan_message (none)\n");
    } catch (const InputError& e) {
      std::printf("nan_message %s\n", e.what());
    }
    try {
      kinematics::ForwardKinematicsWithCovariance(model, data, q_nan, lie::CompoundOrder::kSecond);
      std::printf("nan_cov_message (none)\n");
    } catch (const InputError& e) {
      std::printf("nan_cov_message %s\n", e.what());
    }
    // ... and about a q of the wrong length.
    try {
      kinematics::ForwardKinematics(model, data, Eigen::VectorXd::Zero(3));
      std::printf("size_message (none)\n");
    } catch (const InputError& e) {
      std::printf("size_message %s\n", e.what());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "python_reference: %s\n", e.what());
    return 1;
  }
  return 0;
}
