#include "sim/model_catalog.h"

#include <sstream>

#include "estimators/error.h"
#include "estimators/kinematics/effect_table.h"
#include "sim/config.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

constexpr char kEffectPrefix[] = "effect:";

std::vector<std::string> SplitWords(const std::string& text) {
  std::istringstream in(text);
  std::vector<std::string> out;
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

void ReadJoints(const mjModel* m, ModelCatalog* c) {
  c->joints.resize(m->njnt);
  for (int j = 0; j < m->njnt; ++j) {
    JointEntry& e = c->joints[j];
    e.id = j;
    e.name = ObjectName(m, mjOBJ_JOINT, j);
    e.type = m->jnt_type[j];
    e.qpos_adr = m->jnt_qposadr[j];
    e.dof_adr = m->jnt_dofadr[j];
    if (e.type != mjJNT_HINGE && e.type != mjJNT_SLIDE) {
      throw InputError(c->model_name + ": joint '" + e.name +
                       "' is a ball or free joint; truth models use hinge and slide joints only");
    }
    if (e.name.empty()) {
      throw InputError(c->model_name + ": every joint needs a name (joint " + std::to_string(j) +
                       " has none)");
    }
  }
}

// MuJoCo's <position>: fixed gain kp, bias -kp * q, no velocity term, on a joint.
bool IsPositionServo(const mjModel* m, int a) {
  return m->actuator_trntype[a] == mjTRN_JOINT && m->actuator_dyntype[a] == mjDYN_NONE &&
         m->actuator_gaintype[a] == mjGAIN_FIXED && m->actuator_biastype[a] == mjBIAS_AFFINE &&
         m->actuator_gainprm[a * mjNGAIN] > 0 &&
         m->actuator_biasprm[a * mjNBIAS + 1] == -m->actuator_gainprm[a * mjNGAIN] &&
         m->actuator_biasprm[a * mjNBIAS + 2] == 0;
}

void ReadActuators(const mjModel* m, ModelCatalog* c) {
  for (int a = 0; a < m->nu; ++a) {
    const std::string an = ObjectName(m, mjOBJ_ACTUATOR, a);
    if (!IsPositionServo(m, a)) {
      throw InputError(c->model_name + ": actuator '" + an +
                       "' is not a <position> servo on a joint (the truth commands joint angles)");
    }
    const int j = m->actuator_trnid[2 * a];
    if (c->joints[j].actuator >= 0) {
      throw InputError(c->model_name + ": joint '" + c->joints[j].name + "' has two actuators");
    }
    c->joints[j].actuator = a;
    c->joints[j].role = JointRole::kActuated;
    c->actuated.push_back(j);
  }
}

void ReadJointCoupling(const mjModel* m, int e, ModelCatalog* c) {
  JointEntry& j1 = c->joints[m->eq_obj1id[e]];
  if (j1.role == JointRole::kActuated) {
    throw InputError(c->model_name + ": joint '" + j1.name +
                     "' is actuated and also coupled by an equality constraint");
  }
  j1.role = JointRole::kCoupled;
  j1.coupling_eq = e;
  j1.drivers = {m->eq_obj2id[e]};
}

// A fixed tendon held at its reference length: its one joint without an actuator follows the
// others.
void ReadTendonCoupling(const mjModel* m, int e, ModelCatalog* c) {
  const int t = m->eq_obj1id[e];
  const std::string where = c->model_name + ": tendon '" + ObjectName(m, mjOBJ_TENDON, t) + "'";
  int coupled = -1;
  double coupled_coef = 0.0;
  std::vector<std::pair<int, double>> drivers;
  for (int w = m->tendon_adr[t]; w < m->tendon_adr[t] + m->tendon_num[t]; ++w) {
    if (m->wrap_type[w] != mjWRAP_JOINT) {
      throw InputError(where + " of an equality constraint is not a fixed tendon (joints only)");
    }
    const int j = m->wrap_objid[w];
    if (c->joints[j].role == JointRole::kActuated) {
      drivers.emplace_back(j, m->wrap_prm[w]);
    } else if (coupled >= 0) {
      throw InputError(where + " couples two joints without an actuator ('" +
                       c->joints[coupled].name + "', '" + c->joints[j].name + "'): one follows");
    } else {
      coupled = j;
      coupled_coef = m->wrap_prm[w];
    }
  }
  if (coupled < 0 || coupled_coef == 0.0 || drivers.empty()) {
    throw InputError(where + " needs one joint without an actuator (nonzero coef) and drivers");
  }
  JointEntry& jc = c->joints[coupled];
  jc.role = JointRole::kCoupled;
  jc.coupling_eq = e;
  for (const auto& [j, coef] : drivers) {
    jc.drivers.push_back(j);
    jc.driver_slopes.push_back(-coef / coupled_coef);
  }
  jc.linkage_offset = m->eq_data[e * mjNEQDATA] / coupled_coef;
}

void ReadCouplings(const mjModel* m, ModelCatalog* c) {
  for (int e = 0; e < m->neq; ++e) {
    if (m->eq_type[e] == mjEQ_JOINT && m->eq_obj2id[e] >= 0) ReadJointCoupling(m, e, c);
    if (m->eq_type[e] == mjEQ_TENDON && m->eq_obj2id[e] < 0) ReadTendonCoupling(m, e, c);
  }
}

// "effect:NAME[:param]" -> "NAME[:param]" with a former effect name read as its current one.
std::string EffectField(const std::string& field, const std::string& model_name) {
  const std::string tag = field.substr(sizeof(kEffectPrefix) - 1);
  const size_t colon = tag.find(':');
  const std::string effect = tag.substr(0, colon);
  const std::string current = CanonicalEffectName(effect);
  if (current.empty() || current == effect) return tag;
  NoteFormerName(model_name + ": <custom> " + field, effect, current);
  return current + (colon == std::string::npos ? "" : tag.substr(colon));
}

template <class Map, class Value>
void PutField(Map* fields, const std::string& field, Value value, const ModelCatalog& c) {
  const std::string key = EffectField(field, c.model_name);
  if (!fields->emplace(key, std::move(value)).second) {
    throw InputError(c.model_name + ": <custom> names effect:" + key +
                     " twice (once by a former name)");
  }
}

void ReadEffectFields(const mjModel* m, ModelCatalog* c) {
  for (int t = 0; t < m->ntext; ++t) {
    const std::string name = ObjectName(m, mjOBJ_TEXT, t);
    if (name.rfind(kEffectPrefix, 0) != 0) continue;
    PutField(&c->effect_parts, name, SplitWords(m->text_data + m->text_adr[t]), *c);
  }
  for (int n = 0; n < m->nnumeric; ++n) {
    const std::string name = ObjectName(m, mjOBJ_NUMERIC, n);
    if (name.rfind(kEffectPrefix, 0) != 0) continue;
    const double* data = m->numeric_data + m->numeric_adr[n];
    PutField(&c->effect_numbers, name, std::vector<double>(data, data + m->numeric_size[n]), *c);
  }
}

// Joint-listing effects: every name must be a joint, and each joint belongs to one effect.
void AssignEffectJoints(const mjModel* m, ModelCatalog* c) {
  for (const auto& [effect, parts] : c->effect_parts) {
    for (const std::string& part : parts) {
      const int j = mj_name2id(m, mjOBJ_JOINT, part.c_str());
      if (j < 0) continue;  // bodies (payload, thermal expansion) are checked by their effect
      JointEntry& e = c->joints[j];
      if (e.role == JointRole::kActuated) continue;  // joint_compliance, backlash
      if (!e.effect.empty() && e.effect != effect) {
        throw InputError(c->model_name + ": joint '" + part + "' is listed by effect:" + e.effect +
                         " and effect:" + effect);
      }
      e.effect = effect;
    }
  }
}

// Hinges named by the lateral compliance convention belong to that effect unless a field lists
// them under another.
void ClaimLateralHinges(const mjModel* m, ModelCatalog* c) {
  for (int j = 0; j < m->njnt; ++j) {
    JointEntry& e = c->joints[j];
    if (e.role == JointRole::kPassive && e.effect.empty() && LateralHingeOf(m, j) >= 0) {
      e.effect = kinematics::Row(kinematics::EffectKind::kLateralCompliance).name;
    }
  }
}

void FindImuSites(const mjModel* m, ModelCatalog* c) {
  for (int s = 0; s < m->nsite; ++s) {
    bool gyro = false;
    bool accel = false;
    for (int k = 0; k < m->nsensor; ++k) {
      if (m->sensor_objtype[k] != mjOBJ_SITE || m->sensor_objid[k] != s) continue;
      gyro |= m->sensor_type[k] == mjSENS_GYRO;
      accel |= m->sensor_type[k] == mjSENS_ACCELEROMETER;
    }
    if (gyro && accel) c->imu_sites.push_back(ObjectName(m, mjOBJ_SITE, s));
  }
}

}  // namespace

