// The effects catalogue. Each class edits only the TruthSetup; the simulation does the rest.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <optional>
#include <sstream>
#include <tuple>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/model_effects.h"
#include "estimators/lie/se3.h"
#include "sim/dynamic_effects.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

using K = kinematics::EffectKind;
using T = kinematics::TruthOnlyKind;

// An effect's name, and the tag of the model's <custom><text name="effect:NAME"> listing the
// parts it acts on: the effect table's.
std::string NameOf(K kind) { return kinematics::Row(kind).name; }

// joint_offset's former name, which gave the offset the other sign.
constexpr char kEncoderOffset[] = "encoder_offset";

int ActuatedJointOrFail(const TruthSetup& setup, const Effect& effect, const std::string& joint) {
  const int j = mj_name2id(setup.model, mjOBJ_JOINT, joint.c_str());
  if (j < 0) {
    throw InputError(effect.where() + ": " + setup.model_name + " has no joint named '" + joint +
                     "'");
  }
  if (setup.catalog->Joint(j).role != JointRole::kActuated) {
    throw InputError(effect.where() + ": joint '" + joint + "' of " + setup.model_name +
                     " is not an actuated joint");
  }
  return j;
}

int BodyOrFail(const TruthSetup& setup, const Effect& effect, const std::string& body) {
  const int b = mj_name2id(setup.model, mjOBJ_BODY, body.c_str());
  if (b <= 0) {
    throw InputError(effect.where() + ": " + setup.model_name + " has no body named '" + body +
                     "'");
  }
  return b;
}

// ---- Passive compliance joints listed by the model (base plate, links, neck, camera mount).
class JointGroupEffect : public Effect {
 public:
  explicit JointGroupEffect(std::string group) : group_(std::move(group)) {}
  void Configure(const ComponentParams& p) override {
    scale_ = p.GetPositive("stiffness_scale", 1.0);
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.JointsOfEffect(group_).empty()) return true;
    *why = "no <custom><text name=\"effect:" + group_ + "\"> listing passive joints";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    const std::vector<int> joints = s.catalog->JointsOfEffect(group_);
    if (joints.empty()) {
      throw InputError(where() + ": " + s.model_name + " has no passive joints for effect '" +
                       name() + "' (no <custom><text name=\"effect:" + group_ + "\">)");
    }
    for (int j : joints) {
      if (s.catalog->Joint(j).role == JointRole::kCoupled) {
        // A linkage: follows its equality constraint; stiffness_scale scales the polynomial.
        if (!s.catalog->Joint(j).driver_slopes.empty()) {
          throw InputError(where() + ": '" + s.catalog->Joint(j).name + "' of " + s.model_name +
                           " is a tendon linkage; effect '" + name() + "' scales polynomials");
        }
        const int eq = s.catalog->Joint(j).coupling_eq;
        for (int k = 0; k < 5; ++k) s.model->eq_data[eq * mjNEQDATA + k] *= scale_;
      } else {
        s.model->jnt_stiffness[j] *= scale_;
      }
      s.released[j] = 1;
    }
  }
  std::string Describe() const override { return "stiffness_scale=" + ShortNum(scale_); }

 private:
  std::string group_;
  double scale_ = 1.0;
};

template <auto kKind>
std::unique_ptr<Effect> MakeGroup() {
  return std::make_unique<JointGroupEffect>(kinematics::Row(kKind).name);
}

