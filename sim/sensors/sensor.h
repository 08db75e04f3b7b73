// Sensors of the truth: typed, timestamped readings with their own seeded noise streams.
// MuJoCo 2.2.2 adds no sensor noise; every error term is added here. Sensor errors that are
// mismatches of the declared model (encoder offsets, IMU bias and drift) come from effects
// (sim/effects), the sensors' own parameters are white noise, quantisation and rate.
//
// Scenario files list sensors by kind:
//   sensors:
//     - {name: link_enc, kind: encoder, side: link, noise_std_deg: 0.01, counts_per_rev: 65536}
//     - {name: imu2, kind: imu, site: imu_link2, gyro_noise_std_rad_s: 0.002, rate_hz: 200}
//     - {name: touch, kind: contact, site: index_tip, surface: table_top, noise_std_m: 0.0005}
//     - {name: mast, kind: camera, camera: mast_camera, rate_hz: 10}
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <memory>
#include <ostream>
#include <string>
#include <variant>
#include <vector>

#include "estimators/camera/pinhole.h"
#include "estimators/conventions.h"
#include "estimators/measurement.h"
#include "sim/config.h"
#include "sim/params.h"
#include "sim/rng.h"

namespace flexbench::sim {

class Simulation;

enum class EncoderSide { kMotor, kLink };

// One joint's encoder count converted to an angle (rad; m for slides).
struct EncoderReading {
  double t = 0.0;
  std::string sensor;
  std::string joint;
  EncoderSide side = EncoderSide::kLink;
  double position = 0.0;
};

// 6-axis IMU in the site frame: angular velocity (rad/s) and specific force (m/s^2; at rest
// +9.81 along the site's up direction). No magnetometer. The estimators' reading (t, gyro,
// accel; one definition of what an IMU measures and in which units) named by the sensor and its
// site; an estimator takes it as is once `imu` says which of its IMUs it is.
struct ImuReading : estimators::ImuReading {
  std::string sensor;
  std::string site;
};

// Touch flag and, in contact, the 1-D distance (m) of the site to the touched surface along the
// surface normal (negative: penetration). distance is NaN when not touching.
struct ContactReading {
  double t = 0.0;
  std::string sensor;
  std::string site;
  std::string surface;
  bool touching = false;
  double distance = 0.0;
};

// A camera frame's metadata: intrinsics and (true) extrinsics from the model. The image itself
// is rendered by render/ from the same state; T_w_cam is ground truth, not for estimators.
struct CameraReading {
  double t = 0.0;
  std::string sensor;
  std::string camera;
  int camera_id = -1;
  PinholeCamera intrinsics;
  Eigen::Isometry3d T_w_cam = Eigen::Isometry3d::Identity();
};

using SensorReading = std::variant<EncoderReading, ImuReading, ContactReading, CameraReading>;

class Sensor {
 public:
  virtual ~Sensor() = default;
  const std::string& name() const { return name_; }
  const std::string& kind() const { return kind_; }
  double rate_hz() const { return rate_hz_; }
  // Reads parameters and checks the model objects they name. `seed` is the scenario seed; each
  // noise stream mixes it with a stable name ("<kind>/<sensor>/<channel>").
  virtual void Configure(const ComponentParams& params, const Simulation& sim,
                         std::uint64_t seed) = 0;
  // Appends the reading(s) of the current state, stamped `t` seconds.
  virtual void Sample(const Simulation& sim, double t, std::vector<SensorReading>* out) = 0;

  void set_identity(std::string kind, std::string name) {
    kind_ = std::move(kind);
    name_ = std::move(name);
  }

 protected:
  void ReadRate(const ComponentParams& params, double fallback_hz);

 private:
  std::string kind_;
  std::string name_;
  double rate_hz_ = 0.0;
};

struct SensorEntry {
  const char* kind;
  const char* description;
  std::unique_ptr<Sensor> (*make)();
};

// The explicit list of sensor kinds (SensorRegistry in sim/sensors/sensors.cc).
const std::vector<SensorEntry>& SensorRegistry();

// A configured sensor; throws InputError "<where>: unknown sensor kind '<kind>' (known: ...)"
// or naming the parameter / model object at fault.
std::unique_ptr<Sensor> MakeSensor(const std::string& kind, const std::string& name,
                                   const ComponentParams& params, const Simulation& sim,
                                   std::uint64_t seed);
// Same with parameters as YAML text (tests, programmatic set-ups).
std::unique_ptr<Sensor> MakeSensor(const std::string& kind, const std::string& name,
                                   const std::string& params_yaml, const Simulation& sim,
                                   std::uint64_t seed);

// Samples sensors at their rates as simulated time advances, or all at once for quasi-static
// configurations.
class SensorSuite {
 public:
  SensorSuite() = default;
  // Reads a `sensors:` list of a scenario file (each item: name, kind, parameters).
  static SensorSuite Parse(const ConfigNode& list, const Simulation& sim, std::uint64_t seed);
  void Add(std::unique_ptr<Sensor> sensor);

  // Samples every sensor whose next sample time (k / rate_hz) has been reached at sim.time().
  void Poll(const Simulation& sim, std::vector<SensorReading>* out);
  // Samples every sensor once, stamped t (quasi-static configurations).
  void SampleAll(const Simulation& sim, double t, std::vector<SensorReading>* out);

  const std::vector<std::unique_ptr<Sensor>>& sensors() const { return sensors_; }
  bool empty() const { return sensors_.empty(); }

 private:
  std::vector<std::unique_ptr<Sensor>> sensors_;
  std::vector<long> next_sample_;
};

// CSV of readings: t_s,sensor,kind,channel,v0..v5 (encoder: position; imu: gyro xyz, accel xyz;
// contact: touching, distance_m; camera: fx, fy, cx, cy, width, height), %.9g.
void WriteReadingsCsvHeader(std::ostream& out);
void WriteReadingCsv(std::ostream& out, const SensorReading& reading);

}  // namespace flexbench::sim
