#include "scenarios/runner/inspect.h"

#include <cstdio>
#include <iostream>

#include "estimators/error.h"
#include "render/tag_texture.h"
#include "scenarios/runner/runner.h"
#include "sim/camera.h"
#include "sim/declared_check.h"
#include "sim/effects/effect.h"
#include "sim/export_model.h"
#include "sim/model_catalog.h"
#include "sim/mujoco_model.h"
#include "sim/sensors/sensor.h"
#include "sim/truth_model.h"

namespace flexbench::scenarios {
namespace {

using sim::JointEntry;
using sim::JointRole;

Json Vec(const double* v, int n) {
  Json a = Json::array();
  for (int i = 0; i < n; ++i) a.push_back(v[i]);
  return a;
}

const char* JointType(int type) { return type == mjJNT_SLIDE ? "slide" : "hinge"; }

const char* SensorTypeName(int type) {
  switch (type) {
    case mjSENS_GYRO:
      return "gyro";
    case mjSENS_ACCELEROMETER:
      return "accelerometer";
    case mjSENS_TOUCH:
      return "touch";
    case mjSENS_JOINTPOS:
      return "jointpos";
    case mjSENS_FRAMEPOS:
      return "framepos";
    case mjSENS_FRAMEQUAT:
      return "framequat";
    default:
      return "other";
  }
}

// The actuated joints: type, axis, body, actuator gain, damping, armature, range.
Json ActuatedJoints(const mjModel* m, const sim::ModelCatalog& catalog) {
  Json actuated = Json::array();
  for (int j : catalog.actuated) {
    const JointEntry& e = catalog.Joint(j);
    Json a;
    a["name"] = e.name;
    a["type"] = JointType(e.type);
    a["axis"] = Vec(m->jnt_axis + 3 * j, 3);
    a["body"] = sim::ObjectName(m, mjOBJ_BODY, m->jnt_bodyid[j]);
    a["actuator"] = sim::ObjectName(m, mjOBJ_ACTUATOR, e.actuator);
    a["kp"] = m->actuator_gainprm[e.actuator * mjNGAIN];
    a["damping"] = m->dof_damping[e.dof_adr];
    a["armature"] = m->dof_armature[e.dof_adr];
    if (m->jnt_limited[j]) a["range"] = Vec(m->jnt_range + 2 * j, 2);
    actuated.push_back(a);
  }
  return actuated;
}

// The passive joints (with their stiffness and the effect they belong to) and the coupled ones.
void PassiveAndCoupled(const mjModel* m, const sim::ModelCatalog& catalog, Json* out) {
  Json passive = Json::array();
  Json coupled = Json::array();
  for (const JointEntry& e : catalog.joints) {
    if (e.role == JointRole::kPassive) {
      Json p;
      p["name"] = e.name;
      p["type"] = JointType(e.type);
      p["axis"] = Vec(m->jnt_axis + 3 * e.id, 3);
      p["body"] = sim::ObjectName(m, mjOBJ_BODY, m->jnt_bodyid[e.id]);
      p["stiffness"] = m->jnt_stiffness[e.id];
      p["damping"] = m->dof_damping[e.dof_adr];
      p["armature"] = m->dof_armature[e.dof_adr];
      p["effect"] = e.effect.empty() ? Json() : Json(e.effect);
      passive.push_back(p);
    } else if (e.role == JointRole::kCoupled) {
      Json c;
      c["name"] = e.name;
      c["type"] = JointType(e.type);
      if (e.driver_slopes.empty()) {
        c["follows"] = catalog.Joint(e.drivers[0]).name;
        c["polycoef"] = Vec(m->eq_data + mjNEQDATA * e.coupling_eq, 5);
      } else {
        Json slopes;
        for (size_t k = 0; k < e.drivers.size(); ++k) {
          slopes[catalog.Joint(e.drivers[k]).name] = e.driver_slopes[k];
        }
        c["follows"] = slopes;  // d q / d q_driver of a linear linkage
        c["offset"] = e.linkage_offset;
      }
      c["effect"] = e.effect.empty() ? Json() : Json(e.effect);
      coupled.push_back(c);
    }
  }
  (*out)["passive_joints"] = passive;
  (*out)["coupled_joints"] = coupled;
}

// Encoders, IMU sites, the MJCF's own sensors and the sensor kinds a scenario can ask for.
Json Sensors(const mjModel* m, const sim::ModelCatalog& catalog) {
  Json sensors;
  sensors["encoders"] = catalog.ActuatedNames();
  sensors["imu_sites"] = catalog.imu_sites;
  Json mjcf_sensors = Json::array();
  for (int k = 0; k < m->nsensor; ++k) {
    Json s;
    s["name"] = sim::ObjectName(m, mjOBJ_SENSOR, k);
    s["type"] = SensorTypeName(m->sensor_type[k]);
    if (m->sensor_objtype[k] == mjOBJ_SITE) {
      s["site"] = sim::ObjectName(m, mjOBJ_SITE, m->sensor_objid[k]);
    }
    mjcf_sensors.push_back(s);
  }
  sensors["mjcf"] = mjcf_sensors;
  Json kinds = Json::array();
  for (const sim::SensorEntry& e : sim::SensorRegistry()) {
    kinds.push_back({{"kind", e.kind}, {"description", e.description}});
  }
  sensors["kinds"] = kinds;
  return sensors;
}

Json Cameras(const mjModel* m) {
  Json cameras = Json::array();
  for (int c = 0; c < m->ncam; ++c) {
    const PinholeCamera k = sim::CameraIntrinsics(m, c);
    Json cam;
    cam["name"] = sim::ObjectName(m, mjOBJ_CAMERA, c);
    cam["body"] = sim::ObjectName(m, mjOBJ_BODY, m->cam_bodyid[c]);
    cam["fovy_deg"] = m->cam_fovy[c];
    cam["width_px"] = k.width;
    cam["height_px"] = k.height;
    cam["fx_px"] = k.fx;
    cam["fy_px"] = k.fy;
    cam["cx_px"] = k.cx;
    cam["cy_px"] = k.cy;
    cameras.push_back(cam);
  }
  return cameras;
}

Json Tags(mjModel* m) {
  Json tags = Json::array();
  for (const render::TagInModel& t : render::ApplyTagTextures(m)) {
    Json tag;
    tag["family"] = t.family;
    tag["id"] = t.id;
    tag["geom"] = sim::ObjectName(m, mjOBJ_GEOM, t.geom_id);
    tag["body"] = sim::ObjectName(m, mjOBJ_BODY, m->geom_bodyid[t.geom_id]);
    tag["size_m"] = t.size_m;
    tags.push_back(tag);
  }
  return tags;
}

// Every truth effect: whether this model supports it, and what it would act on.
Json Effects(const mjModel* m, const sim::ModelCatalog& catalog) {
  Json effects = Json::array();
  for (const sim::EffectEntry& e : sim::EffectRegistry()) {
    const std::unique_ptr<sim::Effect> effect = e.make();
    std::string why;
    Json entry;
    entry["name"] = e.name;
    entry["supported"] = effect->SupportedBy(catalog, m, &why);
    entry["description"] = e.description;
    const auto parts = catalog.effect_parts.find(e.name);
    if (parts != catalog.effect_parts.end()) entry["parts"] = parts->second;
    if (!why.empty()) entry["missing"] = why;
    effects.push_back(entry);
  }
  return effects;
}

}  // namespace

Json InspectModel(const std::string& mjcf_path) {
  std::vector<std::string> warnings;
  sim::MjModelPtr model = sim::LoadTruthModel(mjcf_path, &warnings);
  mjModel* m = model.get();
  const sim::ModelCatalog catalog = sim::ModelCatalog::Build(m, mjcf_path);
  Json out;
  out["model"] = mjcf_path;
  out["name"] = std::string(m->names);
  out["timestep_s"] = m->opt.timestep;
  out["integrator"] = m->opt.integrator == mjINT_EULER ? "Euler"
                      : m->opt.integrator == mjINT_RK4 ? "RK4"
                                                       : "implicit";
  out["nq"] = m->nq;
  out["nbody"] = m->nbody;
  if (!warnings.empty()) out["mujoco_warnings"] = warnings;
  out["actuated_joints"] = ActuatedJoints(m, catalog);
  if (sim::IsUrdfPath(mjcf_path)) {
    char kp[32];
    std::snprintf(kp, sizeof(kp), "%g", sim::kDefaultServoKp);
    out["servos_added"] = std::string(
                              "a URDF has no actuators: as the truth, each hinge and "
                              "slide joint gets a <position> servo (kp ") +
                          kp + "), listed in actuated_joints; `flexbench convert` writes that MJCF";
  }
  PassiveAndCoupled(m, catalog, &out);
  out["sensors"] = Sensors(m, catalog);
  out["cameras"] = Cameras(m);
  out["tags"] = Tags(m);
  out["effects"] = Effects(m, catalog);
  return out;
}

int InspectCommand(const std::string& path) {
  try {
    Json out;
    const std::string ext = path.size() > 5 ? path.substr(path.size() - 5) : "";
    if (ext == ".yaml" || (path.size() > 4 && path.substr(path.size() - 4) == ".yml")) {
      const sim::DeclaredCheckSummary d = sim::CheckDeclaredFile(path);
      Json declared;
      declared["file"] = d.file;
      declared["model"] = d.model_path;
      declared["base"] = d.base;
      declared["actuated_joints"] = d.actuated_joints;
      declared["end_effector"] = d.end_effector;
      declared["observed_frames"] = d.observed_frames;
      Json sources = Json::array();
      for (const sim::DeclaredCheckSource& s : d.sources) {
        sources.push_back({{"at", s.at}, {"kind", s.at_kind}});
      }
      declared["sources"] = sources;
      out["declared"] = declared;
      out["truth"] = InspectModel(d.model_path);
    } else {
      out = InspectModel(path);
    }
    std::cout << out.dump(2, ' ', false, Json::error_handler_t::replace) << "\n";
    return kExitOk;
  } catch (const std::exception& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