// ---- Lateral joint compliance: bearing and housing of a joint bend about the two axes normal to
// its own under the weight beyond it (Tenhumberg & Bauml 2021, kappa_alpha / kappa_beta). The
// MJCF provides the passive hinges (ModelCatalog's lateral convention); this releases them with
// the given stiffness, and the statics settle them.
//   lateral_compliance: {stiffness_Nm_per_rad: {shoulder_pitch: [k_a, k_b], elbow: 800}}
// A scalar is both axes; a scalar in place of the map is every joint the model has hinges at.
class LateralComplianceEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    const ConfigNode c = p.Require("stiffness_Nm_per_rad");
    if (!c.IsMap()) {
      all_ = Stiffness(c);
      return;
    }
    for (const std::string& j : c.Keys()) per_joint_[j] = Stiffness(c.Child(j));
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.JointsOfEffect(NameOf(K::kLateralCompliance)).empty()) return true;
    *why = "no passive hinges J_lateral_a, J_lateral_b before a joint J in its body";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    std::map<std::string, std::array<double, 2>> k = per_joint_;
    if (per_joint_.empty()) {
      for (int h : s.catalog->JointsOfEffect(NameOf(K::kLateralCompliance))) {
        k[s.catalog->Joint(LateralHingeOf(s.model, h)).name] = all_;
      }
      if (k.empty()) {
        throw InputError(where() + ": " + s.model_name +
                         " has no lateral hinges (J_lateral_a, J_lateral_b before a joint J)");
      }
    }
    for (const auto& [joint, stiffness] : k) {
      const int J = mj_name2id(s.model, mjOBJ_JOINT, joint.c_str());
      if (J < 0) {
        throw InputError(where() + ": " + s.model_name + " has no joint named '" + joint + "'");
      }
      for (int axis = 0; axis < 2; ++axis) {
        const int h = Hinge(s, joint, J, axis);
        s.model->jnt_stiffness[h] = stiffness[axis];
        s.released[h] = 1;
      }
    }
  }
  std::string Describe() const override {
    std::string d = per_joint_.empty() ? "stiffness_Nm_per_rad=" + ShortNum(all_[0]) : "";
    for (const auto& [j, v] : per_joint_) {
      d += (d.empty() ? "" : " ") + j + "=[" + ShortNum(v[0]) + "," + ShortNum(v[1]) + "]";
    }
    return d;
  }

 private:
  // [k_a, k_b] from a scalar or a pair, each > 0.
  static std::array<double, 2> Stiffness(const ConfigNode& v) {
    std::vector<double> k;
    if (v.IsSequence()) {
      k = v.AsDoubleList();
      if (k.size() != 2) v.Fail("expected a stiffness or [k_a, k_b] in N m/rad");
    } else {
      k = {v.AsDouble(), v.AsDouble()};
    }
    for (double x : k) {
      if (!(x > 0) || !std::isfinite(x)) v.Fail("must be > 0 (N m/rad)");
    }
    return {k[0], k[1]};
  }

  // J's hinge about axis a (0) or b (1), checked against the convention the identification's
  // lateral_compliance@J assumes: in J's body before J, at J's anchor, about its axis.
  int Hinge(const TruthSetup& s, const std::string& joint, int J, int axis) const {
    const mjModel* m = s.model;
    const std::string name = LateralHingeName(joint, axis);
    const int h = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    const std::string missing =
        std::string(h < 0 ? "'" + name + "'" : "") +
        (mj_name2id(m, mjOBJ_JOINT, LateralHingeName(joint, 1 - axis).c_str()) < 0
             ? std::string(h < 0 ? ", " : "") + "'" + LateralHingeName(joint, 1 - axis) + "'"
             : "");
    if (!missing.empty()) {
      throw InputError(where() + ": joint '" + joint + "' of " + s.model_name +
                       " lacks the lateral hinge(s) " + missing +
                       " (passive hinges in its body, listed before it, at its anchor)");
    }
    if (LateralHingeOf(m, h) != J || s.catalog->Joint(h).role != JointRole::kPassive) {
      throw InputError(where() + ": '" + name + "' of " + s.model_name +
                       " is not a passive hinge in the body of '" + joint + "' listed before it");
    }
    Vec3 a, b;
    kinematics::TiltAxes(Vec3(m->jnt_axis + 3 * J), &a, &b);
    const Vec3 expected = axis == 0 ? a : b;
    if ((Vec3(m->jnt_axis + 3 * h).normalized() - expected).norm() > 1e-9 ||
        (Vec3(m->jnt_pos + 3 * h) - Vec3(m->jnt_pos + 3 * J)).norm() > 1e-9) {
      throw InputError(where() + ": '" + name + "' of " + s.model_name +
                       " must sit at the anchor of '" + joint + "' with axis [" +
                       ShortNum(expected.x()) + " " + ShortNum(expected.y()) + " " +
                       ShortNum(expected.z()) + "] (the identification's lateral axis " +
                       (axis == 0 ? "a" : "b") + ")");
    }
    return h;
  }

  std::array<double, 2> all_{0.0, 0.0};
  std::map<std::string, std::array<double, 2>> per_joint_;
};

// ---- Gear elasticity between motor (encoder) and link: a torsional spring per actuated joint.
class JointComplianceEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    scale_ = p.GetPositive("stiffness_scale", 1.0);
    if (const auto c = p.Optional("stiffness_Nm_per_rad")) {
      if (c->IsMap()) {
        for (const std::string& j : c->Keys()) {
          const ConfigNode v = c->Child(j);
          if (v.AsDouble() <= 0) v.Fail("must be > 0");
          per_joint_[j] = v.AsDouble();
        }
      } else {
        all_ = c->AsDouble();
        if (all_ <= 0) c->Fail("must be > 0");
      }
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (c.actuated.empty()) {
      *why = "no actuated joints";
      return false;
    }
    return true;
  }
  void Apply(TruthSetup& s) const override {
    std::map<std::string, double> k = per_joint_;
    if (all_ > 0) {
      for (int j : s.catalog->actuated) k[s.catalog->Joint(j).name] = all_;
    }
    if (k.empty()) {
      // The model's own values: effect:joint_compliance (joints) + :stiffness (numbers).
      const std::string tag = NameOf(K::kJointCompliance);
      const auto parts = s.catalog->effect_parts.find(tag);
      const auto nums = s.catalog->effect_numbers.find(tag + ":stiffness");
      if (parts == s.catalog->effect_parts.end() || nums == s.catalog->effect_numbers.end() ||
          parts->second.size() != nums->second.size()) {
        throw InputError(where() + ": " + s.model_name + " declares no gear stiffness (effect:" +
                         tag + " with effect:" + tag + ":stiffness); give stiffness_Nm_per_rad");
      }
      for (size_t i = 0; i < parts->second.size(); ++i) k[parts->second[i]] = nums->second[i];
    }
    for (const auto& [joint, value] : k) {
      const int j = ActuatedJointOrFail(s, *this, joint);
      s.gear[j].stiffness = value * scale_;
    }
  }
  std::string Describe() const override {
    std::string d = "stiffness_scale=" + ShortNum(scale_);
    if (all_ > 0) d += " stiffness_Nm_per_rad=" + ShortNum(all_);
    for (const auto& [j, v] : per_joint_) d += " " + j + "=" + ShortNum(v);
    return d;
  }

 private:
  double scale_ = 1.0;
  double all_ = 0.0;
  std::map<std::string, double> per_joint_;
};

