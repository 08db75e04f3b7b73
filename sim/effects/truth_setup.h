// What effects change in the truth: a copy of the model whose parameters they may edit, and
// switches the simulation reads. Everything here starts as "nominal": passive compliance joints
// locked at their reference position, rigid gears without play, no sensor errors.
#pragma once

#include <mujoco/mujoco.h>

#include <map>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "sim/model_catalog.h"

namespace flexbench::sim {

// Transmission between motor and link of one actuated joint.
#include <cmath>

struct GearSpec {
  double stiffness = 0.0;        // Nm/rad (N/m for slides); 0 = rigid
  double stiffness_cubic = 0.0;  // Nm/rad^3: torque k d + k3 d^3, a spring that stiffens
  double backlash = 0.0;         // total play, rad (m)
  // Transmission error of a strain-wave gear: the link turns by
  // sum_h amplitude[h] sin((h + 1) motor + phase[h]) beyond the motor, 1 to 3 cycles per
  // revolution (rad).
  double tx_amplitude[3] = {0.0, 0.0, 0.0};
  double tx_phase[3] = {0.0, 0.0, 0.0};
  bool has_transmission_error() const {
    return tx_amplitude[0] != 0 || tx_amplitude[1] != 0 || tx_amplitude[2] != 0;
  }
  double TransmissionError(double motor) const {
    double e = 0.0;
    for (int h = 0; h < 3; ++h) e += tx_amplitude[h] * std::sin((h + 1) * motor + tx_phase[h]);
    return e;
  }
  // Spring torque at deflection d.
  double SpringTorque(double d) const { return stiffness * d + stiffness_cubic * d * d * d; }
};

// Errors of one 6-axis IMU beyond its white noise.
struct ImuBiasSpec {
  Vec3 gyro_bias = Vec3::Zero();   // rad/s, constant
  Vec3 accel_bias = Vec3::Zero();  // m/s^2, constant
  double gyro_walk = 0.0;          // rad/s/sqrt(s): bias random walk density
  double accel_walk = 0.0;         // m/s^2/sqrt(s)
};

// Stribeck friction of one joint (a truth-only dynamic effect): a breakaway torque `static_Nm`
// above the sliding torque `coulomb_Nm` at low speed,
//   tau = -(Fc + (Fs - Fc) exp(-(v / vs)^2)) v / sqrt(v^2 + eps^2),
// smoothed over eps: near v = 0 it acts as a damper of (Fs / eps), which an explicit step keeps
// stable while Fs dt / (eps I) < 2 (I the joint's inertia): 0.02 rad/s keeps Fs / eps to 30
// N m s/rad for closed_loop_dynamic_stribeck's 0.6 N m breakaway.
struct StribeckSpec {
  double static_Nm = 0.0;
  double coulomb_Nm = 0.0;
  double velocity = 0.05;   // vs, rad/s (m/s)
  double smoothing = 0.02;  // eps, rad/s (m/s)
  bool active() const { return static_Nm > 0.0 || coulomb_Nm > 0.0; }
  double Torque(double v) const {
    const double level =
        coulomb_Nm + (static_Nm - coulomb_Nm) * std::exp(-(v / velocity) * (v / velocity));
    return -level * v / std::sqrt(v * v + smoothing * smoothing);
  }
};

struct TruthSetup {
  mjModel* model = nullptr;  // the truth model (a copy; the file's model stays nominal)
  const ModelCatalog* catalog = nullptr;
  std::string model_name;
  // Per joint id: the joint moves (passive: spring-loaded; coupled: follows its linkage).
  // Joints that are not released are held at qpos0, i.e. at the nominal model's value.
  std::vector<char> released;
  std::vector<GearSpec> gear;                   // per joint id (actuated joints)
  std::vector<double> joint_offset;             // per joint id: link - reading, rad (m)
  std::map<std::string, ImuBiasSpec> imu_bias;  // by IMU site; "*" applies to every IMU
  // Per joint id (actuated joints): the servo acts on the command it was sent this long ago (s).
  std::vector<double> servo_delay;
  std::vector<StribeckSpec> stribeck;  // per joint id
  // Set by effects that change masses or geometry: the simulation then calls mj_setConst.
  bool constants_changed = false;
};

// The nominal setup over `model` (which `catalog` describes): nothing released but the passive
// joints and linkages no effect claims, which are the model's own physics.
TruthSetup NominalSetup(mjModel* model, const ModelCatalog* catalog, const std::string& name);

}  // namespace flexbench::sim
