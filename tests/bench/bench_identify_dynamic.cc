// Speed of dynamic identification (scenarios/identify/dynamic/) on a moving 7-joint arm. No
// model of models/ has seven actuated joints and IMUs on two links, so the arm is inline: position
// servos, IMU sites on link2_b and link4, a bending link (link2_b's passive hinges, listed as
// effect:link_bending) and a payload body. Its truth has dry friction and a servo delay at j2
// and j4; 60 s of a multi-sine at 500 Hz (encoders and both IMUs, with the commands) are
// simulated once, outside the timing.
//  - BM_IdentifyDynamic: ReadMotionData, DynamicProblem and IdentifyDynamics with every stage on,
//    10 candidates (six families: the truth's four and six stand-ins), threads 2. Target at
//    most 120 s; one iteration, 3 repetitions: quote the median.
//  - BM_SegmentRollout: Rollout over a log holding one 0.5 s segment (a simulation made for it,
//    a settle, the segment's steps); BM_LogRollout: Rollout over the whole log, per segment.
//  - BM_SegmentJacobian: the finite-difference Jacobian of that segment over the 10
//    candidates' 11 parameters (one rollout each), on 1 and 2 threads.
//  - BM_MjStep: one mj_step of the same MJCF: the unit the rollouts are measured in.
#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "scenarios/identify/dynamic/select.h"
#include "sim/config.h"
#include "sim/motion_log.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"
#include "sim/rng.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::identify::dynamic {
namespace {

// Joint damping and rotor inertia of each servo as the MJCF states them; every spring and
// servo satisfies k < 4 I / dt^2 at the 1 ms step.
constexpr char kArmXml[] = R"(
<mujoco model="arm7">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001" integrator="Euler">
    <flag contact="disable"/>
  </option>
  <default>
    <geom contype="0" conaffinity="0"/>
    <joint armature="0.002"/>
    <default class="servo">
      <joint damping="1.5" armature="0.02"/>
    </default>
  </default>
  <custom>
    <text name="effect:link_bending" data="link2_bend_y link2_bend_x"/>
    <text name="effect:payload" data="hand"/>
  </custom>
  <worldbody>
    <body name="base_link" pos="0 0 0.5">
      <geom type="cylinder" pos="0 0 0.04" size="0.07 0.04" mass="2"/>
      <body name="link1" pos="0 0 0.08">
        <joint name="j1" class="servo" axis="0 0 1"/>
        <inertial pos="0 0 0.04" mass="0.8" diaginertia="0.002 0.002 0.001"/>
        <body name="link2" pos="0 0 0.08">
          <joint name="j2" class="servo" axis="0 1 0"/>
          <inertial pos="0 0 0.08" mass="0.6" diaginertia="0.002 0.002 0.0003"/>
          <body name="link2_b" pos="0 0 0.16">
            <joint name="link2_bend_y" axis="0 1 0" stiffness="600" damping="0.5"/>
            <joint name="link2_bend_x" axis="1 0 0" stiffness="600" damping="0.5"/>
            <inertial pos="0 0 0.08" mass="0.5" diaginertia="0.0015 0.0015 0.0003"/>
            <site name="imu_link2" pos="0.03 0 0.08" size="0.01"/>
            <body name="link3" pos="0 0 0.16">
              <joint name="j3" class="servo" axis="0 0 1"/>
              <inertial pos="0 0 0.04" mass="0.4" diaginertia="0.0006 0.0006 0.0002"/>
              <body name="link4" pos="0 0 0.08">
                <joint name="j4" class="servo" axis="0 1 0"/>
                <inertial pos="0 0 0.1" mass="0.4" diaginertia="0.0012 0.0012 0.0002"/>
                <site name="imu_link4" pos="0.025 0 0.1" size="0.01"/>
                <body name="link5" pos="0 0 0.2">
                  <joint name="j5" class="servo" axis="0 0 1"/>
                  <inertial pos="0 0 0.03" mass="0.25" diaginertia="0.0002 0.0002 0.0001"/>
                  <body name="link6" pos="0 0 0.06">
                    <joint name="j6" class="servo" axis="0 1 0"/>
                    <inertial pos="0 0 0.03" mass="0.2" diaginertia="0.0002 0.0002 0.0001"/>
                    <body name="hand" pos="0 0 0.06">
                      <joint name="j7" class="servo" axis="0 0 1"/>
                      <inertial pos="0 0 0.04" mass="0.3" diaginertia="0.0003 0.0003 0.0002"/>
                      <site name="ee" pos="0 0 0.1" size="0.01"/>
                    </body>
                  </body>
                </body>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="j1" joint="j1" kp="150"/>
    <position name="j2" joint="j2" kp="250"/>
    <position name="j3" joint="j3" kp="80"/>
    <position name="j4" joint="j4" kp="120"/>
    <position name="j5" joint="j5" kp="40"/>
    <position name="j6" joint="j6" kp="40"/>
    <position name="j7" joint="j7" kp="20"/>
  </actuator>
</mujoco>
)";