// ---- Backlash: play between motor and link; the load holds the link against one flank.
class BacklashEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    const ConfigNode c = p.Require("width_deg");
    if (c.IsMap()) {
      for (const std::string& j : c.Keys()) {
        const ConfigNode v = c.Child(j);
        if (v.AsDouble() < 0) v.Fail("must be >= 0");
        per_joint_[j] = v.AsDouble();
      }
    } else {
      all_ = c.AsDouble();
      if (all_ < 0) c.Fail("must be >= 0");
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    for (int j : c.actuated) {
      if (c.Joint(j).type == mjJNT_HINGE) return true;
    }
    *why = "no actuated hinge joints";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    std::map<std::string, double> w = per_joint_;
    if (w.empty()) {
      for (int j : s.catalog->actuated) {
        if (s.catalog->Joint(j).type == mjJNT_HINGE) w[s.catalog->Joint(j).name] = all_;
      }
    }
    for (const auto& [joint, deg] : w) {
      const int j = ActuatedJointOrFail(s, *this, joint);
      if (s.catalog->Joint(j).type != mjJNT_HINGE) {
        throw InputError(where() + ": backlash needs a hinge joint; '" + joint + "' is a slide");
      }
      s.gear[j].backlash = deg * kDeg;
    }
  }
  std::string Describe() const override {
    std::string d;
    if (per_joint_.empty()) d = "width_deg=" + ShortNum(all_);
    for (const auto& [j, v] : per_joint_) d += (d.empty() ? "" : " ") + j + "=" + ShortNum(v);
    return d;
  }

 private:
  double all_ = 0.0;
  std::map<std::string, double> per_joint_;
};

// ---- Payload: a solid sphere of mass_kg at offset_m in the end-effector body's frame.
class PayloadEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    mass_ = p.RequireDouble("mass_kg");
    if (mass_ < 0) p.FailKey("mass_kg", "must be >= 0");
    offset_ = p.GetVec3("offset_m", Vec3::Zero());
    radius_ = p.GetPositive("radius_m", 0.03, true);
    body_ = p.GetString("body", "");
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel* m, std::string* why) const override {
    const auto it = c.effect_parts.find(NameOf(K::kPayload));
    if (it != c.effect_parts.end() && !it->second.empty()) return true;
    *why = "no <custom><text name=\"effect:" + NameOf(K::kPayload) +
           "\"> naming the end-effector body (or give body)";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    std::string body = body_;
    if (body.empty()) {
      const auto it = s.catalog->effect_parts.find(NameOf(K::kPayload));
      if (it == s.catalog->effect_parts.end() || it->second.empty()) {
        throw InputError(where() + ": " + s.model_name +
                         " names no payload body (effect:" + NameOf(K::kPayload) + "); give body");
      }
      body = it->second.front();
    }
    const int b = BodyOrFail(s, *this, body);
    if (mass_ == 0.0) return;
    mjModel* m = s.model;
    const double M = m->body_mass[b];
    const Vec3 c(m->body_ipos + 3 * b);
    const Mat3 R = QuatFromWxyz(m->body_iquat + 4 * b).toRotationMatrix();
    const Vec3 I(m->body_inertia + 3 * b);
    const double Mt = M + mass_;
    const Vec3 c_new = (M * c + mass_ * offset_) / Mt;
    const auto shift = [](double mass, const Vec3& d) {
      return (mass * (d.squaredNorm() * Mat3::Identity() - d * d.transpose())).eval();
    };
    const Mat3 I_new = R * I.asDiagonal() * R.transpose() + shift(M, c - c_new) +
                       (0.4 * mass_ * radius_ * radius_) * Mat3::Identity() +
                       shift(mass_, offset_ - c_new);
    Eigen::SelfAdjointEigenSolver<Mat3> eig(I_new);
    Mat3 axes = eig.eigenvectors();
    if (axes.determinant() < 0) axes.col(2) *= -1.0;
    m->body_mass[b] = Mt;
    Eigen::Map<Vec3>(m->body_ipos + 3 * b) = c_new;
    Eigen::Map<Vec3>(m->body_inertia + 3 * b) = eig.eigenvalues();
    QuatToWxyz(Quat(axes).normalized(), m->body_iquat + 4 * b);
    s.constants_changed = true;
  }
  std::string Describe() const override {
    return "mass_kg=" + ShortNum(mass_) + " offset_m=[" + ShortNum(offset_.x()) + "," +
           ShortNum(offset_.y()) + "," + ShortNum(offset_.z()) + "]" +
           (body_.empty() ? "" : " body=" + body_);
  }

 private:
  double mass_ = 0.0;
  Vec3 offset_ = Vec3::Zero();
  double radius_ = 0.03;
  std::string body_;
};

