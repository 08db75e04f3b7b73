#include "sim/declared_effects.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "estimators/error.h"
#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

using kinematics::FrameId;
using kinematics::ModelEffects;

// The names declared files give the effects (kinematics' effect table; an axis tilt is written
// per axis), sorted, for messages.
std::string KnownEffectNames() {
  std::vector<std::string> names;
  for (const kinematics::EffectRow& r : kinematics::EffectTable()) {
    if (r.kind == kinematics::EffectKind::kAxisTilt) {
      names.push_back(std::string(r.name) + "_a");
      names.push_back(std::string(r.name) + "_b");
    } else {
      names.push_back(r.name);
    }
  }
  std::sort(names.begin(), names.end());
  std::string known;
  for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
  return known;
}

class EffectsBuilder {
 public:
  EffectsBuilder(const mjModel* m, const DeclaredModel& d, DeclaredChain* chain)
      : m_(m), d_(d), chain_(chain), model_(chain->model), pd_(chain->model) {}

  void Build() {
    ModelEffects& e = chain_->effects;
    e = ModelEffects::None(model_);
    if (d_.identified_effects.empty()) return;
    ExtractMasses(m_, *chain_, &e);
    kinematics::ForwardKinematics(model_, pd_, Eigen::VectorXd::Zero(model_.nq()));
    for (FrameId f = chain_->end_effector; f > 0; f = model_.frame(f).parent) e.on_path[f] = 1;
    FindMount();
    bool load_driven = false;
    for (const IdentifiedEffect& ie : d_.identified_effects) {
      load_driven |= Add(ie);
      AddVariance(ie);
    }
    if (load_driven && !HasMasses()) {
      for (const IdentifiedEffect& ie : d_.identified_effects) {
        const kinematics::EffectRow* row =
            kinematics::FindEffect(ie.effect.substr(0, ie.effect.find('@')));
        if (row != nullptr && row->load_driven) {
          Fail(ie, "acts through the gravity loads, but the model " + CapForMessage(d_.model_path) +
                       " has no masses on the arm");
        }
      }
    }
  }

 private:
  [[noreturn]] void Fail(const IdentifiedEffect& ie, const std::string& msg) const {
    throw InputError(ie.where + ": identified_effects: '" + CapForMessage(ie.effect) + "' " + msg);
  }

  // Returns whether the effect is load-driven.
  bool Add(const IdentifiedEffect& ie) {
    const size_t at = ie.effect.find('@');
    if (at == std::string::npos || at == 0 || at + 1 == ie.effect.size()) {
      Fail(ie, "is not of the form type@location");
    }
    const std::string type = ie.effect.substr(0, at);
    const std::string loc = ie.effect.substr(at + 1);
    const kinematics::EffectRow* info = kinematics::FindEffect(type);
    if (info == nullptr) Fail(ie, "is not a known effect type (" + KnownEffectNames() + ")");
    const std::vector<double>& v = ie.value;
    if (static_cast<int>(v.size()) != info->num_values) {
      Fail(ie, "needs " + std::to_string(info->num_values) + " values, got " +
                   std::to_string(v.size()));
    }
    for (double x : v) {
      if (!std::isfinite(x)) Fail(ie, "has a value that is not a finite number");
    }
    ModelEffects& e = chain_->effects;
    if (type == "thermal_expansion") {
      if (loc != "all") Fail(ie, "acts on all links: its location is 'all'");
      e.thermal += v[0];
    } else if (type == "camera_offset") {
      const FrameId f = Frame(ie, "camera/" + loc, "camera");
      for (int k = 0; k < 6; ++k) e.frames[f].origin[k] += v[k];
    } else if (type == "link_length" || type == "link_offset") {
      const FrameId f = AnyFrame(ie, loc);
      if (type == "link_length") {
        if (model_.frame(f).T_parent_ip.translation().norm() < 0.01) {
          Fail(ie, "names a frame less than 1 cm from its parent: it has no length to change");
        }
        e.frames[f].dlen += v[0];
      } else {
        e.frames[f].offset += Vec3(v[0], v[1], v[2]);
      }
    } else if (type == "payload") {
      const FrameId f = AnyFrame(ie, loc);
      if (e.payload_frame >= 0 && e.payload_frame != f) Fail(ie, "a second payload frame");
      e.payload_frame = f;
      e.payload.mass += v[0];
      e.payload.first_moment += Vec3(v[1], v[2], v[3]);
    } else if (type == "gravity_tilt") {
      // The base mounted tilted: gravity turns in the base frame, and every load with it.
      if (loc != "base") Fail(ie, "turns gravity in the base frame: its location is 'base'");
      if (gravity_tilted_) Fail(ie, "is given twice");
      gravity_tilted_ = true;
      e.g_base = kinematics::TiltedGravity(e.g_base, v[0], v[1]);
    } else if (type == "base_compliance") {
      const FrameId f = AnyFrame(ie, loc);
      if (f != e.mount) {
        Fail(ie, "names '" + loc + "', but the arm's mount is '" +
                     (e.mount > 0 ? model_.frame(e.mount).name : std::string("(none)")) + "'");
      }
      e.mount_compliance += Eigen::Vector2d(v[0], v[1]);
    } else {
      AddJointEffect(ie, type, loc);
    }
    return info->load_driven;
  }

