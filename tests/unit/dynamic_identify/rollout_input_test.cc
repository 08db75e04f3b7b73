// What dynamic identification refuses and what it survives: a log without commands, a command
// outside an actuator's range, segments shorter than the model's step are one line each; a
// rollout that diverges is a counted segment, not a crash. And the servo delay the rollouts and
// the truth share: a delayed servo follows the same commands the same way, later by the delay.
// A torque log replays the servo's trajectory with the servo off.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "estimators/error.h"
#include "scenarios/identify/dynamic/fit.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"
#include "sim/simulation.h"
#include "tests/unit/dynamic_identify/sine_log.h"

namespace flexbench::identify::dynamic {
namespace {

// A pendulum on a position servo; kp is the test's (a huge one makes Euler steps diverge).
std::string Pendulum(double kp) {
  return R"(<mujoco model="pendulum"><compiler autolimits="true" angle="radian"/><option timestep="0.001" integrator="Euler"/>
  <worldbody><body name="arm" pos="0 0 1">
    <joint name="j" axis="0 1 0" range="-2 2" damping="0.1" armature="0.01"/>
    <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5"/>
    <site name="imu" pos="0.3 0 0"/></body></worldbody>
  <actuator><position name="j" joint="j" kp=")" +
         std::to_string(kp) + R"(" ctrlrange="-1.5 1.5"/></actuator></mujoco>)";
}

std::string ErrorOf(const sim::RecordedLog& log, const MotionOptions& o) {
  RolloutModel model(sim::LoadModelFromString(Pendulum(20), "pendulum"), "pendulum", {});
  try {
    ReadMotionData(log, model.nominal(), o);
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << "one line: " << e.what();
    return e.what();
  }
  return "";
}

TEST(DynamicInput, BadLogsAreOneLineNamingWhatIsWrong) {
  sim::RecordedLog no_commands = SineLog(0.5);
  no_commands.command_t.clear();
  EXPECT_NE(ErrorOf(no_commands, {}).find("no `commands`"), std::string::npos);
  EXPECT_NE(ErrorOf(SineLog(1.8), {}).find("outside its actuator's range [-1.5, 1.5]"),
            std::string::npos);
  MotionOptions short_segments;
  short_segments.segment_s = 0.0005;
  EXPECT_NE(ErrorOf(SineLog(0.5), short_segments).find("shorter than the model's time step"),
            std::string::npos);
  MotionOptions one_segment;
  one_segment.segment_s = 5.0;
  EXPECT_NE(ErrorOf(SineLog(0.5), one_segment).find("fewer than two segments"), std::string::npos);
  EXPECT_EQ(ErrorOf(SineLog(0.5), {}), "");
}

TEST(DynamicInput, ADivergingRolloutIsACountedSegment) {
  // kp 1e9 on 0.01 kg m^2 at 1 ms: explicit Euler blows up within a few steps.
  RolloutModel model(sim::LoadModelFromString(Pendulum(1e9), "pendulum"), "pendulum", {});
  const MotionData data = ReadMotionData(SineLog(0.5), model.nominal(), {});
  const ResidualLayout layout = MakeLayout(data);
  const Prediction p = Rollout(model, {}, data, layout);
  EXPECT_EQ(p.num_diverged, static_cast<int>(data.segments.size()));
  EXPECT_NE(p.first_divergence.find("diverged"), std::string::npos) << p.first_divergence;
  EXPECT_TRUE(p.residual.allFinite());
}

TEST(ServoDelay, ADelayedServoFollowsTheSameCommandsLater) {
  const double dt = 0.001, delay = 0.02;
  auto plain = sim::Simulation::FromString(Pendulum(20), "pendulum");
  auto late = sim::Simulation::FromString(Pendulum(20), "pendulum", [] {
    sim::EffectList e;
    e.push_back(sim::MakeEffect("servo_delay", "{s: 0.02}"));
    return e;
  }());
  const int lag = static_cast<int>(std::lround(delay / dt));
  std::vector<double> q_plain, q_late;
  for (int k = 0; k < 400; ++k) {
    const double c = k * dt < 0.1 ? 0.0 : 0.4 * std::sin(8 * (k * dt - 0.1));
    Eigen::VectorXd cmd(1);
    cmd << c;
    plain->SetCommand(cmd);
    late->SetCommand(cmd);
    q_plain.push_back(plain->JointPosition("j"));
    q_late.push_back(late->JointPosition("j"));
    plain->Step(1);
    late->Step(1);
  }
  double moved = 0.0;
  for (int k = 0; k + lag < 400; ++k) {
    EXPECT_NEAR(q_late[k + lag], q_plain[k], 1e-12) << "step " << k;
    moved = std::max(moved, std::abs(q_plain[k]));
  }
  EXPECT_GT(moved, 0.1) << "q at the end " << q_plain.back();  // the commands moved the arm
}

// A torque log is what the motor did: the servo-driven pendulum's torque of each step, applied
// to a second pendulum with its servo off from the same state, gives the same trajectory (the
// same model: to the last bits the float sums allow).
TEST(TorqueCommands, TheLoggedMotorTorquesReplayTheServosTrajectory) {
  auto servo = sim::Simulation::FromString(Pendulum(20), "pendulum");
  auto motor = sim::Simulation::FromString(Pendulum(20), "pendulum");
  Eigen::VectorXd cmd(1), tau(1), q0(1), qd0(1);
  cmd << 0.2;
  servo->SetCommand(cmd);
  servo->Settle();
  q0 << servo->JointPosition("j");
  qd0 << 0.0;
  motor->SetCommand(cmd);
  motor->Settle();
  motor->SetActuatedState(servo->time(), q0, qd0);
  double worst = 0.0, moved = 0.0, torque = 0.0;
  for (int k = 0; k < 600; ++k) {
    cmd << 0.2 + 0.5 * std::sin(6.0 * k * 0.001);
    servo->SetCommand(cmd);
    servo->Step(1);
    tau << servo->MotorTorque(0);
    torque = std::max(torque, std::abs(tau[0]));
    motor->SetTorque(tau);
    motor->Step(1);
    worst = std::max(worst, std::abs(motor->JointPosition("j") - servo->JointPosition("j")));
    moved = std::max(moved, std::abs(servo->JointPosition("j") - q0[0]));
  }
  EXPECT_GT(moved, 0.2);
  EXPECT_GT(torque, 0.5);
  EXPECT_LT(worst, 1e-12);
  EXPECT_THROW(servo->MotorTorque(1), std::invalid_argument);  // one actuated joint
  EXPECT_THROW(servo->MotorTorque(-1), std::invalid_argument);
  // SetCommand switches the servo back on: it pulls towards the command again.
  cmd << 0.0;
  motor->SetCommand(cmd);
  motor->Step(300);
  EXPECT_LT(std::abs(motor->JointPosition("j")), 0.1);
}

// A torque log written and read back: type torque, <joint>_Nm columns, every digit.
TEST(TorqueCommands, ATorqueLogRoundTrips) {
  sim::RecordedLog log = SineLog(0.3);
  log.command_torque = true;
  log.robot = "pendulum";
  log.declared_path = "pendulum.declared.yaml";
  const std::string dir = "/tmp/flexbench_torque_log_" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  sim::WriteRecordedLog(log, dir);
  std::ifstream in(dir + "/commands.csv");
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "t_s,j_Nm");
  const sim::RecordedLog back = sim::ReadRecordedLog(dir);
  EXPECT_TRUE(back.command_torque);
  EXPECT_EQ(back.command_q, log.command_q);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace flexbench::identify::dynamic