// ---- Joint offset: a calibration error of both encoders of a joint. The encoders read
// link - offset (joint_offset) or link + offset (encoder_offset, the former name).
class JointOffsetEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    // joint_offset says what identification reports, link = reading + offset; the former name
    // said what the encoder adds. Negation is exact, so both give the same bits.
    sign_ = name() == kEncoderOffset ? -1.0 : 1.0;
    const ConfigNode c = p.Require("offset_deg");
    if (c.IsMap()) {
      for (const std::string& j : c.Keys()) per_joint_[j] = c.GetDouble(j);
    } else {
      all_ = c.AsDouble();
      has_all_ = true;
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.actuated.empty()) return true;
    *why = "no actuated joints";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    if (has_all_) {
      for (int j : s.catalog->actuated) s.joint_offset[j] += sign_ * (all_ * kDeg);
    }
    for (const auto& [joint, deg] : per_joint_) {
      const int j = ActuatedJointOrFail(s, *this, joint);
      s.joint_offset[j] += sign_ * (deg * kDeg);
    }
  }
  std::string Describe() const override {
    std::string d = has_all_ ? "offset_deg=" + ShortNum(all_) : "";
    for (const auto& [j, v] : per_joint_) d += (d.empty() ? "" : " ") + j + "=" + ShortNum(v);
    return d;
  }

 private:
  double sign_ = 1.0;  // of offset_deg in link - reading
  bool has_all_ = false;
  double all_ = 0.0;
  std::map<std::string, double> per_joint_;
};

// ---- Transmission error of strain-wave gears: the link runs ahead of or behind the motor by a
// periodic function of the motor angle (the flexspline's elliptic deformation: mostly 2 cycles
// per revolution, plus 1 from eccentricity). The encoder reads the motor.
//   transmission_error: {harmonics_deg: {j3: [A1, phase1, A2, phase2(, A3, phase3)]}}  (deg)
class TransmissionErrorEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    const ConfigNode c = p.Require("harmonics_deg");
    if (!c.IsMap()) c.Fail("expected {joint: [A1, phase1, A2, phase2]} in degrees");
    for (const std::string& j : c.Keys()) {
      const ConfigNode v = c.Child(j);
      const std::vector<double> h = v.AsDoubleList();
      if (h.size() != 4 && h.size() != 6) {
        v.Fail("expected [A1, phase1, A2, phase2] or with A3, phase3, in degrees");
      }
      for (size_t k = 0; k < h.size(); k += 2) {
        if (std::abs(h[k]) > 5) v.Fail("amplitudes above 5 deg");
      }
      per_joint_[j] = h;
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.actuated.empty()) return true;
    *why = "no actuated joints";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    for (const auto& [joint, h] : per_joint_) {
      const int j = ActuatedJointOrFail(s, *this, joint);
      if (s.catalog->Joint(j).type != mjJNT_HINGE) {
        throw InputError(where() + ": a transmission error needs a hinge joint; '" + joint +
                         "' is a slide");
      }
      GearSpec& g = s.gear[j];
      for (size_t k = 0; 2 * k < h.size(); ++k) {
        g.tx_amplitude[k] = h[2 * k] * kDeg;
        g.tx_phase[k] = h[2 * k + 1] * kDeg;
      }
    }
  }
  std::string Describe() const override {
    std::string d;
    for (const auto& [j, h] : per_joint_) {
      std::string list;
      for (double v : h) list += (list.empty() ? "" : ",") + ShortNum(v);
      d += (d.empty() ? "" : " ") + j + "=[" + list + "]";
    }
    return d;
  }

 private:
  std::map<std::string, std::vector<double>> per_joint_;
};