  // The effect's parameter stds (if given) as ModelEffects::Uncertainty: variances per term;
  // the geometric terms as a twist covariance at the frame's source, whose axes are the fixed
  // part's (a translation d in parent axes is R^T d there). A payload's or a gravity tilt's
  // uncertainty is not carried (it would act through every load-driven term at once).
  void AddVariance(const IdentifiedEffect& ie) {
    if (ie.std.empty()) return;
    const size_t at = ie.effect.find('@');
    const std::string type = ie.effect.substr(0, at);
    const std::string loc = ie.effect.substr(at + 1);
    std::vector<double> v2(ie.std.size());
    for (size_t i = 0; i < v2.size(); ++i) v2[i] = ie.std[i] * ie.std[i];
    ModelEffects::Uncertainty& u = chain_->effects.uncertainty;
    const auto translation = [&](FrameId f, const Vec3& d_parent, double var) {
      const Vec3 d = model_.frame(f).T_parent_ip.rotation().transpose() * d_parent;
      u.frames[f].block<3, 3>(kTransIdx, kTransIdx) += var * d * d.transpose();
    };
    if (type == "thermal_expansion") {
      u.thermal += v2[0];
    } else if (type == "camera_offset" || type == "joint_origin") {
      const FrameId f = type == "camera_offset" ? Frame(ie, "camera/" + loc, "camera")
                                                : model_.joint_frame(JointIndex(ie, loc));
      for (int k = 0; k < 6; ++k) u.frames[f](k, k) += v2[k];
    } else if (type == "link_length") {
      const FrameId f = AnyFrame(ie, loc);
      translation(f, model_.frame(f).T_parent_ip.translation().normalized(), v2[0]);
    } else if (type == "link_offset") {
      const FrameId f = AnyFrame(ie, loc);
      for (int k = 0; k < 3; ++k) translation(f, Vec3::Unit(k), v2[k]);
    } else if (type == "base_compliance") {
      u.mount_compliance += Eigen::Vector2d(v2[0], v2[1]);
    } else if (type != "payload" && type != "gravity_tilt") {
      AddJointVariance(ie, type, JointIndex(ie, loc), v2);
    }
  }

  void AddJointVariance(const IdentifiedEffect& ie, const std::string& type, int k,
                        const std::vector<double>& v2) {
    const FrameId f = model_.joint_frame(k);
    ModelEffects::Uncertainty& u = chain_->effects.uncertainty;
    ModelEffects::JointTerms& j = u.joints[k];
    if (type == "joint_offset") {
      j.offset += v2[0];
    } else if (type == "joint_axis_tilt_a" || type == "joint_axis_tilt_b") {
      const Vec3 a = TiltAxis(model_.frame(f).joint.axis, type == "joint_axis_tilt_a");
      u.frames[f].block<3, 3>(kRotIdx, kRotIdx) += v2[0] * a * a.transpose();
    } else if (type == "joint_compliance") {
      j.compliance += v2[0];
    } else if (type == "backlash") {
      j.backlash += v2[0];
    } else if (type == "stiffening_spring") {
      j.compliance += v2[0];
      j.cubic += v2[1] / std::pow(kinematics::kStiffeningTau0Nm, 4);
    } else if (type == "transmission_error" || type == "joint_error_curve") {
      for (size_t i = 0; i < v2.size(); ++i) j.harmonic[i] += v2[i];
    } else if (type == "link_bending") {
      u.bend[f] += v2[0];
    } else if (type == "lateral_compliance") {
      u.lateral[f] += Eigen::Vector2d(v2[0], v2[1]);
    } else {
      Fail(ie, "has no uncertainty model");  // the effect table and this list disagree
    }
  }

