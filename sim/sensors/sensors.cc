// The sensor kinds: encoder, imu, contact, camera, and the registry that lists them.
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"
#include "sim/sensors/sensor.h"
#include "sim/simulation.h"

namespace flexbench::sim {
namespace {

// (+ 0.0 turns a rounded -0 into 0.)
double Quantize(double x, double step) { return step > 0 ? step * std::round(x / step) + 0.0 : x; }

// ---- Joint encoders, motor side (before the gear: the commanded motor angle when the gear is
// elastic or has play) or link side (after it). Reading = Q(true + offset + white noise).
class EncoderSensor : public Sensor {
 public:
  void Configure(const ComponentParams& p, const Simulation& sim, std::uint64_t seed) override {
    const ConfigNode side = p.Require("side");
    if (side.AsString() == "motor") {
      side_ = EncoderSide::kMotor;
    } else if (side.AsString() == "link") {
      side_ = EncoderSide::kLink;
    } else {
      side.Fail("expected 'motor' or 'link', got '" + side.AsString() + "'");
    }
    noise_std_ = p.GetPositive("noise_std_deg", 0.0, true) * kDeg;
    noise_std_m_ = p.GetPositive("noise_std_m", 0.0, true);
    const int counts = p.GetInt("counts_per_rev", 0);
    if (counts < 0) p.FailKey("counts_per_rev", "must be >= 0 (0: no quantisation)");
    step_ = counts > 0 ? 2.0 * M_PI / counts : 0.0;
    step_m_ = p.GetPositive("resolution_m", 0.0, true);
    ReadRate(p, 100.0);
    const std::vector<std::string> joints =
        p.GetStringList("joints", sim.catalog().ActuatedNames());
    for (const std::string& joint : joints) {
      const int j = mj_name2id(sim.model(), mjOBJ_JOINT, joint.c_str());
      if (j < 0) p.FailKey("joints", sim.model_name() + " has no joint named '" + joint + "'");
      if (side_ == EncoderSide::kMotor && sim.catalog().Joint(j).role != JointRole::kActuated) {
        p.FailKey("joints", "joint '" + joint + "' has no motor (not actuated)");
      }
      channels_.push_back(Channel{joint, j, sim.model()->jnt_type[j] == mjJNT_SLIDE,
                                  NoiseStream(seed, "encoder/" + name() + "/" + joint)});
    }
  }
  void Sample(const Simulation& sim, double t, std::vector<SensorReading>* out) override {
    for (Channel& c : channels_) {
      const double truth =
          side_ == EncoderSide::kMotor ? sim.MotorPosition(c.id) : sim.JointPosition(c.id);
      const double noisy =
          truth - sim.JointOffset(c.id) + c.noise.Normal(c.slide ? noise_std_m_ : noise_std_);
      EncoderReading r;
      r.t = t;
      r.sensor = name();
      r.joint = c.joint;
      r.side = side_;
      r.position = Quantize(noisy, c.slide ? step_m_ : step_);
      out->push_back(r);
    }
  }