// ---- A gear spring that stiffens with deflection: torque = k d + k3 d^3.
//   stiffening_spring: {stiffness_Nm_per_rad: {j2: 800}, cubic_Nm_per_rad3: {j2: 4e7}}
class StiffeningSpringEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    for (const auto& [key, out] :
         {std::pair{"stiffness_Nm_per_rad", &k1_}, std::pair{"cubic_Nm_per_rad3", &k3_}}) {
      const ConfigNode c = p.Require(key);
      if (!c.IsMap()) c.Fail("expected {joint: value}");
      for (const std::string& j : c.Keys()) {
        const ConfigNode v = c.Child(j);
        if (!(v.AsDouble() > 0)) v.Fail("must be > 0");
        (*out)[j] = v.AsDouble();
      }
    }
    for (const auto& [j, v] : k3_) {
      if (!k1_.count(j)) p.Require("stiffness_Nm_per_rad").Fail("no linear stiffness for " + j);
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.actuated.empty()) return true;
    *why = "no actuated joints";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    for (const auto& [joint, k] : k1_) {
      const int j = ActuatedJointOrFail(s, *this, joint);
      s.gear[j].stiffness = k;
      const auto it = k3_.find(joint);
      s.gear[j].stiffness_cubic = it == k3_.end() ? 0.0 : it->second;
    }
  }
  std::string Describe() const override {
    std::string d;
    for (const auto& [j, v] : k1_) {
      d += (d.empty() ? "" : " ") + j + "=" + ShortNum(v) + "+" +
           ShortNum(k3_.count(j) ? k3_.at(j) : 0.0) + "d^3";
    }
    return d;
  }

 private:
  std::map<std::string, double> k1_, k3_;
};

// ---- Thermal expansion: the listed link bodies grow by alpha * delta_T along every offset.
class ThermalExpansionEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    delta_t_ = p.RequireDouble("delta_T_K");
    alpha_ = p.GetPositive("alpha_per_K", 2.3e-5);  // aluminium
    bodies_ = p.GetStringList("bodies", {});
    if (1.0 + alpha_ * delta_t_ <= 0.0) p.FailKey("delta_T_K", "shrinks the link to nothing");
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (c.HasEffectParts(NameOf(K::kThermalExpansion))) return true;
    *why = "no <custom><text name=\"effect:" + NameOf(K::kThermalExpansion) +
           "\"> listing link bodies (or give bodies)";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    std::vector<std::string> bodies = bodies_;
    if (bodies.empty()) {
      const auto it = s.catalog->effect_parts.find(NameOf(K::kThermalExpansion));
      if (it == s.catalog->effect_parts.end()) {
        throw InputError(where() + ": " + s.model_name + " lists no bodies for " +
                         NameOf(K::kThermalExpansion) + "; give bodies");
      }
      bodies = it->second;
    }
    mjModel* m = s.model;
    const double k = 1.0 + alpha_ * delta_t_;
    const auto scale = [k](mjtNum* v) {
      for (int i = 0; i < 3; ++i) v[i] *= k;
    };
    for (const std::string& name : bodies) {
      const int b = BodyOrFail(s, *this, name);
      scale(m->body_ipos + 3 * b);
      for (int i = 0; i < 3; ++i) m->body_inertia[3 * b + i] *= k * k;
      for (int c = 0; c < m->nbody; ++c) {
        if (c != b && m->body_parentid[c] == b) scale(m->body_pos + 3 * c);
      }
      for (int g = 0; g < m->ngeom; ++g) {
        if (m->geom_bodyid[g] != b) continue;
        scale(m->geom_pos + 3 * g);
        if (m->geom_type[g] == mjGEOM_CAPSULE || m->geom_type[g] == mjGEOM_CYLINDER) {
          m->geom_size[3 * g + 1] *= k;
        }
      }
      for (int i = 0; i < m->nsite; ++i) {
        if (m->site_bodyid[i] == b) scale(m->site_pos + 3 * i);
      }
      for (int i = 0; i < m->ncam; ++i) {
        if (m->cam_bodyid[i] == b) scale(m->cam_pos + 3 * i);
      }
      for (int j = 0; j < m->njnt; ++j) {
        if (m->jnt_bodyid[j] == b) scale(m->jnt_pos + 3 * j);
      }
    }
    s.constants_changed = true;
  }
  std::string Describe() const override {
    return "delta_T_K=" + ShortNum(delta_t_) + " alpha_per_K=" + ShortNum(alpha_);
  }

 private:
  double delta_t_ = 0.0;
  double alpha_ = 2.3e-5;
  std::vector<std::string> bodies_;
};

