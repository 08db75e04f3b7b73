// Dynamic identification on a log no MuJoCo wrote. A planar two-link arm whose second link bends
// at mid-link and whose second joint has dry friction is integrated here by its own equations of
// motion (Lagrange, derived by hand, RK4); its encoders, commands and IMUs at 500 Hz make a
// recorded log, and identification (MuJoCo rollouts of the rigid, frictionless MJCF of the same
// arm) must name the bending mode and the friction with their values. A first test shows the
// integrator and MuJoCo describe one arm: from one state, under one command, their trajectories
// agree and the gap closes as MuJoCo's time step shrinks.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

#include "scenarios/identify/dynamic/select.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"
#include "sim/rng.h"

namespace flexbench::identify::dynamic {
namespace {

using Vec2 = Eigen::Vector2d;
using State = Eigen::Matrix<double, 6, 1>;  // q1, q2, bend, then their speeds

// The arm's numbers, read by the MJCF and by the integrator. Index 0: link 1; 1: link 2's inner
// half (from joint 2 to the bend); 2: its outer half (beyond the bend hinge). Links lie along
// their body's x; every hinge turns about y, so the arm moves in the x-z plane.
struct Arm {
  double l1 = 0.30, h = 0.15;  // joint 1 to joint 2; joint 2 to the bend hinge
  double m[3] = {0.8, 0.3, 0.4};
  double c[3] = {0.15, 0.075, 0.12};     // centre of mass along the body's x
  double I[3] = {0.006, 0.0006, 0.001};  // about the centre of mass, y
  double armature[3] = {0.01, 0.01, 0.0};
  double damping[3] = {1.0, 0.5, 0.05};  // joint 1, joint 2, bend (the MJCF's)
  double kp[2] = {40.0, 20.0};
  double k_bend = 40.0;                                // the MJCF's bend stiffness
  Vec2 imu[2] = {Vec2(0.20, 0.02), Vec2(0.12, 0.02)};  // site (x, z) on link1, on link2_b
  double g = 9.81;
};

// What the integrator's arm has that the MJCF as identification loads it lacks.
struct Truth {
  bool flexible = true;  // false: the bend held at 0 (the MJCF's locked joint)
  double stiffness_scale = 0.5, damping_scale = 1.0;
  double friction_Nm = 0.25;       // Coulomb friction of joint 2 ...
  double friction_v_rad_s = 0.01;  // ... smoothed as F tanh(qd / v)
};

std::string Num(double x) {
  std::ostringstream s;
  s << std::setprecision(17) << x;
  return s.str();
}

std::string MakeXml(const Arm& a, double timestep) {
  const auto inertial = [&](int k) {
    return "<inertial pos=\"" + Num(a.c[k]) + " 0 0\" mass=\"" + Num(a.m[k]) +
           "\" diaginertia=\"1e-5 " + Num(a.I[k]) + " " + Num(a.I[k]) + "\"/>";
  };
  const auto joint = [&](const char* name, int k) {
    return std::string("<joint name=\"") + name + "\" axis=\"0 1 0\" damping=\"" +
           Num(a.damping[k]) + "\" armature=\"" + Num(a.armature[k]) + "\"";
  };
  const auto site = [&](const char* name, int k) {
    return std::string("<site name=\"") + name + "\" pos=\"" + Num(a.imu[k].x()) + " 0 " +
           Num(a.imu[k].y()) + "\"/>";
  };
  return "<mujoco model=\"indep_arm\"><compiler angle=\"radian\"/>"
         "<option timestep=\"" +
         Num(timestep) + "\" integrator=\"Euler\" gravity=\"0 0 -" + Num(a.g) +
         "\"><flag contact=\"disable\"/></option>"
         "<custom><text name=\"effect:link_bending\" data=\"link2_bend\"/></custom>"
         "<worldbody><body name=\"link1\" pos=\"0 0 0.5\">" +
         joint("joint1", 0) + "/>" + inertial(0) + site("imu_link1", 0) +
         "<body name=\"link2\" pos=\"" + Num(a.l1) + " 0 0\">" + joint("joint2", 1) + "/>" +
         inertial(1) + "<body name=\"link2_b\" pos=\"" + Num(a.h) + " 0 0\">" +
         joint("link2_bend", 2) + " stiffness=\"" + Num(a.k_bend) + "\"/>" + inertial(2) +
         site("imu_link2", 1) +
         "</body></body></body></worldbody><actuator>"
         "<position name=\"joint1\" joint=\"joint1\" kp=\"" +
         Num(a.kp[0]) +
         "\"/>"
         "<position name=\"joint2\" joint=\"joint2\" kp=\"" +
         Num(a.kp[1]) +
         "\"/>"
         "</actuator></mujoco>";
}

// The equations of motion. Absolute angles phi = A q (phi1 = q1, phi2 = q1 + q2, phi3 = phi2 +
// bend); body k's centre of mass is sum_i a_ki u(phi_i) with u(phi) = (cos, -sin) in (x, z)
// (a turn about y), a_ki the lever of angle i: l1, h for the hinges passed, c_k for its own.
// T = 1/2 sum_k (m_k |r_k'|^2 + I_k phi_k'^2) and V = sum_k m_k g z_k give, with
// P_ij = sum_k m_k a_ki a_kj and S_i = sum_k m_k a_ki,
//   M_phi,ij = P_ij cos(phi_i - phi_j) + I_i d_ij
//   c_phi,i  = sum_j P_ij sin(phi_i - phi_j) phi_j'^2            (Coriolis and centrifugal)
//   G_phi,i  = -g S_i cos(phi_i)                                  (dV / dphi_i)
// and in q (A constant): M = A' M_phi A + diag(armature), bias = A' (c_phi + G_phi): MuJoCo's
// qfrc_bias. Forces on q: the servo kp (command - q) plus the feed-forward bias of the actuated
// rows (sim/simulation.h), joint damping, the bend's spring and damping, joint 2's friction.
class PlanarArm {
 public:
  PlanarArm(const Arm& a, const Truth& t) : a_(a), t_(t) {
    const double lever[3][3] = {{a.c[0], 0, 0}, {a.l1, a.c[1], 0}, {a.l1, a.h, a.c[2]}};
    P_.setZero();
    S_.setZero();
    for (int k = 0; k < 3; ++k) {
      for (int i = 0; i < 3; ++i) {
        S_[i] += a.m[k] * lever[k][i];
        for (int j = 0; j < 3; ++j) P_(i, j) += a.m[k] * lever[k][i] * lever[k][j];
      }
    }
    A_ << 1, 0, 0, 1, 1, 0, 1, 1, 1;
  }