constexpr char kTruthEffects[] = R"(
joint_friction: {Nm: {j2: 0.3, j4: 0.15}}
servo_delay: {s: {j2: 0.02, j4: 0.015}}
)";

constexpr char kSensors[] = R"(
sensors:
- {name: encoders, kind: encoder, side: link, noise_std_deg: 0.02, counts_per_rev: 65536, rate_hz: 500}
- {name: imu2, kind: imu, site: imu_link2, gyro_noise_std_rad_s: 0.003, accel_noise_std_m_s2: 0.05, rate_hz: 500}
- {name: imu4, kind: imu, site: imu_link4, gyro_noise_std_rad_s: 0.003, accel_noise_std_m_s2: 0.05, rate_hz: 500}
)";

// The truth's four and a stand-in from each other family the arm has a location for.
const char* const kCandidates[] = {"joint_friction@j2", "joint_friction@j4", "servo_delay@j2",
                                   "servo_delay@j4",    "joint_damping@j2",  "joint_damping@j4",
                                   "joint_armature@j2", "servo_gain@j4",     "link_mode@link2_b",
                                   "payload_mass@hand"};

constexpr double kDurationS = 60.0;
constexpr double kCommandRateHz = 500.0;

sim::RecordedLog SimulateTruth() {
  const sim::EffectList effects =
      sim::ParseEffects(ConfigNode::LoadString(kTruthEffects, "bench truth effects"));
  const std::unique_ptr<sim::Simulation> truth =
      sim::Simulation::FromString(kArmXml, "arm7", effects);
  sim::SensorSuite sensors = sim::SensorSuite::Parse(
      ConfigNode::LoadString(kSensors, "bench").Child("sensors"), *truth, 1);
  const double deg = M_PI / 180.0;
  sim::MultiSine motion;
  motion.frequencies = {0.23, 0.61, 1.3};
  for (double c : {0.0, 30.0, 0.0, 40.0, 0.0, 20.0, 0.0}) motion.center.push_back(c * deg);
  for (double a : {40.0, 25.0, 40.0, 30.0, 40.0, 30.0, 40.0}) motion.amplitude.push_back(a * deg);
  motion.DrawPhases(1, "bench_identify_dynamic/phases", truth->num_actuated());
  sim::MotionLogOptions o;
  o.duration_s = kDurationS;
  o.command_rate_hz = kCommandRateHz;
  o.encoder_std = 0.02 * deg;
  o.gyro_std = 0.003;
  o.accel_std = 0.05;
  sim::RecordedLog log = sim::SimulateMotionLog(*truth, sensors, motion, o);
  log.dir = "arm7 (simulated)";
  return log;
}

struct Arm {
  sim::RecordedLog log;
  std::unique_ptr<RolloutModel> model;
  std::vector<Candidate> candidates;
  MotionData data;  // the whole log, as identification reads it
};

Arm& TheArm() {
  static Arm a;
  if (a.model) return a;
  a.log = SimulateTruth();
  a.model = std::make_unique<RolloutModel>(sim::LoadModelFromString(kArmXml, "arm7.xml"), "arm7",
                                           std::vector<DynamicTerm>{});
  const std::vector<Candidate> all = AllCandidates(a.model->nominal(), {});
  for (const char* name : kCandidates) {
    bool found = false;
    for (const Candidate& c : all) {
      if (c.Name() != name) continue;
      a.candidates.push_back(c);
      found = true;
    }
    if (!found) std::abort();
  }
  a.data = ReadMotionData(a.log, a.model->nominal(), MotionOptions());
  return a;
}