 private:
  struct Channel {
    std::string joint;
    int id;
    bool slide;
    NoiseStream noise;
  };
  EncoderSide side_ = EncoderSide::kLink;
  double noise_std_ = 0.0;
  double noise_std_m_ = 0.0;
  double step_ = 0.0;
  double step_m_ = 0.0;
  std::vector<Channel> channels_;
};

// ---- 6-axis IMU: truth + constant bias + bias random walk + white noise, per axis.
class ImuSensor : public Sensor {
 public:
  void Configure(const ComponentParams& p, const Simulation& sim, std::uint64_t seed) override {
    site_ = p.RequireString("site");
    site_id_ = mj_name2id(sim.model(), mjOBJ_SITE, site_.c_str());
    if (site_id_ < 0) p.FailKey("site", sim.model_name() + " has no site named '" + site_ + "'");
    gyro_std_ = p.GetPositive("gyro_noise_std_rad_s", 0.0, true);
    accel_std_ = p.GetPositive("accel_noise_std_m_s2", 0.0, true);
    ReadRate(p, 200.0);
    bias_ = sim.ImuBias(site_);
    const std::string id = "imu/" + name() + "/";
    gyro_noise_ = NoiseStream(seed, id + "gyro");
    accel_noise_ = NoiseStream(seed, id + "accel");
    gyro_walk_noise_ = NoiseStream(seed, id + "gyro_walk");
    accel_walk_noise_ = NoiseStream(seed, id + "accel_walk");
  }
  void Sample(const Simulation& sim, double t, std::vector<SensorReading>* out) override {
    // Bias random walk over the time since the previous sample.
    const double dt = has_last_ ? std::max(0.0, t - last_t_) : 0.0;
    has_last_ = true;
    last_t_ = t;
    const double sg = bias_.gyro_walk * std::sqrt(dt);
    const double sa = bias_.accel_walk * std::sqrt(dt);
    for (int k = 0; k < 3; ++k) {
      gyro_walk_[k] += gyro_walk_noise_.Normal(sg);
      accel_walk_[k] += accel_walk_noise_.Normal(sa);
    }
    ImuReading r;
    r.t = t;
    r.sensor = name();
    r.site = site_;
    const Vec3 w = sim.SiteAngularVelocity(site_id_);
    const Vec3 f = sim.SiteSpecificForce(site_id_);
    for (int k = 0; k < 3; ++k) {
      r.gyro[k] = w[k] + bias_.gyro_bias[k] + gyro_walk_[k] + gyro_noise_.Normal(gyro_std_);
      r.accel[k] = f[k] + bias_.accel_bias[k] + accel_walk_[k] + accel_noise_.Normal(accel_std_);
    }
    out->push_back(r);
  }

 private:
  std::string site_;
  int site_id_ = -1;
  double gyro_std_ = 0.0;
  double accel_std_ = 0.0;
  ImuBiasSpec bias_;
  Vec3 gyro_walk_ = Vec3::Zero();
  Vec3 accel_walk_ = Vec3::Zero();
  bool has_last_ = false;
  double last_t_ = 0.0;
  NoiseStream gyro_noise_, accel_noise_, gyro_walk_noise_, accel_walk_noise_;
};

// ---- Contact: a site (fingertip) against the top face (+z) of a box or plane geom.
class ContactSensor : public Sensor {
 public:
  void Configure(const ComponentParams& p, const Simulation& sim, std::uint64_t seed) override {
    site_ = p.RequireString("site");
    surface_ = p.RequireString("surface");
    site_id_ = mj_name2id(sim.model(), mjOBJ_SITE, site_.c_str());
    if (site_id_ < 0) p.FailKey("site", sim.model_name() + " has no site named '" + site_ + "'");
    geom_id_ = mj_name2id(sim.model(), mjOBJ_GEOM, surface_.c_str());
    if (geom_id_ < 0) {
      p.FailKey("surface", sim.model_name() + " has no geom named '" + surface_ + "'");
    }
    const int type = sim.model()->geom_type[geom_id_];
    if (type != mjGEOM_BOX && type != mjGEOM_PLANE) {
      p.FailKey("surface", "geom '" + surface_ + "' must be a box or a plane (its +z face)");
    }
    threshold_ = p.GetPositive("threshold_m", 0.001, true);
    noise_std_ = p.GetPositive("noise_std_m", 0.0, true);
    ReadRate(p, 100.0);
    noise_ = NoiseStream(seed, "contact/" + name());
  }
  void Sample(const Simulation& sim, double t, std::vector<SensorReading>* out) override {
    const mjModel* m = sim.model();
    const Eigen::Isometry3d T_w_g = sim.Pose(FrameRef{FrameType::kGeom, geom_id_, surface_});
    const Vec3 p_w = sim.Pose(FrameRef{FrameType::kSite, site_id_, site_}).translation();
    const Vec3 p_g = T_w_g.inverse() * p_w;
    const double* size = m->geom_size + 3 * geom_id_;
    const bool box = m->geom_type[geom_id_] == mjGEOM_BOX;
    const double top = box ? size[2] : 0.0;
    const bool inside = !box || (std::abs(p_g.x()) <= size[0] && std::abs(p_g.y()) <= size[1] &&
                                 p_g.z() >= -size[2]);
    const double d = p_g.z() - top;  // along the surface normal
    ContactReading r;
    r.t = t;
    r.sensor = name();
    r.site = site_;
    r.surface = surface_;
    r.touching = inside && d <= threshold_;
    r.distance =
        r.touching ? d + noise_.Normal(noise_std_) : std::numeric_limits<double>::quiet_NaN();
    out->push_back(r);
  }