ModelCatalog ModelCatalog::Build(const mjModel* m, const std::string& model_name) {
  ModelCatalog c;
  c.model_name = model_name;
  ReadJoints(m, &c);
  ReadActuators(m, &c);
  ReadCouplings(m, &c);
  ReadEffectFields(m, &c);
  AssignEffectJoints(m, &c);
  ClaimLateralHinges(m, &c);
  FindImuSites(m, &c);
  return c;
}

void CoupledValue(const mjModel* m, const JointEntry& joint, const mjtNum* qpos, double* dq,
                  std::vector<double>* slopes) {
  slopes->resize(joint.drivers.size());
  if (joint.driver_slopes.empty()) {
    // MuJoCo's joint-equality polynomial: y - y0 = sum_k a_k (x - x0)^k.
    const int a2 = m->jnt_qposadr[joint.drivers[0]];
    const double x = qpos[a2] - m->qpos0[a2];
    const mjtNum* a = m->eq_data + joint.coupling_eq * mjNEQDATA;
    *dq = a[0] + x * (a[1] + x * (a[2] + x * (a[3] + x * a[4])));
    (*slopes)[0] = a[1] + x * (2 * a[2] + x * (3 * a[3] + x * 4 * a[4]));
    return;
  }
  *dq = joint.linkage_offset;
  for (size_t k = 0; k < joint.drivers.size(); ++k) {
    const int a = m->jnt_qposadr[joint.drivers[k]];
    *dq += joint.driver_slopes[k] * (qpos[a] - m->qpos0[a]);
    (*slopes)[k] = joint.driver_slopes[k];
  }
}