// ---- Joint origin: a joint placed off its nominal pose (machining, assembly). J's frame (at its
// anchor, axes of its body, before it moves) becomes T Exp(xi), xi = [rho; theta], as
// identification's joint_origin@J: the body is moved so that its joint frame lands there
// (P' = P Tr(a) Exp(xi) Tr(-a), a the anchor in the body), the anchor kept in the body.
//   joint_origin: {errors: {J: {pos_mm: [x, y, z], rot_deg: [x, y, z]}}}
class JointOriginEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    const ConfigNode errors = p.Require("errors");
    if (!errors.IsMap()) errors.Fail("expected {joint: {pos_mm: [x, y, z], rot_deg: [x, y, z]}}");
    for (const std::string& j : errors.Keys()) {
      const ConfigNode e = errors.Child(j);
      if (!e.IsMap()) e.Fail("expected {pos_mm: [x, y, z], rot_deg: [x, y, z]}");
      Vec6 xi = Vec6::Zero();
      for (const auto& [key, scale, at] :
           {std::tuple{"pos_mm", 1e-3, 0}, std::tuple{"rot_deg", kDeg, 3}}) {
        const std::optional<ConfigNode> v = e.Optional(key);
        if (!v) continue;
        const std::vector<double> x = v->AsDoubleList();
        if (x.size() != 3) v->Fail("expected [x, y, z]");
        for (int k = 0; k < 3; ++k) xi[at + k] = x[k] * scale;
      }
      errors_.emplace_back(j, xi, e.WhereKey());
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.joints.empty()) return true;
    *why = "no joints";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    mjModel* m = s.model;
    for (const auto& [joint, xi, where_key] : errors_) {
      const int j = mj_name2id(m, mjOBJ_JOINT, joint.c_str());
      if (j < 0) {
        throw InputError(where_key + ": " + s.model_name + " has no joint named '" + joint + "'");
      }
      const int b = m->jnt_bodyid[j];
      // J's lateral hinges come before it, at its anchor: they turn inside the frame the origin
      // error moves, as identification's lateral_compliance@J does after joint_origin@J.
      int first = m->body_jntadr[b];
      while (first < j && LateralHingeOf(m, first) == j) ++first;
      if (first != j) {
        throw InputError(where_key + ": joint '" + joint + "' is not the first joint of body '" +
                         ObjectName(m, mjOBJ_BODY, b) + "' (its origin sits between two joints)");
      }
      const Vec3 a(m->jnt_pos + 3 * j);
      const lie::SE3 P(QuatFromWxyz(m->body_quat + 4 * b).toRotationMatrix(),
                       Vec3(m->body_pos + 3 * b));
      const lie::SE3 P_new =
          P * lie::SE3::Translation(a) * lie::SE3::Exp(xi) * lie::SE3::Translation(-a);
      Eigen::Map<Vec3>(m->body_pos + 3 * b) = P_new.translation();
      QuatToWxyz(Quat(P_new.rotation()).normalized(), m->body_quat + 4 * b);
      // A "simple" body (diagonal mass matrix, frame aligned with the world) is no longer one.
      if (m->body_simple[b]) {
        m->body_simple[b] = 0;
        for (int i = m->nv - 1; i >= 0; --i) {
          m->dof_simplenum[i] = m->body_simple[m->dof_bodyid[i]]
                                    ? 1 + (i + 1 < m->nv ? m->dof_simplenum[i + 1] : 0)
                                    : 0;
        }
      }
    }
    s.constants_changed = true;
  }
  std::string Describe() const override {
    std::string d;
    for (const auto& [j, xi, where_key] : errors_) {
      d += (d.empty() ? "" : " ") + j + "=[" + ShortNum(xi[0] * 1e3) + "," + ShortNum(xi[1] * 1e3) +
           "," + ShortNum(xi[2] * 1e3) + " mm; " + ShortNum(xi[3] / kDeg) + "," +
           ShortNum(xi[4] / kDeg) + "," + ShortNum(xi[5] / kDeg) + " deg]";
    }
    return d;
  }

 private:
  std::vector<std::tuple<std::string, Vec6, std::string>> errors_;  // joint, xi, where
};

// ---- IMU bias and yaw drift: constant biases plus bias random walks. With no magnetometer,
// integrated yaw drifts with the gyro bias about the vertical.
class ImuBiasEffect : public Effect {
 public:
  void Configure(const ComponentParams& p) override {
    spec_.gyro_bias = p.GetVec3("gyro_bias_rad_s", Vec3::Zero());
    spec_.accel_bias = p.GetVec3("accel_bias_m_s2", Vec3::Zero());
    spec_.gyro_walk = p.GetPositive("gyro_walk_rad_s_sqrt_s", 0.0, true);
    spec_.accel_walk = p.GetPositive("accel_walk_m_s2_sqrt_s", 0.0, true);
    sites_ = p.GetStringList("sites", {});
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    if (!c.imu_sites.empty()) return true;
    *why = "no IMU site (a site with MJCF gyro and accelerometer)";
    return false;
  }
  void Apply(TruthSetup& s) const override {
    if (sites_.empty()) {
      s.imu_bias["*"] = spec_;
      return;
    }
    for (const std::string& site : sites_) {
      if (mj_name2id(s.model, mjOBJ_SITE, site.c_str()) < 0) {
        throw InputError(where() + ": " + s.model_name + " has no site named '" + site + "'");
      }
      s.imu_bias[site] = spec_;
    }
  }
  std::string Describe() const override {
    return "gyro_bias_rad_s=[" + ShortNum(spec_.gyro_bias.x()) + "," +
           ShortNum(spec_.gyro_bias.y()) + "," + ShortNum(spec_.gyro_bias.z()) +
           "] gyro_walk=" + ShortNum(spec_.gyro_walk);
  }

 private:
  ImuBiasSpec spec_;
  std::vector<std::string> sites_;
};