 private:
  std::string site_, surface_;
  int site_id_ = -1;
  int geom_id_ = -1;
  double threshold_ = 0.001;
  double noise_std_ = 0.0;
  NoiseStream noise_;
};

// ---- Camera: intrinsics (fovy, offscreen resolution) and extrinsics from the model.
class CameraSensor : public Sensor {
 public:
  void Configure(const ComponentParams& p, const Simulation& sim, std::uint64_t) override {
    camera_ = p.RequireString("camera");
    camera_id_ = mj_name2id(sim.model(), mjOBJ_CAMERA, camera_.c_str());
    if (camera_id_ < 0) {
      p.FailKey("camera", sim.model_name() + " has no camera named '" + camera_ + "'");
    }
    ReadRate(p, 10.0);
  }
  void Sample(const Simulation& sim, double t, std::vector<SensorReading>* out) override {
    CameraReading r;
    r.t = t;
    r.sensor = name();
    r.camera = camera_;
    r.camera_id = camera_id_;
    r.intrinsics = CameraIntrinsics(sim.model(), camera_id_);
    r.T_w_cam = sim.Pose(FrameRef{FrameType::kCamera, camera_id_, camera_});
    out->push_back(r);
  }

 private:
  std::string camera_;
  int camera_id_ = -1;
};

template <class T>
std::unique_ptr<Sensor> Make() {
  return std::make_unique<T>();
}

}  // namespace

const std::vector<SensorEntry>& SensorRegistry() {
  // One line per sensor kind.
  static const std::vector<SensorEntry> kinds = {
      {"encoder", "joint encoders, motor or link side: white noise, counts per revolution",
       Make<EncoderSensor>},
      {"imu", "6-axis IMU (gyro + accelerometer) at a site: white noise; bias from imu_bias",
       Make<ImuSensor>},
      {"contact", "touch flag and 1-D distance of a site to a surface along its normal",
       Make<ContactSensor>},
      {"camera", "camera intrinsics and extrinsics from the model (images: render/)",
       Make<CameraSensor>},
  };
  return kinds;
}

void Sensor::ReadRate(const ComponentParams& params, double fallback_hz) {
  rate_hz_ = params.GetPositive("rate_hz", fallback_hz);
}

std::unique_ptr<Sensor> MakeSensor(const std::string& kind, const std::string& name,
                                   const ComponentParams& params, const Simulation& sim,
                                   std::uint64_t seed) {
  std::string known;
  for (const SensorEntry& e : SensorRegistry()) {
    if (kind == e.kind) {
      std::unique_ptr<Sensor> s = e.make();
      s->set_identity(kind, name);
      s->Configure(params, sim, seed);
      return s;
    }
    known += std::string(known.empty() ? "" : ", ") + e.kind;
  }
  throw InputError(params.where() + ": unknown sensor kind '" + kind + "' (known: " + known + ")");
}

std::unique_ptr<Sensor> MakeSensor(const std::string& kind, const std::string& name,
                                   const std::string& params_yaml, const Simulation& sim,
                                   std::uint64_t seed) {
  return MakeSensor(kind, name, ComponentParams::FromYaml(params_yaml, "sensor '" + name + "'"),
                    sim, seed);
}

SensorSuite SensorSuite::Parse(const ConfigNode& list, const Simulation& sim, std::uint64_t seed) {
  SensorSuite suite;
  std::set<std::string> names;
  for (const ConfigNode& item : list.Items()) {
    if (!item.IsMap()) item.Fail("expected a sensor {name, kind, parameters...}");
    const ConfigNode name_node = item.Child("name");
    const std::string name = name_node.AsString();
    if (!names.insert(name).second) name_node.Fail("sensor name '" + name + "' used twice");
    const ConfigNode kind_node = item.Child("kind");
    const std::string kind = kind_node.AsString();
    std::string known;
    bool found = false;
    for (const SensorEntry& e : SensorRegistry()) {
      found |= kind == e.kind;
      known += std::string(known.empty() ? "" : ", ") + e.kind;
    }
    if (!found) kind_node.Fail("unknown sensor kind '" + kind + "' (known: " + known + ")");
    suite.Add(MakeSensor(
        kind, name, ComponentParams(item, item.Where() + ": sensor '" + name + "'"), sim, seed));
  }
  return suite;
}

void SensorSuite::Add(std::unique_ptr<Sensor> sensor) {
  sensors_.push_back(std::move(sensor));
  next_sample_.push_back(0);
}

void SensorSuite::Poll(const Simulation& sim, std::vector<SensorReading>* out) {
  const double t = sim.time();
  for (size_t i = 0; i < sensors_.size(); ++i) {
    const double rate = sensors_[i]->rate_hz();
    // Due when t has reached k / rate (with a tolerance of a millionth of the period).
    if (t * rate + 1e-6 >= static_cast<double>(next_sample_[i])) {
      sensors_[i]->Sample(sim, t, out);
      next_sample_[i] = static_cast<long>(std::floor(t * rate + 1e-6)) + 1;
    }
  }
}

void SensorSuite::SampleAll(const Simulation& sim, double t, std::vector<SensorReading>* out) {
  for (auto& s : sensors_) s->Sample(sim, t, out);
}

void WriteReadingsCsvHeader(std::ostream& out) {
  out << "t_s,sensor,kind,channel,v0,v1,v2,v3,v4,v5\n";
}

void WriteReadingCsv(std::ostream& out, const SensorReading& reading) {
  char buf[512];
  std::visit(
      [&](const auto& r) {
        using T = std::decay_t<decltype(r)>;
        if constexpr (std::is_same_v<T, EncoderReading>) {
          std::snprintf(buf, sizeof(buf), "%.9g,%s,encoder_%s,%s,%.12g,,,,,\n", r.t,
                        r.sensor.c_str(), r.side == EncoderSide::kMotor ? "motor" : "link",
                        r.joint.c_str(), r.position);
        } else if constexpr (std::is_same_v<T, ImuReading>) {
          std::snprintf(buf, sizeof(buf), "%.9g,%s,imu,%s,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", r.t,
                        r.sensor.c_str(), r.site.c_str(), r.gyro.x(), r.gyro.y(), r.gyro.z(),
                        r.accel.x(), r.accel.y(), r.accel.z());
        } else if constexpr (std::is_same_v<T, ContactReading>) {
          std::snprintf(buf, sizeof(buf), "%.9g,%s,contact,%s,%d,%.9g,,,,\n", r.t, r.sensor.c_str(),
                        r.site.c_str(), r.touching ? 1 : 0, r.distance);
        } else {
          std::snprintf(buf, sizeof(buf), "%.9g,%s,camera,%s,%.9g,%.9g,%.9g,%.9g,%d,%d\n", r.t,
                        r.sensor.c_str(), r.camera.c_str(), r.intrinsics.fx, r.intrinsics.fy,
                        r.intrinsics.cx, r.intrinsics.cy, r.intrinsics.width, r.intrinsics.height);
        }
      },
      reading);
  out << buf;
}

}  // namespace flexbench::sim
