// Sensor noise models against their specification: mean and standard deviation over 10,000
// samples within 3 sigma of the sampling distribution, quantisation steps, offsets and biases
// from effects, the IMU's gravity at rest and MuJoCo's own gyro/accelerometer in motion,
// rates and timestamps, seeding.
#include <gtest/gtest.h>

#include <cmath>
#include <set>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "sim/camera.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"
#include "sim/trajectory.h"

namespace flexbench::sim {
namespace {

constexpr int kSamples = 10000;

// A pendulum with a passive spring joint at its tip, an IMU site, a fingertip and a table.
const char kPendulum[] = R"(
<mujoco model="pendulum">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.001"/>
  <custom>
    <text name="effect:link_bending" data="tip_bend"/>
    <text name="effect:joint_compliance" data="hinge"/>
    <numeric name="effect:joint_compliance:stiffness" data="80"/>
  </custom>
  <worldbody>
    <geom name="table" type="box" pos="0.45 0 0.75" size="0.2 0.2 0.02" contype="0" conaffinity="0"/>
    <camera name="cam" pos="0.2 -1.0 1.0" xyaxes="1 0 0 0 0 1" fovy="50"/>
    <body name="link" pos="0 0 1">
      <joint name="hinge" axis="0 1 0" damping="2" armature="0.01"/>
      <inertial pos="0.2 0 0" mass="1" diaginertia="0.005 0.02 0.02"/>
      <site name="imu" pos="0.2 0 0"/>
      <site name="imu_tilted" pos="0.2 0 0" zaxis="1 0 1"/>
      <body name="tip" pos="0.4 0 0">
        <joint name="tip_bend" axis="0 1 0" stiffness="60" damping="0.3" armature="0.001"/>
        <inertial pos="0.05 0 0" mass="0.2" diaginertia="0.0002 0.0005 0.0005"/>
        <site name="finger" pos="0.1 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator><position name="hinge" joint="hinge" kp="300"/></actuator>
  <sensor>
    <gyro name="imu_gyro" site="imu"/>
    <accelerometer name="imu_accel" site="imu"/>
  </sensor>
</mujoco>)";

std::unique_ptr<Simulation> Pendulum(EffectList effects = {}) {
  return Simulation::FromString(kPendulum, "pendulum.xml", effects);
}

EffectList Effects(const std::vector<std::pair<std::string, std::string>>& list) {
  EffectList out;
  for (const auto& [name, params] : list) out.push_back(MakeEffect(name, params));
  return out;
}

struct Stats {
  double mean = 0.0;
  double std = 0.0;
};

Stats Compute(const std::vector<double>& v) {
  Stats s;
  for (double x : v) s.mean += x;
  s.mean /= v.size();
  for (double x : v) s.std += (x - s.mean) * (x - s.mean);
  s.std = std::sqrt(s.std / (v.size() - 1));
  return s;
}

// Sample mean within 3 standard errors of `mean`, sample std within 3 standard errors of `std`
// (standard error of the std of a normal sample: std / sqrt(2 (n - 1))).
void ExpectNormal(const std::vector<double>& v, double mean, double std) {
  const Stats s = Compute(v);
  const double n = static_cast<double>(v.size());
  EXPECT_NEAR(s.mean, mean, 3.0 * std / std::sqrt(n)) << "sample mean";
  EXPECT_NEAR(s.std, std, 3.0 * std / std::sqrt(2.0 * (n - 1.0))) << "sample std";
}

template <class T>
std::vector<T> Take(const std::vector<SensorReading>& readings) {
  std::vector<T> out;
  for (const SensorReading& r : readings) {
    if (const T* x = std::get_if<T>(&r)) out.push_back(*x);
  }
  return out;
}

std::vector<SensorReading> SampleMany(Sensor& s, const Simulation& sim, int n, double dt = 0.01) {
  std::vector<SensorReading> out;
  for (int i = 0; i < n; ++i) s.Sample(sim, i * dt, &out);
  return out;
}

TEST(EncoderSensor, WhiteNoiseStatistics) {
  auto sim = Pendulum();
  sim->SetCommand("hinge", 0.3);
  sim->Settle();
  auto enc = MakeSensor("encoder", "enc", "{side: link, noise_std_deg: 0.05}", *sim, 11);
  std::vector<double> v;
  for (const auto& r : Take<EncoderReading>(SampleMany(*enc, *sim, kSamples))) {
    v.push_back(r.position);
  }
  ASSERT_EQ(v.size(), static_cast<size_t>(kSamples));
  ExpectNormal(v, 0.3, 0.05 * kDeg);
}

TEST(EncoderSensor, QuantisationFromCountsPerRevolution) {
  auto sim = Pendulum();
  const int counts = 4096;
  const double step = 2 * M_PI / counts;
  auto enc = MakeSensor("encoder", "enc", "{side: link, counts_per_rev: 4096}", *sim, 1);
  std::set<long> distinct;
  for (int i = 0; i < 200; ++i) {
    const double q = -1.0 + 0.0123 * i;
    sim->SetCommand("hinge", q);
    sim->Settle();
    std::vector<SensorReading> out;
    enc->Sample(*sim, 0.0, &out);
    const double reading = std::get<EncoderReading>(out.at(0)).position;
    const double counts_read = reading / step;
    EXPECT_NEAR(counts_read, std::round(counts_read), 1e-6) << "not on the count grid";
    EXPECT_LE(std::abs(reading - q), 0.5 * step + 1e-12);
    distinct.insert(std::lround(counts_read));
  }
  EXPECT_GT(distinct.size(), 150u);
}

TEST(EncoderSensor, QuantisedNoisyReadingsStayOnTheGrid) {
  auto sim = Pendulum();
  sim->SetCommand("hinge", 0.2);
  sim->Settle();
  auto enc = MakeSensor("encoder", "enc", "{side: link, counts_per_rev: 1024, noise_std_deg: 0.3}",
                        *sim, 5);
  const double step = 2 * M_PI / 1024;
  std::vector<double> v;
  for (const auto& r : Take<EncoderReading>(SampleMany(*enc, *sim, kSamples))) {
    EXPECT_NEAR(r.position / step, std::round(r.position / step), 1e-6);
    v.push_back(r.position);
  }
  // Noise larger than a count dithers the quantiser: the mean is unbiased; the variance adds
  // the uniform quantisation noise step^2 / 12.
  const double std = std::sqrt(std::pow(0.3 * kDeg, 2) + step * step / 12.0);
  ExpectNormal(v, 0.2, std);
}

TEST(EncoderSensor, OffsetComesFromTheJointOffsetEffect) {
  auto plain = Pendulum();
  auto offset = Pendulum(Effects({{"joint_offset", "{offset_deg: {hinge: -0.4}}"}}));
  for (Simulation* s : {plain.get(), offset.get()}) {
    s->SetCommand("hinge", 0.25);
    s->Settle();
  }
  auto a = MakeSensor("encoder", "enc", "{side: link}", *plain, 1);
  auto b = MakeSensor("encoder", "enc", "{side: link}", *offset, 1);
  auto c = MakeSensor("encoder", "enc", "{side: motor}", *offset, 1);
  std::vector<SensorReading> out;
  a->Sample(*plain, 0, &out);
  b->Sample(*offset, 0, &out);
  c->Sample(*offset, 0, &out);
  const auto r = Take<EncoderReading>(out);
  EXPECT_EQ(r[0].position, 0.25);  // effect off: the truth, exactly
  EXPECT_NEAR(r[1].position, 0.25 + 0.4 * kDeg, 1e-15);
  EXPECT_NEAR(r[2].position, 0.25 + 0.4 * kDeg, 1e-15);
}

TEST(EncoderSensor, MotorSideSeesTheCommandLinkSideTheElasticJoint) {
  auto sim = Pendulum(Effects({{"joint_compliance", "{}"}}));
  sim->SetCommand("hinge", 0.0);
  sim->Settle();
  auto motor = MakeSensor("encoder", "m", "{side: motor}", *sim, 1);
  auto link = MakeSensor("encoder", "l", "{side: link}", *sim, 1);
  std::vector<SensorReading> out;
  motor->Sample(*sim, 0, &out);
  link->Sample(*sim, 0, &out);
  const auto r = Take<EncoderReading>(out);
  EXPECT_EQ(r[0].position, 0.0);
  // Horizontal pendulum: the gear spring (80 Nm/rad) carries about m g l = 1.0 * 9.81 * 0.2 + ...
  EXPECT_GT(r[1].position, 0.02);
  EXPECT_EQ(r[1].position, sim->JointPosition("hinge"));
}

TEST(EncoderSensor, BadParametersNameTheProblem) {
  auto sim = Pendulum();
  EXPECT_THROW(MakeSensor("encoder", "e", "{side: middle}", *sim, 1), InputError);
  try {
    MakeSensor("encoder", "e", "{side: motor, joints: [tip_bend]}", *sim, 1);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("tip_bend"), std::string::npos) << e.what();
  }
  try {
    MakeSensor("encoder", "e", "{side: link, joints: [nope]}", *sim, 1);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no joint named 'nope'"), std::string::npos) << e.what();
  }
}