// ---- A dynamic effect (sim/dynamic_effects.h), its values per location:
//   joint_friction: {Nm: {link2_pitch_joint: 0.2}}     # a scalar: every location the row has
//   link_mode: {stiffness_scale: {link2_b: 0.5}, damping_scale: {link2_b: 3}}
// A value not given is the row's neutral one (the MJCF as written).
class DynamicEffect : public Effect {
 public:
  explicit DynamicEffect(DynamicKind kind) : kind_(kind) {}
  void Configure(const ComponentParams& p) override {
    const DynamicRow& row = Row(kind_);
    for (int k = 0; k < row.num_values; ++k) {
      const std::optional<ConfigNode> c = p.Optional(row.value_names[k]);
      if (!c) continue;
      if (!c->IsMap()) {
        all_[k] = c->AsDouble();
        has_all_[k] = true;
        continue;
      }
      for (const std::string& loc : c->Keys()) {
        given_[loc][k] = c->GetDouble(loc);
      }
    }
    if (!has_all_[0] && !has_all_[1] && given_.empty()) {
      throw InputError(p.where() + ": give " + row.value_names[0] +
                       (row.num_values > 1 ? std::string(" or ") + row.value_names[1] : "") +
                       " (a value, or {location: value})");
    }
  }
  bool SupportedBy(const ModelCatalog& c, const mjModel*, std::string* why) const override {
    return DynamicSupported(c, kind_, why);
  }
  void Apply(TruthSetup& s) const override {
    const DynamicRow& row = Row(kind_);
    std::vector<std::string> locations;
    if (has_all_[0] || has_all_[1]) locations = DynamicLocations(s, kind_);
    for (const auto& [loc, v] : given_) {
      if (std::find(locations.begin(), locations.end(), loc) == locations.end()) {
        locations.push_back(loc);
      }
    }
    for (const std::string& loc : locations) {
      double v[2] = {row.neutral[0], row.neutral[1]};
      for (int k = 0; k < row.num_values; ++k) {
        if (has_all_[k]) v[k] = all_[k];
        const auto it = given_.find(loc);
        if (it != given_.end() && it->second.count(k)) v[k] = it->second.at(k);
      }
      ApplyDynamic(s, kind_, loc, v, where());
    }
    if (kind_ == DynamicKind::kPayloadMass) s.constants_changed = true;
  }
  std::string Describe() const override {
    const DynamicRow& row = Row(kind_);
    std::string out;
    for (int k = 0; k < row.num_values; ++k) {
      if (has_all_[k])
        out += std::string(out.empty() ? "" : " ") + row.value_names[k] + "=" + ShortNum(all_[k]);
    }
    for (const auto& [loc, values] : given_) {
      for (const auto& [k, v] : values) {
        out += std::string(out.empty() ? "" : " ") + row.value_names[k] + "@" + loc + "=" +
               ShortNum(v);
      }
    }
    return out;
  }

 private:
  DynamicKind kind_;
  double all_[2] = {0.0, 0.0};
  bool has_all_[2] = {false, false};
  std::map<std::string, std::map<int, double>> given_;
};

template <DynamicKind kKind>
std::unique_ptr<Effect> MakeDynamic() {
  return std::make_unique<DynamicEffect>(kKind);
}

template <class E>
std::unique_ptr<Effect> Make() {
  return std::make_unique<E>();
}

using MakeFn = std::unique_ptr<Effect> (*)();

// A line of the list: the truth physics of a row of the effect table, or of a truth-only
// effect, under the table's name.
EffectEntry Line(K kind, const char* description, MakeFn make, const char* former = nullptr) {
  return {kinematics::Row(kind).name, description, make, former};
}
EffectEntry Line(T kind, const char* description, MakeFn make, const char* former = nullptr) {
  return {kinematics::Row(kind).name, description, make, former};
}
template <DynamicKind kKind>
EffectEntry Line() {
  return {Row(kKind).name, Row(kKind).description, MakeDynamic<kKind>, nullptr};
}

}  // namespace

