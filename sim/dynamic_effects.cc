#include "sim/dynamic_effects.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/config.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

using K = DynamicKind;
using L = DynamicLocation;

constexpr std::array<DynamicRow, kNumDynamicKinds> kRows = {{
    {K::kJointDamping,
     "joint_damping",
     L::kJoint,
     1,
     {"Nm_s_per_rad", ""},
     {0, 0},
     {50, 0},
     {0, 0},
     {0.01, 0},
     true,
     "viscous damping added to a joint's (dof_damping)"},
    {K::kJointFriction,
     "joint_friction",
     L::kJoint,
     1,
     {"Nm", ""},
     {0, 0},
     {20, 0},
     {0, 0},
     {0.005, 0},
     true,
     "dry (Coulomb) friction of a joint (frictionloss)"},
    {K::kJointArmature,
     "joint_armature",
     L::kJoint,
     1,
     {"kg_m2", ""},
     {0, 0},
     {5, 0},
     {0, 0},
     {0.001, 0},
     true,
     "rotor inertia reflected through the gear, added (armature)"},
    {K::kServoGain,
     "servo_gain",
     L::kActuatedJoint,
     1,
     {"scale", ""},
     {0.1, 0},
     {10, 0},
     {1, 0},
     {0.01, 0},
     true,
     "the position servo's stiffness kp, scaled"},
    {K::kServoDelay,
     "servo_delay",
     L::kActuatedJoint,
     1,
     {"s", ""},
     {0, 0},
     {0.2, 0},
     {0, 0},
     {0.001, 0},
     true,
     "the servo acts on the command it was sent this long ago"},
    {K::kLinkMode,
     "link_mode",
     L::kBendingBody,
     2,
     {"stiffness_scale", "damping_scale"},
     {0.05, 0.0},
     {20, 100},
     {1, 1},
     {0.01, 0.02},
     true,
     "a link's first bending mode: its passive bending joints released, their stiffness and "
     "damping scaled"},
    {K::kBaseMode,
     "base_mode",
     L::kBasePlate,
     2,
     {"stiffness_scale", "damping_scale"},
     {0.05, 0.0},
     {20, 100},
     {1, 1},
     {0.01, 0.02},
     true,
     "the base plate sways: its passive joints released, their stiffness and damping scaled"},
    {K::kPayloadMass,
     "payload_mass",
     L::kBody,
     1,
     {"kg", ""},
     {0, 0},
     {20, 0},
     {0, 0},
     {0.005, 0},
     true,
     "a point mass added at a payload body's centre of mass"},
    {K::kStribeckFriction,
     "stribeck_friction",
     L::kActuatedJoint,
     2,
     {"static_Nm", "coulomb_Nm"},
     {0, 0},
     {20, 20},
     {0, 0},
     {0, 0},
     false,
     "breakaway friction above the sliding friction at low speed (truth only)"},
}};

template <size_t... I>
constexpr bool InKindOrder(std::index_sequence<I...>) {
  return ((kRows[I].kind == static_cast<K>(I)) && ...);
}
static_assert(InKindOrder(std::make_index_sequence<kNumDynamicKinds>{}),
              "kRows must list every DynamicKind once, in enum order");

bool Contains(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

// Bodies holding the model's passive bending joints (effect:link_bending), in model order.
std::vector<std::string> BendingBodies(const TruthSetup& s) {
  std::vector<std::string> bodies;
  for (int j : s.catalog->JointsOfEffect("link_bending")) {
    const std::string b = ObjectName(s.model, mjOBJ_BODY, s.model->jnt_bodyid[j]);
    if (!Contains(bodies, b)) bodies.push_back(b);
  }
  return bodies;
}

void ScaleJoints(TruthSetup& s, const std::vector<int>& joints, const double* v) {
  for (int j : joints) {
    s.model->jnt_stiffness[j] *= v[0];
    s.model->dof_damping[s.model->jnt_dofadr[j]] *= v[1];
    s.released[j] = 1;
  }
}

}  // namespace

const std::array<DynamicRow, kNumDynamicKinds>& DynamicTable() { return kRows; }

const DynamicRow& Row(DynamicKind kind) { return kRows[static_cast<int>(kind)]; }

const DynamicRow* FindDynamic(const std::string& name) {
  for (const DynamicRow& r : kRows) {
    if (name == r.name) return &r;
  }
  return nullptr;
}

std::vector<int> DynamicParts(const TruthSetup& s, DynamicKind kind, const std::string& loc) {
  const mjModel* m = s.model;
  switch (Row(kind).location) {
    case L::kJoint:
    case L::kActuatedJoint: {
      const int j = mj_name2id(m, mjOBJ_JOINT, loc.c_str());
      if (j < 0 || m->jnt_type[j] == mjJNT_FREE || m->jnt_type[j] == mjJNT_BALL) return {};
      if (Row(kind).location == L::kActuatedJoint &&
          s.catalog->Joint(j).role != JointRole::kActuated) {
        return {};
      }
      return {j};
    }
    case L::kBendingBody: {
      std::vector<int> joints;
      for (int j : s.catalog->JointsOfEffect("link_bending")) {
        if (ObjectName(m, mjOBJ_BODY, m->jnt_bodyid[j]) == loc) joints.push_back(j);
      }
      return joints;
    }
    case L::kBasePlate:
      return loc == "base_plate" ? s.catalog->JointsOfEffect("base_compliance")
                                 : std::vector<int>{};
    case L::kBody: {
      const int b = mj_name2id(m, mjOBJ_BODY, loc.c_str());
      return b > 0 ? std::vector<int>{b} : std::vector<int>{};
    }
  }
  return {};
}