TEST(ImuSensor, AtRestReadsGravityUpInTheSensorFrame) {
  auto sim = Pendulum();
  sim->SetCommand("hinge", 0.0);
  sim->Settle();
  auto imu = MakeSensor("imu", "imu", "{site: imu}", *sim, 1);
  auto tilted = MakeSensor("imu", "tilted", "{site: imu_tilted}", *sim, 1);
  std::vector<SensorReading> out;
  imu->Sample(*sim, 0, &out);
  tilted->Sample(*sim, 0, &out);
  const auto r = Take<ImuReading>(out);
  EXPECT_LT((r[0].accel - Vec3(0, 0, 9.81)).norm(), 1e-12) << r[0].accel.transpose();
  EXPECT_LT(r[0].gyro.norm(), 1e-15);
  // The tilted site's z is (1, 0, 1)/sqrt(2): gravity reads 9.81 / sqrt(2) along it.
  EXPECT_NEAR(r[1].accel.norm(), 9.81, 1e-12);
  EXPECT_NEAR(r[1].accel.z(), 9.81 / std::sqrt(2.0), 1e-12);
}

TEST(ImuSensor, WhiteNoiseStatistics) {
  auto sim = Pendulum();
  sim->Settle();
  auto imu =
      MakeSensor("imu", "imu",
                 "{site: imu, gyro_noise_std_rad_s: 0.003, accel_noise_std_m_s2: 0.05}", *sim, 21);
  const auto r = Take<ImuReading>(SampleMany(*imu, *sim, kSamples));
  for (int k = 0; k < 3; ++k) {
    std::vector<double> g, a;
    for (const auto& x : r) {
      g.push_back(x.gyro[k]);
      a.push_back(x.accel[k]);
    }
    ExpectNormal(g, 0.0, 0.003);
    ExpectNormal(a, k == 2 ? 9.81 : 0.0, 0.05);
  }
}