const std::vector<EffectEntry>& EffectRegistry() {
  // One line per effect.
  static const std::vector<EffectEntry> effects = {
      Line(K::kBaseCompliance, "base plate bends under load: passive tilt joints (stiffness_scale)",
           MakeGroup<K::kBaseCompliance>, "base_plate_compliance"),
      Line(K::kLinkBending,
           "elastic links: passive bending hinges between link segments (stiffness_scale)",
           MakeGroup<K::kLinkBending>, "link_elasticity"),
      Line(T::kNeckElasticity,
           "continuum-elastic neck: chain of passive spring joints (stiffness_scale)",
           MakeGroup<T::kNeckElasticity>),
      Line(T::kCameraMountSag,
           "camera mount sags under the camera's weight: passive joint (stiffness_scale)",
           MakeGroup<T::kCameraMountSag>),
      Line(T::kNonlinearWrist,
           "wrist is a nonlinear linkage: coupled joints follow the actuated ones (scale)",
           MakeGroup<T::kNonlinearWrist>),
      Line(K::kLateralCompliance,
           "bearing and housing of a joint bend about the two axes normal to its own: releases "
           "the MJCF's passive hinges J_lateral_a, J_lateral_b (stiffness_Nm_per_rad: {J: [k_a, "
           "k_b]}; identification reports compliances 1/k, rad/Nm)",
           Make<LateralComplianceEffect>),
      Line(K::kJointCompliance,
           "gear elasticity between motor encoder and link (stiffness_Nm_per_rad; identification "
           "reports its inverse, rad/Nm)",
           Make<JointComplianceEffect>, "joint_elasticity"),
      Line(K::kBacklash,
           "play between motor and link, load holds the link on one flank (width_deg)",
           Make<BacklashEffect>),
      Line(K::kPayload, "extra mass at the end effector (mass_kg, offset_m, radius_m, body)",
           Make<PayloadEffect>),
      Line(K::kJointOffset,
           "encoder calibration offset: link angle = reading + offset_deg (encoder_offset, its "
           "former name, takes the encoder's error: reading = link + offset_deg)",
           Make<JointOffsetEffect>, kEncoderOffset),
      Line(K::kJointOrigin,
           "a joint's frame off its nominal pose, T Exp(xi) before it moves "
           "(errors: {joint: {pos_mm: [x, y, z], rot_deg: [x, y, z]}})",
           Make<JointOriginEffect>),
      Line(K::kThermalExpansion, "links grow by alpha * delta_T (delta_T_K, alpha_per_K, bodies)",
           Make<ThermalExpansionEffect>),
      Line(K::kTransmissionError,
           "strain-wave gear: link ahead of the motor by a periodic error "
           "(harmonics_deg: {joint: [A1, phase1, A2, phase2]})",
           Make<TransmissionErrorEffect>),
      Line(K::kStiffeningSpring,
           "gear spring stiffening with deflection, k d + k3 d^3 "
           "(stiffness_Nm_per_rad, cubic_Nm_per_rad3)",
           Make<StiffeningSpringEffect>, "stiffening_joint"),
      Line(T::kImuBias,
           "IMU constant bias and bias random walk, hence yaw drift (gyro_bias_rad_s, ...)",
           Make<ImuBiasEffect>),
      Line<DynamicKind::kJointDamping>(),
      Line<DynamicKind::kJointFriction>(),
      Line<DynamicKind::kJointArmature>(),
      Line<DynamicKind::kServoGain>(),
      Line<DynamicKind::kServoDelay>(),
      Line<DynamicKind::kLinkMode>(),
      Line<DynamicKind::kBaseMode>(),
      Line<DynamicKind::kPayloadMass>(),
      Line<DynamicKind::kStribeckFriction>(),
  };
  static_assert(kNumDynamicKinds == 9, "a dynamic row needs its line above");
  return effects;
}

namespace {

const EffectEntry* FindEffect(const std::string& name, std::string* known) {
  for (const EffectEntry& e : EffectRegistry()) {
    if (name == e.name || (e.former_name && name == e.former_name)) return &e;
    *known += std::string(known->empty() ? "" : ", ") + e.name;
  }
  return nullptr;
}

}  // namespace

std::string CanonicalEffectName(const std::string& name) {
  std::string known;
  const EffectEntry* entry = FindEffect(name, &known);
  return entry ? entry->name : "";
}

std::unique_ptr<Effect> MakeEffect(const std::string& name, const ComponentParams& params) {
  std::string known;
  const EffectEntry* entry = FindEffect(name, &known);
  if (!entry) {
    throw InputError(params.where() + ": unknown effect '" + name + "' (known: " + known + ")");
  }
  if (name != entry->name) NoteFormerName(params.where(), name, entry->name);
  std::unique_ptr<Effect> effect = entry->make();
  effect->set_identity(name, params.where());
  effect->Configure(params);
  return effect;
}

std::unique_ptr<Effect> MakeEffect(const std::string& name, const std::string& params_yaml) {
  return MakeEffect(name, ComponentParams::FromYaml(params_yaml, "effect '" + name + "'"));
}

std::vector<std::unique_ptr<Effect>> ParseEffects(const ConfigNode& effects) {
  std::vector<std::unique_ptr<Effect>> out;
  if (!effects.IsMap()) effects.Fail("expected a mapping {effect name: {parameters}}");
  for (const std::string& name : effects.Keys()) {
    std::optional<ConfigNode> params = effects.Optional(name);
    std::string known;
    if (!FindEffect(name, &known)) {
      throw InputError((params ? params->Where() : effects.Where()) + ": unknown effect '" + name +
                       "' (known: " + known + ")");
    }
    const std::string where =
        (params ? params->Where() : effects.Where()) + ": effect '" + name + "'";
    out.push_back(MakeEffect(name, ComponentParams(params, where)));
  }
  return out;
}

}  // namespace flexbench::sim