std::vector<int> ModelCatalog::JointsOfEffect(const std::string& effect) const {
  std::vector<int> out;
  for (const JointEntry& e : joints) {
    if (e.effect == effect) out.push_back(e.id);
  }
  return out;
}

std::string LateralHingeName(const std::string& joint, int axis) {
  return joint + (axis == 0 ? "_lateral_a" : "_lateral_b");
}

int LateralHingeOf(const mjModel* m, int j) {
  const std::string name = ObjectName(m, mjOBJ_JOINT, j);
  constexpr size_t kSuffix = sizeof("_lateral_a") - 1;
  if (name.size() <= kSuffix || m->jnt_type[j] != mjJNT_HINGE) return -1;
  const std::string joint = name.substr(0, name.size() - kSuffix);
  if (name != LateralHingeName(joint, 0) && name != LateralHingeName(joint, 1)) return -1;
  const int J = mj_name2id(m, mjOBJ_JOINT, joint.c_str());
  if (J <= j || m->jnt_bodyid[J] != m->jnt_bodyid[j] || m->jnt_type[J] != mjJNT_HINGE) return -1;
  return J;
}

std::vector<std::string> ModelCatalog::ActuatedNames() const {
  std::vector<std::string> out;
  for (int j : actuated) out.push_back(joints[j].name);
  return out;
}

}  // namespace flexbench::sim