TEST(ImuSensor, ConstantBiasFromTheImuBiasEffect) {
  auto sim = Pendulum(Effects({{"imu_bias",
                                "{gyro_bias_rad_s: [0.01, -0.02, 0.005], "
                                "accel_bias_m_s2: [0.1, 0.0, -0.2]}"}}));
  sim->Settle();
  auto imu = MakeSensor("imu", "imu", "{site: imu, gyro_noise_std_rad_s: 0.002}", *sim, 3);
  const auto r = Take<ImuReading>(SampleMany(*imu, *sim, kSamples));
  std::vector<double> gx;
  for (const auto& x : r) gx.push_back(x.gyro.x());
  ExpectNormal(gx, 0.01, 0.002);
  EXPECT_NEAR(r[0].accel.x(), 0.1, 1e-12);
  EXPECT_NEAR(r[0].accel.z(), 9.81 - 0.2, 1e-12);
}

TEST(ImuSensor, BiasRandomWalkIncrementsScaleWithSqrtTime) {
  auto sim = Pendulum(Effects({{"imu_bias", "{gyro_walk_rad_s_sqrt_s: 0.02}"}}));
  sim->Settle();
  auto imu = MakeSensor("imu", "imu", "{site: imu}", *sim, 8);
  const double dt = 0.005;
  const auto r = Take<ImuReading>(SampleMany(*imu, *sim, kSamples + 1, dt));
  std::vector<double> inc;
  for (size_t i = 1; i < r.size(); ++i) inc.push_back(r[i].gyro.z() - r[i - 1].gyro.z());
  ExpectNormal(inc, 0.0, 0.02 * std::sqrt(dt));
}

TEST(ImuSensor, IntegratedYawDriftsWithoutMagnetometer) {
  // At rest, integrating the gyro's vertical axis gives yaw = bias * t (+ a random walk).
  auto sim = Pendulum(Effects({{"imu_bias", "{gyro_bias_rad_s: [0, 0, 0.002]}"}}));
  sim->Settle();
  auto imu = MakeSensor("imu", "imu", "{site: imu, gyro_noise_std_rad_s: 0.001}", *sim, 2);
  const double dt = 0.01;
  double yaw = 0.0;
  for (const auto& x : Take<ImuReading>(SampleMany(*imu, *sim, 6000, dt))) yaw += x.gyro.z() * dt;
  EXPECT_NEAR(yaw, 0.002 * 60.0, 5 * 0.001 * dt * std::sqrt(6000.0));
}