  // The identification's tilt axes: a, the first of x, y not along the joint axis w, made
  // normal to w; b = w x a.
  static Vec3 TiltAxis(const Vec3& axis, bool a_axis) {
    Vec3 a, b;
    kinematics::TiltAxes(axis, &a, &b);
    return a_axis ? a : b;
  }

  void AddJointEffect(const IdentifiedEffect& ie, const std::string& type, const std::string& loc) {
    const int k = JointIndex(ie, loc);
    const FrameId f = model_.joint_frame(k);
    const kinematics::PpoeFrame& fr = model_.frame(f);
    const bool revolute = fr.joint.type == kinematics::JointType::kRevolute;
    ModelEffects& e = chain_->effects;
    ModelEffects::JointTerms& j = e.joints[k];
    const std::vector<double>& v = ie.value;
    if (type == "joint_offset") {
      j.offset += v[0];
      return;
    }
    if (type == "joint_origin") {
      for (int i = 0; i < 6; ++i) e.frames[f].origin[i] += v[i];
      return;
    }
    if (type == "joint_axis_tilt_a" || type == "joint_axis_tilt_b") {
      e.frames[f].tilt += v[0] * TiltAxis(fr.joint.axis, type == "joint_axis_tilt_a");
      return;
    }
    if (!revolute) Fail(ie, "needs a revolute joint; '" + loc + "' is not");
    if (type == "joint_compliance") {
      j.compliance += v[0];
    } else if (type == "backlash") {
      j.backlash += v[0];
    } else if (type == "stiffening_spring") {
      j.compliance += v[0];
      j.cubic += v[1] / (kinematics::kStiffeningTau0Nm * kinematics::kStiffeningTau0Nm);
    } else if (type == "transmission_error" || type == "joint_error_curve") {
      for (size_t i = 0; i < v.size(); ++i) j.harmonic[i] += v[i];
    } else if (type == "link_bending") {
      SetBendingLink(ie, f);
      e.frames[f].bend += v[0];
    } else if (type == "lateral_compliance") {
      ModelEffects::FrameTerms& t = e.frames[f];
      t.lateral += Eigen::Vector2d(v[0], v[1]);
      kinematics::TiltAxes(fr.joint.axis, &t.lateral_a, &t.lateral_b);
    }
  }

  // The link that ends at joint frame f starts at the previous joint (fixed frames between
  // belong to the link); shorter than 5 cm it does not bend (the identification's rule).
  void SetBendingLink(const IdentifiedEffect& ie, FrameId f) {
    const kinematics::PpoeFrame& fr = model_.frame(f);
    FrameId p = fr.parent;
    while (p > 0 && model_.frame(p).q_index < 0) p = model_.frame(p).parent;
    const std::vector<lie::SE3>& T = pd_.T_base_frame;
    Vec3 link = Vec3::Zero();
    if (p > 0) {
      const lie::SE3 T_pre = T[fr.parent] * fr.T_parent_ip;
      link = T[p].rotation().transpose() * (T_pre.translation() - T[p].translation());
    }
    if (p <= 0 || link.norm() < 0.05) {
      Fail(ie, "needs a link of at least 5 cm between two joints ending at this joint");
    }
    chain_->effects.frames[f].bend_start = p;
    chain_->effects.frames[f].bend_dir = link.normalized();
  }

  // Where a compliant base tilts: the first frame with a declared source ahead of the first
  // joint on the way to the end effector, else that joint (scenarios/identify/effect_model.cc).
  void FindMount() {
    ModelEffects& e = chain_->effects;
    FrameId first_joint = -1;
    for (FrameId f = 1; f < model_.num_frames(); ++f) {
      if (e.on_path[f] && model_.frame(f).q_index >= 0) {
        first_joint = f;
        break;
      }
    }
    e.mount = first_joint > 0 ? first_joint : -1;
    for (FrameId f = 1; f < first_joint; ++f) {
      if (e.on_path[f] && model_.frame(f).has_source) {
        e.mount = f;
        break;
      }
    }
  }