  // qdd of state x under command cmd.
  Eigen::Vector3d Acceleration(const State& x, const Vec2& cmd) const {
    const Eigen::Vector3d phi = A_ * x.head<3>(), phid = A_ * x.tail<3>();
    Eigen::Matrix3d Mphi;
    Eigen::Vector3d bias_phi;
    for (int i = 0; i < 3; ++i) {
      bias_phi[i] = -a_.g * S_[i] * std::cos(phi[i]);
      for (int j = 0; j < 3; ++j) {
        Mphi(i, j) = P_(i, j) * std::cos(phi[i] - phi[j]) + (i == j ? a_.I[i] : 0.0);
        bias_phi[i] += P_(i, j) * std::sin(phi[i] - phi[j]) * phid[j] * phid[j];
      }
    }
    Eigen::Matrix3d M = A_.transpose() * Mphi * A_;
    const Eigen::Vector3d bias = A_.transpose() * bias_phi;
    Eigen::Vector3d tau;
    for (int i = 0; i < 3; ++i) {
      M(i, i) += a_.armature[i];
      tau[i] = -a_.damping[i] * x[3 + i];
    }
    for (int i = 0; i < 2; ++i) tau[i] += a_.kp[i] * (cmd[i] - x[i]) + bias[i];
    tau[1] -= t_.friction_Nm * std::tanh(x[4] / t_.friction_v_rad_s);
    tau[2] = -t_.stiffness_scale * a_.k_bend * x[2] - t_.damping_scale * a_.damping[2] * x[5];
    Eigen::Vector3d qdd = Eigen::Vector3d::Zero();
    if (t_.flexible) {
      qdd = M.ldlt().solve(tau - bias);
    } else {
      qdd.head<2>() = M.topLeftCorner<2, 2>().ldlt().solve((tau - bias).head<2>());
    }
    return qdd;
  }