TEST(ImuSensor, TruthInMotionMatchesMujocoGyroAndAccelerometer) {
  auto sim = Pendulum(Effects({{"link_bending", "{}"}}));
  auto imu = MakeSensor("imu", "imu", "{site: imu}", *sim, 1);
  const int gyro = mj_name2id(sim->model(), mjOBJ_SENSOR, "imu_gyro");
  const int accel = mj_name2id(sim->model(), mjOBJ_SENSOR, "imu_accel");
  JointTrajectory traj;
  traj.Add(0.0, Eigen::VectorXd::Constant(1, 0.0));
  traj.Add(0.5, Eigen::VectorXd::Constant(1, 1.0));
  int checked = 0;
  while (sim->time() < 0.6) {
    sim->SetCommand(traj.At(sim->time()));
    sim->Step(7);
    std::vector<SensorReading> out;
    imu->Sample(*sim, sim->time(), &out);
    const ImuReading& r = std::get<ImuReading>(out[0]);
    // Sampling ran mj_forward at the current state, so MuJoCo's sensordata is current too.
    const double* g = sim->data()->sensordata + sim->model()->sensor_adr[gyro];
    const double* a = sim->data()->sensordata + sim->model()->sensor_adr[accel];
    EXPECT_LT((r.gyro - Vec3(g[0], g[1], g[2])).norm(), 1e-9);
    EXPECT_LT((r.accel - Vec3(a[0], a[1], a[2])).norm(), 1e-9);
    checked += r.gyro.norm() > 0.1;
  }
  EXPECT_GT(checked, 10) << "the pendulum should have moved";
}

TEST(ImuSensor, SamplingDoesNotChangeTheTrajectory) {
  auto a = Pendulum(Effects({{"link_bending", "{}"}}));
  auto b = Pendulum(Effects({{"link_bending", "{}"}}));
  auto imu = MakeSensor("imu", "imu", "{site: imu}", *a, 1);
  for (Simulation* s : {a.get(), b.get()}) s->SetCommand("hinge", 0.8);
  for (int i = 0; i < 300; ++i) {
    a->Step(1);
    b->Step(1);
    std::vector<SensorReading> out;
    if (i % 3 == 0) imu->Sample(*a, a->time(), &out);
  }
  EXPECT_EQ(a->JointPosition("tip_bend"), b->JointPosition("tip_bend"));
  EXPECT_EQ(a->JointPosition("hinge"), b->JointPosition("hinge"));
}

TEST(ContactSensor, TouchFlagAndDistanceNoise) {
  auto sim = Pendulum();
  auto touch = MakeSensor("contact", "touch",
                          "{site: finger, surface: table, threshold_m: 0.002, noise_std_m: 0.0005}",
                          *sim, 4);
  // Finger (0.5 m from the hinge) above the table top (z = 0.77): not touching.
  sim->SetCommand("hinge", 0.0);
  sim->Settle();
  std::vector<SensorReading> out;
  touch->Sample(*sim, 0, &out);
  EXPECT_FALSE(std::get<ContactReading>(out[0]).touching);
  EXPECT_TRUE(std::isnan(std::get<ContactReading>(out[0]).distance));
  // Lower it onto the table: finger at z = 1 - 0.5 sin(q) = 0.7705 m, 0.5 mm above the top.
  const double q = std::asin((1.0 - 0.7705) / 0.5);
  sim->SetCommand("hinge", q);
  sim->Settle();
  const Vec3 p = sim->SitePose("finger").translation();
  const double truth = p.z() - 0.77;
  ASSERT_NEAR(truth, 0.0005, 1e-9);
  std::vector<double> d;
  for (const auto& r : Take<ContactReading>(SampleMany(*touch, *sim, kSamples))) {
    ASSERT_TRUE(r.touching);
    d.push_back(r.distance);
  }
  ExpectNormal(d, truth, 0.0005);
}

TEST(ContactSensor, NeedsABoxOrPlaneSurface) {
  auto sim = Pendulum();
  EXPECT_THROW(MakeSensor("contact", "c", "{site: finger, surface: nope}", *sim, 1), InputError);
  EXPECT_THROW(MakeSensor("contact", "c", "{site: nope, surface: table}", *sim, 1), InputError);
}