// The log cut to one segment (past the fade-in): what one multiple-shooting rollout covers.
MotionData OneSegment(const MotionData& all) {
  const int s = static_cast<int>(all.segments.size()) / 2;
  MotionData one = all;
  one.segments = {all.segments[s]};
  one.segments[0].fold = 0;
  one.start_qd = all.start_qd.row(s);
  one.folds = 1;
  return one;
}

void BM_IdentifyDynamic(benchmark::State& state) {
  Arm& a = TheArm();
  DynamicReport rep;
  for (auto _ : state) {
    const MotionData data = ReadMotionData(a.log, a.model->nominal(), MotionOptions());
    DynamicProblem problem(*a.model, data, a.candidates, /*threads=*/2);
    rep = IdentifyDynamics(problem, DynamicIdentifyOptions());
    benchmark::DoNotOptimize(rep.rollouts);
  }
  std::string chosen;
  for (const ChosenEffect& c : rep.chosen) chosen += (chosen.empty() ? "" : " ") + c.name;
  state.counters["candidates"] = a.candidates.size();
  state.counters["segments"] = rep.segments;
  state.counters["rollouts"] = rep.rollouts;
  state.counters["effects_found"] = rep.chosen.size();
  state.counters["heldout_ratio"] = rep.heldout_after / rep.heldout_before;
  state.SetLabel(rep.verdict + ": " + chosen);
}
BENCHMARK(BM_IdentifyDynamic)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

void BM_SegmentRollout(benchmark::State& state) {
  Arm& a = TheArm();
  const MotionData one = OneSegment(a.data);
  const ResidualLayout layout = MakeLayout(one);
  for (auto _ : state) {
    const Prediction p = Rollout(*a.model, {}, one, layout);
    benchmark::DoNotOptimize(p.error.data());
  }
  state.counters["steps"] =
      std::lround((one.t[one.segments[0].row_end - 1] - one.t[one.segments[0].row_begin]) /
                  a.model->nominal().timestep());
  state.counters["entries"] = layout.size();
}
BENCHMARK(BM_SegmentRollout)->Unit(benchmark::kMillisecond);

// The whole log's rollout: a segment's share once the simulation is made and settled.
void BM_LogRollout(benchmark::State& state) {
  Arm& a = TheArm();
  const ResidualLayout layout = MakeLayout(a.data);
  for (auto _ : state) {
    const Prediction p = Rollout(*a.model, {}, a.data, layout);
    benchmark::DoNotOptimize(p.error.data());
  }
  state.counters["segments"] = a.data.segments.size();
}
BENCHMARK(BM_LogRollout)->Unit(benchmark::kMillisecond)->UseRealTime();

// Arg: threads.
void BM_SegmentJacobian(benchmark::State& state) {
  Arm& a = TheArm();
  const DynamicProblem problem(*a.model, OneSegment(a.data), a.candidates,
                               static_cast<int>(state.range(0)));
  std::vector<int> active(a.candidates.size());
  for (size_t i = 0; i < active.size(); ++i) active[i] = static_cast<int>(i);
  const Eigen::VectorXd theta = problem.Neutral(active);
  const FitState at = problem.Evaluate(active, theta, problem.Mask(-1));
  for (auto _ : state) {
    const Eigen::MatrixXd J = problem.Jacobian(active, theta, at.prediction);
    benchmark::DoNotOptimize(J.data());
  }
  state.counters["parameters"] = theta.size();
}
BENCHMARK(BM_SegmentJacobian)
    ->ArgName("threads")
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_MjStep(benchmark::State& state) {
  const sim::MjModelPtr model = sim::LoadModelFromString(kArmXml, "arm7.xml");
  const sim::MjDataPtr data = sim::MakeData(model.get());
  mjModel* m = model.get();
  mjData* d = data.get();
  for (int k = 0; k < m->nu; ++k) d->ctrl[k] = 0.3;
  for (auto _ : state) {
    mj_step(m, d);
  }
  benchmark::DoNotOptimize(d->qpos[0]);
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MjStep)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace flexbench::identify::dynamic

BENCHMARK_MAIN();