  void Rk4(State* x, const Vec2& cmd, double dt) const {
    const auto f = [&](const State& s) {
      State d;
      d << s.tail<3>(), Acceleration(s, cmd);
      return d;
    };
    const State k1 = f(*x), k2 = f(*x + 0.5 * dt * k1), k3 = f(*x + 0.5 * dt * k2),
                k4 = f(*x + dt * k3);
    *x += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
  }

  // The bend at rest with the actuated joints at q: spring = gravity on the outer half
  // (k s b = g S_3 cos(phi3)), by Newton.
  double RestingBend(const Vec2& q) const {
    if (!t_.flexible) return 0.0;
    const double k = t_.stiffness_scale * a_.k_bend, w = a_.g * S_[2];
    double b = 0.0;
    for (int it = 0; it < 50; ++it) {
      const double phi3 = q[0] + q[1] + b;
      b -= (k * b - w * std::cos(phi3)) / (k + w * std::sin(phi3));
    }
    return b;
  }

  // IMU `i` (0: link 1, 1: link 2's outer half): gyro and specific force in its site frame
  // (+g up at rest). Site at s = (x, z) on the body of angle phi_f: p = sum levers + s_x u +
  // s_z n, n(phi) = (sin, cos), u' = -n, n' = u; the frame's axes are u (x), y and n (z).
  void Imu(int i, const State& x, const Vec2& cmd, Eigen::Vector3d* gyro,
           Eigen::Vector3d* accel) const {
    const Eigen::Vector3d phi = A_ * x.head<3>(), phid = A_ * x.tail<3>();
    const Eigen::Vector3d phidd = A_ * Acceleration(x, cmd);
    const auto u = [](double p) { return Vec2(std::cos(p), -std::sin(p)); };
    const auto n = [](double p) { return Vec2(std::sin(p), std::cos(p)); };
    const int f = i == 0 ? 0 : 2;  // the angle of the site's body
    const double lever[2] = {a_.l1, a_.h};
    Vec2 acc = Vec2::Zero();
    for (int k = 0; k < f; ++k) {
      acc += lever[k] * (-phidd[k] * n(phi[k]) - phid[k] * phid[k] * u(phi[k]));
    }
    const Vec2 s = a_.imu[i];
    acc += s.x() * (-phidd[f] * n(phi[f]) - phid[f] * phid[f] * u(phi[f]));
    acc += s.y() * (phidd[f] * u(phi[f]) - phid[f] * phid[f] * n(phi[f]));
    const Vec2 sf = acc + Vec2(0.0, a_.g);
    *gyro = Eigen::Vector3d(0.0, phid[f], 0.0);
    *accel = Eigen::Vector3d(sf.dot(u(phi[f])), 0.0, sf.dot(n(phi[f])));
  }