  // Below 10 g on the first joint the model carries no real masses (the identification's rule).
  bool HasMasses() {
    const ModelEffects& e = chain_->effects;
    FrameId first_joint = -1;
    for (FrameId f = 1; f < model_.num_frames() && first_joint < 0; ++f) {
      if (e.on_path[f] && model_.frame(f).q_index >= 0) first_joint = f;
    }
    if (first_joint < 0) return false;
    ModelEffects no_payload = e;
    no_payload.payload_frame = -1;
    std::vector<double> mass(model_.num_frames());
    std::vector<Vec3> first(model_.num_frames());
    kinematics::SubtreeMasses(model_, pd_, no_payload, &mass, &first);
    return mass[first_joint] > 0.01;
  }

  int JointIndex(const IdentifiedEffect& ie, const std::string& joint) const {
    for (size_t k = 0; k < chain_->q_joints.size(); ++k) {
      if (chain_->q_joints[k] == joint) return static_cast<int>(k);
    }
    Fail(ie, "names joint '" + CapForMessage(joint) + "', which is not an actuated joint of " +
                 d_.file);
  }

  FrameId Frame(const IdentifiedEffect& ie, const std::string& typed, const char* what) const {
    if (!model_.HasFrame(typed)) {
      Fail(ie, std::string("names ") + what + " '" +
                   CapForMessage(typed.substr(typed.find('/') + 1)) +
                   "', which is not in the declared chain");
    }
    return model_.FindFrame(typed);
  }

  // A frame by its untyped name, as the identification writes it: a joint's frame first, then a
  // site, geom, camera or body.
  FrameId AnyFrame(const IdentifiedEffect& ie, const std::string& name) const {
    for (const char* type : {"joint/", "site/", "geom/", "camera/", "body/"}) {
      if (model_.HasFrame(type + name)) return model_.FindFrame(type + name);
    }
    Fail(ie, "names frame '" + CapForMessage(name) + "', which is not in the declared chain");
  }

  const mjModel* m_;
  const DeclaredModel& d_;
  DeclaredChain* chain_;
  const kinematics::PpoeModel& model_;
  kinematics::PpoeData pd_;
  bool gravity_tilted_ = false;
};

}  // namespace

void ExtractMasses(const mjModel* m, const DeclaredChain& chain,
                   kinematics::ModelEffects* effects) {
  const kinematics::PpoeModel& model = chain.model;
  effects->masses.assign(model.num_frames(), kinematics::FrameMass{});
  std::map<int, FrameId> frame_of_body;
  frame_of_body[chain.base_body] = kinematics::kBaseFrame;
  for (FrameId f = 1; f < model.num_frames(); ++f) {
    const std::string& name = model.frame(f).name;
    if (name.rfind("body/", 0) != 0) continue;
    const int b = mj_name2id(m, mjOBJ_BODY, name.substr(5).c_str());
    if (b >= 0) frame_of_body[b] = f;
  }
  MjDataPtr data = MakeData(m);
  mjData* d = data.get();
  mju_copy(d->qpos, m->qpos0, m->nq);
  mj_kinematics(m, d);
  const auto pose = [&](int b) {
    Mat3 R;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = d->xmat[9 * b + 3 * r + c];
    }
    return lie::SE3(R, Vec3(d->xpos[3 * b], d->xpos[3 * b + 1], d->xpos[3 * b + 2]));
  };
  for (int b = 1; b < m->nbody; ++b) {
    if (!(m->body_mass[b] > 0.0)) continue;
    int a = b;
    while (a > 0 && !frame_of_body.count(a)) a = m->body_parentid[a];
    const auto it = frame_of_body.find(a);
    if (it == frame_of_body.end()) continue;  // not below the base
    const lie::SE3 T_w_a = pose(a);
    const Vec3 com(d->xipos[3 * b], d->xipos[3 * b + 1], d->xipos[3 * b + 2]);
    kinematics::FrameMass& fm = effects->masses[it->second];
    fm.mass += m->body_mass[b];
    fm.first_moment +=
        m->body_mass[b] * (T_w_a.rotation().transpose() * (com - T_w_a.translation()));
  }
  const Mat3 R_w_base = pose(chain.base_body).rotation();
  effects->g_base =
      R_w_base.transpose() * Vec3(m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]);
}

void ApplyIdentifiedEffects(const mjModel* m, const DeclaredModel& declared, DeclaredChain* chain) {
  EffectsBuilder(m, declared, chain).Build();
}

}  // namespace flexbench::sim