TEST(CameraSensor, IntrinsicsAndExtrinsicsFromTheModel) {
  auto sim = Pendulum();
  sim->Settle();
  auto cam = MakeSensor("camera", "cam", "{camera: cam}", *sim, 1);
  std::vector<SensorReading> out;
  cam->Sample(*sim, 0.5, &out);
  const CameraReading& r = std::get<CameraReading>(out[0]);
  const int id = mj_name2id(sim->model(), mjOBJ_CAMERA, "cam");
  EXPECT_EQ(r.camera_id, id);
  EXPECT_EQ(r.t, 0.5);
  EXPECT_EQ(r.intrinsics.width, sim->model()->vis.global.offwidth);
  EXPECT_NEAR(r.intrinsics.fy, 0.5 * r.intrinsics.height / std::tan(25 * kDeg), 1e-9);
  // Optical frame: z forward = MuJoCo camera's -z = world +y here; y down = world -z.
  EXPECT_LT((r.T_w_cam.linear().col(2) - Vec3(0, 1, 0)).norm(), 1e-12);
  EXPECT_LT((r.T_w_cam.linear().col(1) - Vec3(0, 0, -1)).norm(), 1e-12);
  EXPECT_LT((r.T_w_cam.translation() - Vec3(0.2, -1.0, 1.0)).norm(), 1e-12);
}

TEST(SensorSuite, RatesAndTimestamps) {
  auto sim = Pendulum();
  SensorSuite suite;
  suite.Add(MakeSensor("encoder", "enc", "{side: link, rate_hz: 100}", *sim, 1));
  suite.Add(MakeSensor("imu", "imu", "{site: imu, rate_hz: 250}", *sim, 1));
  std::vector<SensorReading> out;
  suite.Poll(*sim, &out);
  while (sim->time() < 1.0 - 1e-9) {
    sim->Step(1);
    suite.Poll(*sim, &out);
  }
  const auto enc = Take<EncoderReading>(out);
  const auto imu = Take<ImuReading>(out);
  EXPECT_EQ(enc.size(), 101u);
  EXPECT_EQ(imu.size(), 251u);
  for (size_t i = 0; i < enc.size(); ++i) EXPECT_NEAR(enc[i].t, 0.01 * i, 1e-9);
  for (size_t i = 0; i < imu.size(); ++i) EXPECT_NEAR(imu[i].t, 0.004 * i, 1e-9);
}

TEST(SensorSeeding, SameSeedSameNumbersOwnStreamPerSensor) {
  auto sim = Pendulum();
  sim->Settle();
  const std::string p = "{site: imu, gyro_noise_std_rad_s: 0.01}";
  auto a = MakeSensor("imu", "imu", p, *sim, 42);
  auto b = MakeSensor("imu", "imu", p, *sim, 42);
  auto c = MakeSensor("imu", "imu", p, *sim, 43);
  auto other = MakeSensor("imu", "imu_b", p, *sim, 42);
  const auto ra = Take<ImuReading>(SampleMany(*a, *sim, 50));
  const auto rb = Take<ImuReading>(SampleMany(*b, *sim, 50));
  const auto rc = Take<ImuReading>(SampleMany(*c, *sim, 50));
  const auto ro = Take<ImuReading>(SampleMany(*other, *sim, 50));
  for (int i = 0; i < 50; ++i) {
    EXPECT_EQ(ra[i].gyro, rb[i].gyro);
    EXPECT_NE(ra[i].gyro, rc[i].gyro);
    EXPECT_NE(ra[i].gyro, ro[i].gyro);
  }
}

TEST(SensorRegistry, UnknownKindIsBadInput) {
  auto sim = Pendulum();
  try {
    MakeSensor("lidar", "x", "{}", *sim, 1);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown sensor kind 'lidar'"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("encoder, imu, contact, camera"), std::string::npos);
  }
}

TEST(SensorRegistry, ParsedFromAScenarioList) {
  auto sim = Pendulum();
  const ConfigNode root = ConfigNode::LoadString(
      "sensors:\n"
      "  - {name: a, kind: encoder, side: link}\n"
      "  - {name: b, kind: sonar}\n",
      "s.yaml");
  try {
    SensorSuite::Parse(root.Child("sensors"), *sim, 1);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("s.yaml:3"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("unknown sensor kind 'sonar'"), std::string::npos);
  }
}

}  // namespace
}  // namespace flexbench::sim