 private:
  Arm a_;
  Truth t_;
  Eigen::Matrix3d P_, A_;
  Eigen::Vector3d S_;
};

// Each joint a sum of three sines about its centre, faded in over `fade_s`.
Vec2 Command(double t, double fade_s) {
  const double center[2] = {-0.3, 0.6}, amplitude[2] = {0.6, 0.9};
  const double freq[2][3] = {{0.31, 0.73, 1.37}, {0.47, 1.09, 1.91}};
  const double phase[2][3] = {{0.3, 2.1, 4.0}, {1.2, 5.0, 2.7}};
  const double fade = t < fade_s ? 0.5 - 0.5 * std::cos(M_PI * t / fade_s) : 1.0;
  Vec2 c;
  for (int j = 0; j < 2; ++j) {
    double s = 0.0;
    for (int k = 0; k < 3; ++k) s += std::sin(2.0 * M_PI * freq[j][k] * t + phase[j][k]);
    c[j] = center[j] + fade * amplitude[j] * s / 3.0;
  }
  return c;
}

constexpr double kRk4Step = 1e-4;
constexpr double kHoldS = 1e-3;  // the verification's command rate

// Joint 1, joint 2 and the bend every kHoldS for 1 s from rest at the command's start, the
// command held over each kHoldS: MuJoCo at step `dt`, or (dt = 0) the integrator.
std::vector<Eigen::Vector3d> Trajectory(const Arm& arm, const Truth& truth, double dt) {
  std::vector<DynamicTerm> declared;
  if (truth.flexible) {
    declared.push_back(
        {sim::DynamicKind::kLinkMode, "link2_b", {truth.stiffness_scale, truth.damping_scale}});
  }
  RolloutModel model(sim::LoadModelFromString(MakeXml(arm, dt > 0 ? dt : kHoldS), "indep_arm"),
                     "indep_arm", declared);
  std::unique_ptr<sim::Simulation> mj = model.Make({});
  const int bend = sim::JointId(mj->model(), "link2_bend");
  const PlanarArm own(arm, truth);
  const Vec2 c0 = Command(0.0, 0.0);
  mj->SetCommand(c0);
  mj->Settle();
  State x = State::Zero();
  x.head<2>() = c0;
  x[2] = own.RestingBend(c0);
  EXPECT_NEAR(mj->JointPosition(bend), x[2], 1e-9) << "resting bend";
  const int sub = static_cast<int>(std::lround(kHoldS / (dt > 0 ? dt : kRk4Step)));
  std::vector<Eigen::Vector3d> out;
  for (int k = 0; k < static_cast<int>(std::lround(1.0 / kHoldS)); ++k) {
    const Vec2 cmd = Command(k * kHoldS, 0.0);
    mj->SetCommand(cmd);
    for (int s = 0; s < sub; ++s) {
      if (dt > 0) {
        mj->Step(1);
      } else {
        own.Rk4(&x, cmd, kHoldS / sub);
      }
    }
    out.push_back(dt > 0 ? Eigen::Vector3d(mj->JointPosition("joint1"), mj->JointPosition("joint2"),
                                           mj->JointPosition(bend))
                         : Eigen::Vector3d(x.head<3>()));
  }
  return out;
}

double LargestGap(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b) {
  double gap = 0.0;
  for (size_t k = 0; k < a.size(); ++k) gap = std::max(gap, (a[k] - b[k]).cwiseAbs().maxCoeff());
  return gap;
}

// MuJoCo's Euler is first order: its gap to the integrator shrinks tenfold with a tenfold
// shorter step, and the two steps' Richardson extrapolation (10 fine - coarse) / 9 removes that
// first-order error. A derivation error would leave a gap no step removes.
TEST(IndependentIntegrator, AgreesWithMujocoRigidAndFlexible) {
  const Arm arm;
  for (const bool flexible : {false, true}) {
    Truth truth;
    truth.flexible = flexible;
    truth.friction_Nm = 0.0;
    const auto own = Trajectory(arm, truth, 0.0);
    const auto coarse = Trajectory(arm, truth, 1e-3), fine = Trajectory(arm, truth, 1e-4);
    std::vector<Eigen::Vector3d> extrapolated(own.size());
    for (size_t k = 0; k < own.size(); ++k) extrapolated[k] = (10.0 * fine[k] - coarse[k]) / 9.0;
    const double gc = LargestGap(own, coarse), gf = LargestGap(own, fine),
                 ge = LargestGap(own, extrapolated);
    std::printf("%s: largest gap %.3g rad at MuJoCo's 1 ms, %.3g at 0.1 ms, %.3g extrapolated\n",
                flexible ? "flexible" : "rigid", gc, gf, ge);
    EXPECT_GT(gc / gf, 8.0) << (flexible ? "flexible" : "rigid");
    EXPECT_LT(ge, 1e-5) << (flexible ? "flexible" : "rigid");
  }
}

// The integrator's arm moved by the multi-sine for `seconds`: each 2 ms the encoders (with
// noise), the command sent then (held until the next) and both IMUs (with noise) as a log.
sim::RecordedLog IntegratorLog(const Arm& arm, const Truth& truth, double seconds) {
  constexpr double kRowS = 0.002, kStdQ = 5e-4, kStdGyro = 0.01, kStdAccel = 0.05;
  const PlanarArm own(arm, truth);
  sim::NoiseStream rng(7, "independent_integrator");
  sim::RecordedLog log;
  log.dir = "independent_integrator";
  log.robot = "indep_arm";
  log.joints = {"joint1", "joint2"};
  log.joint_is_slide = {0, 0};
  log.command_joints = log.joints;
  log.command_is_slide = log.joint_is_slide;
  log.joint_std = kStdQ;
  log.gyro_std = kStdGyro;
  log.accel_std = kStdAccel;
  log.imus = {{"imu1", "imu_link1", false, Quat::Identity()},
              {"imu2", "imu_link2", false, Quat::Identity()}};
  const Vec2 c0 = Command(0.0, 1.0);
  State x = State::Zero();
  x.head<2>() = c0;
  x[2] = own.RestingBend(c0);
  const int rows = static_cast<int>(std::lround(seconds / kRowS));
  const int sub = static_cast<int>(std::lround(kRowS / kRk4Step));
  for (int r = 0; r <= rows; ++r) {
    const double t = r * kRowS;
    const Vec2 cmd = Command(t, 1.0);
    log.joint_t.push_back(t);
    log.command_t.push_back(t);
    for (int j = 0; j < 2; ++j) {
      log.joint_q.push_back(x[j] + rng.Normal(kStdQ));
      log.command_q.push_back(cmd[j]);
    }
    for (int i = 0; i < 2; ++i) {
      estimators::ImuReading z;
      z.t = t;
      z.imu = i;
      own.Imu(i, x, cmd, &z.gyro, &z.accel);
      for (int a = 0; a < 3; ++a) {
        z.gyro[a] += rng.Normal(kStdGyro);
        z.accel[a] += rng.Normal(kStdAccel);
      }
      log.imu.push_back(z);
    }
    for (int s = 0; s < sub; ++s) own.Rk4(&x, cmd, kRowS / sub);
  }
  return log;
}

const ChosenEffect* Find(const DynamicReport& rep, const std::string& name) {
  for (const ChosenEffect& c : rep.chosen) {
    if (c.name == name ||
        std::find(c.equivalent.begin(), c.equivalent.end(), name) != c.equivalent.end()) {
      return &c;
    }
  }
  return nullptr;
}

// The log of the arm with its link bending at half the MJCF's stiffness and dry friction on
// joint 2; the rollout model is the MJCF as written (bend locked, no friction), every candidate
// family at every location.
TEST(IndependentIntegrator, IdentifiesBendingModeAndFriction) {
  const auto start = std::chrono::steady_clock::now();
  const Arm arm;
  const Truth truth;
  const sim::RecordedLog log = IntegratorLog(arm, truth, 10.0);
  RolloutModel model(sim::LoadModelFromString(MakeXml(arm, 1e-3), "indep_arm"), "indep_arm", {});
  const MotionData data = ReadMotionData(log, model.nominal(), MotionOptions{});
  DynamicProblem problem(model, data, AllCandidates(model.nominal(), {}), 2);
  const DynamicReport rep = IdentifyDynamics(problem, DynamicIdentifyOptions{});
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  for (const std::string& line : rep.log) std::printf("  %s\n", line.c_str());
  for (const ChosenEffect& c : rep.chosen) {
    std::printf("chosen %s:", c.name.c_str());
    for (size_t k = 0; k < c.values.size(); ++k) {
      std::printf(" %s %.4g (+- %.2g)", c.value_names[k].c_str(), c.values[k], c.std_errors[k]);
    }
    for (const std::string& e : c.equivalent) std::printf(" ~ %s", e.c_str());
    std::printf("\n");
  }
  for (const StreamError& e : rep.streams) {
    std::printf("%s: noise %.3g %s, rms %.3g -> %.3g\n", e.stream.c_str(), e.noise, e.unit.c_str(),
                e.rms_before, e.rms_after);
  }
  const double ratio = rep.heldout_after / rep.heldout_before;
  std::printf("held-out %.4g -> %.4g (ratio %.3g), verdict %s, %ld rollouts, %.1f s\n",
              rep.heldout_before, rep.heldout_after, ratio, rep.verdict.c_str(), rep.rollouts,
              seconds);

  const ChosenEffect* friction = Find(rep, "joint_friction@joint2");
  ASSERT_NE(friction, nullptr) << "joint_friction@joint2 not among the chosen effects";
  if (friction->name == "joint_friction@joint2") {
    EXPECT_NEAR(friction->values[0], truth.friction_Nm, 0.15 * truth.friction_Nm);
  }
  const ChosenEffect* mode = Find(rep, "link_mode@link2_b");
  ASSERT_NE(mode, nullptr) << "link_mode@link2_b not among the chosen effects";
  ASSERT_EQ(mode->name, "link_mode@link2_b");
  // The mode's damping scale is left ungated: the segments' start speeds (a line through 20 ms
  // of encoder rows each side) are biased by the mode's own vibration, which the damping absorbs.
  EXPECT_NEAR(mode->values[0], truth.stiffness_scale, 0.10 * truth.stiffness_scale);
  EXPECT_LT(ratio, 0.5);
}

}  // namespace
}  // namespace flexbench::identify::dynamic