bool DynamicSupported(const ModelCatalog& c, DynamicKind kind, std::string* why) {
  switch (Row(kind).location) {
    case L::kJoint:
    case L::kActuatedJoint:
      if (!c.actuated.empty()) return true;
      *why = "no actuated joint";
      return false;
    case L::kBendingBody:
      if (!c.JointsOfEffect("link_bending").empty()) return true;
      *why = "no <custom><text name=\"effect:link_bending\"> listing passive joints";
      return false;
    case L::kBasePlate:
      if (!c.JointsOfEffect("base_compliance").empty()) return true;
      *why = "no <custom><text name=\"effect:base_compliance\"> listing passive joints";
      return false;
    case L::kBody:
      if (c.effect_parts.count("payload") && !c.effect_parts.at("payload").empty()) return true;
      *why = "no <custom><text name=\"effect:payload\"> naming a body";
      return false;
  }
  return false;
}

std::vector<std::string> DynamicLocations(const TruthSetup& s, DynamicKind kind) {
  std::vector<std::string> out;
  switch (Row(kind).location) {
    case L::kJoint:
    case L::kActuatedJoint:
      for (int j : s.catalog->actuated) out.push_back(s.catalog->Joint(j).name);
      break;
    case L::kBendingBody:
      out = BendingBodies(s);
      break;
    case L::kBasePlate:
      if (!s.catalog->JointsOfEffect("base_compliance").empty()) out.push_back("base_plate");
      break;
    case L::kBody:
      if (const auto it = s.catalog->effect_parts.find("payload");
          it != s.catalog->effect_parts.end()) {
        out = it->second;
      }
      break;
  }
  return out;
}

void ApplyDynamic(TruthSetup& s, DynamicKind kind, const std::string& loc, const double* v,
                  const std::string& where) {
  const DynamicRow& row = Row(kind);
  for (int k = 0; k < row.num_values; ++k) {
    if (!(v[k] >= row.lower[k] && v[k] <= row.upper[k])) {
      throw InputError(where + ": " + row.name + " " + row.value_names[k] + " = " + ShortNum(v[k]) +
                       " is outside [" + ShortNum(row.lower[k]) + ", " + ShortNum(row.upper[k]) +
                       "]");
    }
  }
  const std::vector<int> parts = DynamicParts(s, kind, loc);
  if (parts.empty()) {
    std::string known;
    for (const std::string& l : DynamicLocations(s, kind)) known += (known.empty() ? "" : ", ") + l;
    throw InputError(where + ": " + s.model_name + " has no '" + loc + "' for " + row.name +
                     " (it has: " + (known.empty() ? "none" : known) + ")");
  }
  mjModel* m = s.model;
  const int j = parts[0];
  switch (kind) {
    case K::kJointDamping:
      m->dof_damping[m->jnt_dofadr[j]] += v[0];
      break;
    case K::kJointFriction:
      m->dof_frictionloss[m->jnt_dofadr[j]] += v[0];
      break;
    case K::kJointArmature:
      m->dof_armature[m->jnt_dofadr[j]] += v[0];
      break;
    case K::kServoGain: {
      const int a = s.catalog->Joint(j).actuator;
      m->actuator_gainprm[a * mjNGAIN] *= v[0];
      m->actuator_biasprm[a * mjNBIAS + 1] *= v[0];
      break;
    }
    case K::kServoDelay:
      s.servo_delay.at(j) = v[0];
      break;
    case K::kLinkMode:
    case K::kBaseMode:
      ScaleJoints(s, parts, v);
      break;
    case K::kPayloadMass:
      m->body_mass[j] += v[0];
      s.constants_changed = true;
      break;
    case K::kStribeckFriction:
      s.stribeck.at(j).static_Nm = v[0];
      s.stribeck.at(j).coulomb_Nm = v[1];
      break;
  }
}

std::array<double, 2> Combined(DynamicKind kind, const std::array<double, 2>& first,
                               const std::array<double, 2>& second) {
  switch (kind) {
    case K::kServoGain:
      return {first[0] * second[0], 0.0};
    case K::kLinkMode:
    case K::kBaseMode:
      return {first[0] * second[0], first[1] * second[1]};
    case K::kServoDelay:
    case K::kStribeckFriction:
      return second;
    case K::kJointDamping:
    case K::kJointFriction:
    case K::kJointArmature:
    case K::kPayloadMass:
      break;
  }
  return {first[0] + second[0], first[1] + second[1]};
}

