// A compliant mount's tilt under the load it carries (kinematics::MountTilt), against MuJoCo's
// own static equilibrium of a plate on two spring joints (pitch then roll, as the rover's
// base plate) carrying a rigid load: the tilted-equilibrium solution agrees to 1e-9 of the
// tilt, and the linear C M0 it replaced is off by the P-delta term (m g h / k of the tilt)
// wherever the load's centre of mass sits above the pivot; the pitch-then-roll rotation
// (kinematics::MountRotation) beats one Exp of the tilt where both turn.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "estimators/kinematics/model_effects.h"
#include "estimators/lie/so3.h"
#include "sim/mujoco_model.h"

namespace flexbench::kinematics {
namespace {

struct Load {
  const char* name;
  Vec3 com;  // pivot -> centre of mass, m
  double mass;
};

std::string Mjcf(const Load& l) {
  char buf[1024];
  std::snprintf(buf, sizeof(buf), R"(
<mujoco>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="plate" pos="0 0 0.5">
      <joint name="pitch" type="hinge" axis="0 1 0" stiffness="1300"/>
      <joint name="roll" type="hinge" axis="1 0 0" stiffness="4000"/>
      <inertial pos="0 0 0" mass="1e-9" diaginertia="1e-9 1e-9 1e-9"/>
      <body name="load" pos="%.17g %.17g %.17g">
        <inertial pos="0 0 0" mass="%.17g" diaginertia="0.01 0.01 0.01"/>
      </body>
    </body>
  </worldbody>
</mujoco>)",
                l.com.x(), l.com.y(), l.com.z(), l.mass);
  return buf;
}

// Newton on MuJoCo's generalized forces: the spring force balances gravity (qfrc_bias at rest).
Mat3 MujocoTilt(const mjModel* m, mjData* d) {
  const auto residual = [&](const Eigen::Vector2d& q) {
    d->qpos[0] = q[0];
    d->qpos[1] = q[1];
    mju_zero(d->qvel, m->nv);
    mj_forward(m, d);
    return Eigen::Vector2d(d->qfrc_passive[0] - d->qfrc_bias[0],
                           d->qfrc_passive[1] - d->qfrc_bias[1]);
  };
  Eigen::Vector2d q = Eigen::Vector2d::Zero();
  for (int it = 0; it < 30; ++it) {
    const Eigen::Vector2d r = residual(q);
    if (r.norm() < 1e-12) break;
    Eigen::Matrix2d J;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d dq = q;
      dq[k] += 1e-7;
      J.col(k) = (residual(dq) - r) / 1e-7;
    }
    q -= J.partialPivLu().solve(r);
  }
  residual(q);
  const int b = mj_name2id(m, mjOBJ_BODY, "plate");
  Mat3 R;
  for (int i = 0; i < 9; ++i) R(i / 3, i % 3) = d->xmat[9 * b + i];
  return R;
}

class MountTiltTest : public ::testing::TestWithParam<Load> {};

TEST_P(MountTiltTest, MatchesMujocoEquilibriumWhereTheLinearTiltDoesNot) {
  const Load& l = GetParam();
  const auto model = sim::LoadModelFromString(Mjcf(l), "mount_tilt.xml");
  const auto data = sim::MakeData(model.get());
  const Mat3 R_truth = MujocoTilt(model.get(), data.get());
  const Vec3 truth = lie::SO3Log(R_truth);

  const Vec3 g(0.0, 0.0, -9.81);
  const Vec3 s = l.mass * l.com;
  const Vec3 M0 = l.com.cross(l.mass * g);
  const Eigen::Vector2d c(1.0 / 4000.0, 1.0 / 1300.0);
  const Vec3 tilt = MountTilt(c, M0, s, g);
  const Vec3 linear(c.x() * M0.x(), c.y() * M0.y(), 0.0);
  const auto error = [&](const Vec3& t) {
    return lie::SO3Log(R_truth.transpose() * MountRotation(t)).norm();
  };
  const double err = error(tilt), err_linear = error(linear);
  const double err_exp = lie::SO3Log(R_truth.transpose() * lie::SO3Exp(tilt)).norm();
  char figures[256];
  std::snprintf(figures, sizeof(figures),
                "%s: MuJoCo tilt %.3g rad, MountTilt error %.2g (as one Exp %.2g), linear %.2g",
                l.name, truth.norm(), err, err_exp, err_linear);
  SCOPED_TRACE(figures);
  std::printf("%s\n", figures);
  // The same two hinges and springs: equal but for the solvers' tolerances.
  EXPECT_LT(err, 1e-9 * truth.norm());
  // The P-delta term the linear tilt lacks: m g h / k of the tilt about y, at least.
  const double p_delta = l.mass * 9.81 * std::abs(l.com.z()) / 1300.0 * std::abs(truth.y());
  EXPECT_GT(err_linear, 0.5 * p_delta);
  EXPECT_LT(err, 0.1 * err_linear);
  // Pitch, then roll about the pitched axis: one Exp of both misses theta_x theta_y / 2.
  if (std::abs(truth.x() * truth.y()) > 1e-6) {
    EXPECT_LT(err, 0.2 * err_exp);
  }
}

// Stretched forward low, raised high above the plate, off to the side and hanging below it.
INSTANTIATE_TEST_SUITE_P(Loads, MountTiltTest,
                         ::testing::Values(Load{"stretched", Vec3(0.6, 0.0, 0.1), 4.0},
                                           Load{"raised", Vec3(0.15, 0.05, 0.45), 4.0},
                                           Load{"sideways", Vec3(0.3, 0.25, 0.3), 4.0},
                                           Load{"hanging", Vec3(0.4, -0.1, -0.3), 3.0}),
                         [](const ::testing::TestParamInfo<Load>& i) {
                           return std::string(i.param.name);
                         });

// With C = 0 nothing tilts, and the sensitivity to the compliance is the moment at rest.
TEST(MountTilt, ZeroComplianceGivesNoTiltAndTheRestingMomentAsSensitivity) {
  const Vec3 g(0.0, 0.0, -9.81), com(0.5, 0.1, 0.3);
  const Vec3 M0 = com.cross(4.0 * g);
  Eigen::Matrix2d J;
  EXPECT_EQ(MountTilt(Eigen::Vector2d::Zero(), M0, 4.0 * com, g, &J), Vec3::Zero());
  EXPECT_NEAR((J - Eigen::Vector2d(M0.x(), M0.y()).asDiagonal().toDenseMatrix()).norm(), 0.0,
              1e-12);
}

// The sensitivity d theta / d c against central differences of MountTilt itself.
TEST(MountTilt, ComplianceJacobianMatchesFiniteDifferences) {
  const Vec3 g(0.0, 0.0, -9.81), com(0.3, 0.2, 0.4);
  const Vec3 M0 = com.cross(4.0 * g), s = 4.0 * com;
  const Eigen::Vector2d c(2.5e-4, 7.7e-4);
  Eigen::Matrix2d J;
  MountTilt(c, M0, s, g, &J);
  for (int k = 0; k < 2; ++k) {
    Eigen::Vector2d cp = c, cm = c;
    const double h = 1e-7;
    cp[k] += h;
    cm[k] -= h;
    const Vec3 d = (MountTilt(cp, M0, s, g) - MountTilt(cm, M0, s, g)) / (2 * h);
    EXPECT_NEAR((d.head<2>() - J.col(k)).norm(), 0.0, 1e-6 * J.col(k).norm()) << "column " << k;
  }
}

}  // namespace
}  // namespace flexbench::kinematics
