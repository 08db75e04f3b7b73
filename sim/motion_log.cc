#include "sim/motion_log.h"

#include <cmath>
#include <map>
#include <variant>

#include "sim/rng.h"

namespace flexbench::sim {

void MultiSine::DrawPhases(std::uint64_t seed, const std::string& name, int joints) {
  NoiseStream rng(seed, name);
  phase.resize(joints * frequencies.size());
  for (double& p : phase) p = 2.0 * M_PI * rng.Uniform();
}

double MultiSine::At(int joint, double t) const {
  double s = 0.0;
  const int nf = static_cast<int>(frequencies.size());
  for (int i = 0; i < nf; ++i) {
    const double f = frequencies[(i + joint) % nf] * (1.0 + 0.07 * joint);
    s += std::sin(2.0 * M_PI * f * t + phase[joint * nf + i]);
  }
  const double fade = t < 1.0 ? 0.5 - 0.5 * std::cos(M_PI * t) : 1.0;
  return center[joint] + fade * amplitude[joint] * s / nf;
}

RecordedLog SimulateMotionLog(Simulation& s, SensorSuite& sensors, const MultiSine& motion,
                              const MotionLogOptions& o) {
  const int n = s.num_actuated();
  Eigen::VectorXd cmd(n);
  for (int k = 0; k < n; ++k) cmd[k] = motion.At(k, 0.0);
  s.SetCommand(cmd);
  s.Settle();
  RecordedLog log;
  log.robot = s.model_name();
  log.declared_path = o.declared_path;
  log.joints = s.actuated_joints();
  log.joint_is_slide.assign(n, 0);
  for (int k = 0; k < n; ++k) {
    log.joint_is_slide[k] = s.model()->jnt_type[s.catalog().actuated[k]] == mjJNT_SLIDE;
  }
  log.command_joints = log.joints;
  log.command_torque = o.torque_commands;
  log.command_is_slide = log.joint_is_slide;
  log.joint_std = o.encoder_std;
  log.gyro_std = o.gyro_std;
  log.accel_std = o.accel_std;
  std::map<std::string, int> imu_index;
  for (const auto& sensor : sensors.sensors()) {
    if (sensor->kind() != "imu") continue;
    imu_index[sensor->name()] = static_cast<int>(log.imus.size());
    log.imus.push_back({sensor->name(), "", false, Quat::Identity()});
  }
  const long steps = std::lround(o.duration_s / s.timestep());
  const long per_command = std::max(1L, std::lround(1.0 / (o.command_rate_hz * s.timestep())));
  std::vector<SensorReading> readings;
  std::map<double, std::vector<double>> rows;  // encoder rows by time
  std::map<double, lie::SE3> truth;            // the truth frame's pose by encoder row time
  log.truth_frame = o.truth_frame;
  const bool world_base = o.base_body.empty() || o.base_body == "world";
  for (long k = 0; k <= steps; ++k) {
    if (k % per_command == 0) {
      const double t = s.time();
      for (int j = 0; j < n; ++j) cmd[j] = motion.At(j, t);
      s.SetCommand(cmd);
      if (!o.torque_commands) {
        log.command_t.push_back(t);
        log.command_q.insert(log.command_q.end(), cmd.data(), cmd.data() + n);
      }
    }
    readings.clear();
    sensors.Poll(s, &readings);
    for (const SensorReading& r : readings) {
      if (const auto* e = std::get_if<EncoderReading>(&r)) {
        std::vector<double>& row = rows[e->t];
        row.resize(n, 0.0);
        for (int j = 0; j < n; ++j) {
          if (log.joints[j] == e->joint) row[j] = e->position;
        }
        if (!o.truth_frame.empty() && !truth.count(e->t)) {
          const Eigen::Isometry3d T_w_base =
              world_base ? Eigen::Isometry3d::Identity() : s.BodyPose(o.base_body);
          const Eigen::Isometry3d T_base_frame = T_w_base.inverse() * s.Pose(o.truth_frame);
          truth[e->t] = lie::SE3(T_base_frame.linear(), T_base_frame.translation());
        }
      } else if (const auto* z = std::get_if<ImuReading>(&r)) {
        estimators::ImuReading reading = *z;
        reading.imu = imu_index.at(z->sensor);
        log.imus[reading.imu].frame = z->site;
        log.imu.push_back(reading);
      }
    }
    if (o.after_poll) o.after_poll(s);
    if (k < steps) {
      const double t = s.time();
      s.Step(1);
      if (o.torque_commands) {
        log.command_t.push_back(t);
        for (int j = 0; j < n; ++j) log.command_q.push_back(s.MotorTorque(j));
      }
    }
  }
  for (const auto& [t, row] : rows) {
    log.joint_t.push_back(t);
    log.joint_q.insert(log.joint_q.end(), row.begin(), row.end());
  }
  for (const auto& [t, T] : truth) {
    log.truth_t.push_back(t);
    log.truth.push_back(T);
  }
  return log;
}

}  // namespace flexbench::sim