bool HasStandingPart(DynamicKind kind) { return kind == K::kLinkMode || kind == K::kPayloadMass; }

bool IsDynamicEffect(const std::string& effect) {
  return FindDynamic(effect.substr(0, effect.find('@'))) != nullptr;
}

std::vector<DeclaredDynamic> DynamicEntries(const std::vector<IdentifiedEffect>& effects) {
  std::vector<DeclaredDynamic> out;
  for (const IdentifiedEffect& ie : effects) {
    if (!IsDynamicEffect(ie.effect)) continue;
    const auto fail = [&](const std::string& msg) {
      throw InputError(ie.where + ": identified_effects: '" + CapForMessage(ie.effect) + "' " +
                       msg);
    };
    const size_t at = ie.effect.find('@');
    if (at == std::string::npos || at + 1 == ie.effect.size()) {
      fail("is not of the form type@location");
    }
    DeclaredDynamic d;
    d.row = FindDynamic(ie.effect.substr(0, at));
    if (!d.row->fitted) fail("is an effect of the truth only: no model carries it");
    d.location = ie.effect.substr(at + 1);
    d.where = ie.where;
    const int n = d.row->num_values;
    if (static_cast<int>(ie.value.size()) != n) {
      fail("needs " + std::to_string(n) + " values, got " + std::to_string(ie.value.size()));
    }
    if (!ie.std.empty() && static_cast<int>(ie.std.size()) != n) {
      fail("needs " + std::to_string(n) + " stds, got " + std::to_string(ie.std.size()));
    }
    for (const DeclaredDynamic& earlier : out) {
      if (earlier.row == d.row && earlier.location == d.location) fail("is given twice");
    }
    for (int k = 0; k < n; ++k) {
      const double v = ie.value[k];
      if (!std::isfinite(v)) fail("has a value that is not a finite number");
      if (!ie.std.empty() && !(ie.std[k] >= 0.0 && std::isfinite(ie.std[k]))) {
        fail("has a std that is not a finite number >= 0");
      }
      if (!(v >= d.row->lower[k] && v <= d.row->upper[k])) {
        fail(std::string(d.row->value_names[k]) + " = " + ShortNum(v) + " is outside [" +
             ShortNum(d.row->lower[k]) + ", " + ShortNum(d.row->upper[k]) + "]");
      }
      d.values[k] = v;
      if (!ie.std.empty()) d.stds[k] = ie.std[k];
    }
    out.push_back(d);
  }
  return out;
}

std::vector<StaticCounterpart> DynamicCounterparts(const mjModel* m, const ModelCatalog& c,
                                                   const DeclaredModel& d) {
  std::vector<StaticCounterpart> out;
  const auto add = [&](const IdentifiedEffect& ie, DynamicKind kind, const std::string& loc,
                       double v0, double v1) {
    StaticCounterpart sc;
    sc.static_effect = ie.effect;
    sc.dynamic.row = &Row(kind);
    sc.dynamic.location = loc;
    sc.dynamic.values = {std::clamp(v0, Row(kind).lower[0], Row(kind).upper[0]),
                         std::clamp(v1, Row(kind).lower[1], Row(kind).upper[1])};
    sc.dynamic.where = ie.where;
    out.push_back(sc);
  };
  const std::vector<int> bending = c.JointsOfEffect("link_bending");
  for (const IdentifiedEffect& ie : d.identified_effects) {
    const size_t at = ie.effect.find('@');
    if (at == std::string::npos || ie.value.empty() || !(ie.value[0] > 0.0)) continue;
    const std::string type = ie.effect.substr(0, at), loc = ie.effect.substr(at + 1);
    if (type == "link_bending") {
      const int j = mj_name2id(m, mjOBJ_JOINT, loc.c_str());
      if (j < 0) continue;
      // Up from the joint's body to the link's bending body, not past the joint before.
      for (int b = m->body_parentid[m->jnt_bodyid[j]]; b > 0; b = m->body_parentid[b]) {
        double k = 0.0;
        int n = 0;
        for (int bj : bending) {
          if (m->jnt_bodyid[bj] == b) k += m->jnt_stiffness[bj], ++n;
        }
        if (n > 0 && k > 0.0) {
          add(ie, DynamicKind::kLinkMode, ObjectName(m, mjOBJ_BODY, b), n / (ie.value[0] * k), 1.0);
          break;
        }
        bool actuated = false;
        for (int a = m->body_jntadr[b]; a >= 0 && a < m->body_jntadr[b] + m->body_jntnum[b]; ++a) {
          actuated |= c.Joint(a).role == JointRole::kActuated;
        }
        if (actuated) break;
      }
    } else if (type == "payload") {
      const auto it = c.effect_parts.find("payload");
      if (it != c.effect_parts.end() &&
          std::find(it->second.begin(), it->second.end(), loc) != it->second.end()) {
        add(ie, DynamicKind::kPayloadMass, loc, ie.value[0], 0.0);
      }
    }
  }
  return out;
}

}  // namespace flexbench::sim
