#include "sim/declared_effects.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>

#include "estimators/error.h"
#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "sim/dynamic_effects.h"
#include "sim/mujoco_model.h"

// Each row of the effect table has its case in the switches below: a kind without one fails to
// build.
#pragma GCC diagnostic error "-Wswitch"

namespace flexbench::sim {
namespace {

using kinematics::FrameId;
using kinematics::ModelEffects;

using K = kinematics::EffectKind;

// The names declared files give the effects (the effect table's; an axis tilt is written per
// axis), sorted, for messages.
std::string KnownEffectNames() {
  std::vector<std::string> names;
  for (const kinematics::EffectRow& r : kinematics::EffectTable()) {
    names.push_back(kinematics::FileName(r.kind, 0));
    if (r.kind == K::kAxisTilt) names.push_back(kinematics::FileName(r.kind, 1));
  }
  std::sort(names.begin(), names.end());
  std::string known;
  for (const std::string& n : names) known += (known.empty() ? "" : ", ") + n;
  return known;
}

// An identified_effects entry's type@location, split, with its row.
struct Parsed {
  const kinematics::EffectRow* row = nullptr;  // nullptr: no effect of that name
  int axis = 0;                                // an axis tilt's axis (0: a, 1: b)
  std::string loc;
};

Parsed Parse(const IdentifiedEffect& ie) {
  const size_t at = ie.effect.find('@');
  Parsed p;
  p.row = kinematics::FindEffect(ie.effect.substr(0, at), &p.axis);
  if (at != std::string::npos) p.loc = ie.effect.substr(at + 1);
  return p;
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
    // Checked as a whole (an entry given twice); in the file's order.
    const std::vector<DeclaredDynamic> dynamic = DynamicEntries(d_.identified_effects);
    std::vector<const DeclaredDynamic*> dynamic_of;  // per entry, its dynamic row or nullptr
    for (size_t i = 0, k = 0; i < d_.identified_effects.size(); ++i) {
      const bool is = IsDynamicEffect(d_.identified_effects[i].effect);
      dynamic_of.push_back(is ? &dynamic[k++] : nullptr);
    }
    for (size_t i = 0; i < d_.identified_effects.size(); ++i) {
      const IdentifiedEffect& ie = d_.identified_effects[i];
      if (dynamic_of[i]) {
        load_driven |= AddStaticPartOf(ie, *dynamic_of[i]);
        continue;
      }
      const Parsed p = Check(ie);
      Add(ie, p);
      AddVariance(ie, p);
      load_driven |= p.row->load_driven;
    }
    if (load_driven && !HasMasses()) {
      for (size_t i = 0; i < d_.identified_effects.size(); ++i) {
        const IdentifiedEffect& ie = d_.identified_effects[i];
        const bool loads =
            dynamic_of[i] ? HasStandingPart(dynamic_of[i]->row->kind) : Parse(ie).row->load_driven;
        if (loads) {
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

  // The entry parsed, its name and values checked against its row.
  Parsed Check(const IdentifiedEffect& ie) const {
    const size_t at = ie.effect.find('@');
    if (at == std::string::npos || at == 0 || at + 1 == ie.effect.size()) {
      Fail(ie, "is not of the form type@location");
    }
    const Parsed p = Parse(ie);
    if (p.row == nullptr) Fail(ie, "is not a known effect type (" + KnownEffectNames() + ")");
    const std::vector<double>& v = ie.value;
    if (static_cast<int>(v.size()) != p.row->num_values) {
      Fail(ie, "needs " + std::to_string(p.row->num_values) + " values, got " +
                   std::to_string(v.size()));
    }
    for (double x : v) {
      if (!std::isfinite(x)) Fail(ie, "has a value that is not a finite number");
    }
    return p;
  }

  // The effect's values onto the ModelEffects' terms, at its location (the maths of each row;
  // identify::EffectModel::AddTerms is the fit's).
  void Add(const IdentifiedEffect& ie, const Parsed& p) {
    ModelEffects& e = chain_->effects;
    const std::vector<double>& v = ie.value;
    const std::string& loc = p.loc;
    switch (p.row->kind) {
      case K::kThermalExpansion:
        if (loc != "all") Fail(ie, "acts on all links: its location is 'all'");
        e.thermal += v[0];
        break;
      case K::kCameraOffset: {
        const FrameId f = Frame(ie, "camera/" + loc, "camera");
        for (int k = 0; k < 6; ++k) e.frames[f].origin[k] += v[k];
        break;
      }
      case K::kLinkLength: {
        const FrameId f = AnyFrame(ie, loc);
        if (model_.frame(f).T_parent_ip.translation().norm() < 0.01) {
          Fail(ie, "names a frame less than 1 cm from its parent: it has no length to change");
        }
        e.frames[f].dlen += v[0];
        break;
      }
      case K::kLinkOffset:
        e.frames[AnyFrame(ie, loc)].offset += Vec3(v[0], v[1], v[2]);
        break;
      case K::kPayload: {
        const FrameId f = AnyFrame(ie, loc);
        if (e.payload_frame >= 0 && e.payload_frame != f) Fail(ie, "a second payload frame");
        e.payload_frame = f;
        e.payload.mass += v[0];
        e.payload.first_moment += Vec3(v[1], v[2], v[3]);
        break;
      }
      case K::kGravityTilt:
        // The base mounted tilted: gravity turns in the base frame, and every load with it.
        if (loc != "base") Fail(ie, "turns gravity in the base frame: its location is 'base'");
        if (gravity_tilted_) Fail(ie, "is given twice");
        gravity_tilted_ = true;
        e.g_base = kinematics::TiltedGravity(e.g_base, v[0], v[1]);
        break;
      case K::kBaseCompliance: {
        const FrameId f = AnyFrame(ie, loc);
        if (f != e.mount) {
          Fail(ie, "names '" + loc + "', but the arm's mount is '" +
                       (e.mount > 0 ? model_.frame(e.mount).name : std::string("(none)")) + "'");
        }
        e.mount_compliance += Eigen::Vector2d(v[0], v[1]);
        break;
      }
      case K::kJointOffset:
        e.joints[JointIndex(ie, loc)].offset += v[0];
        break;
      case K::kJointOrigin: {
        const FrameId f = model_.joint_frame(JointIndex(ie, loc));
        for (int i = 0; i < 6; ++i) e.frames[f].origin[i] += v[i];
        break;
      }
      case K::kAxisTilt: {
        const FrameId f = model_.joint_frame(JointIndex(ie, loc));
        e.frames[f].tilt += v[0] * TiltAxis(model_.frame(f).joint.axis, p.axis);
        break;
      }
      case K::kJointCompliance:
        e.joints[RevoluteJoint(ie, loc)].compliance += v[0];
        break;
      case K::kBacklash:
        e.joints[RevoluteJoint(ie, loc)].backlash += v[0];
        break;
      case K::kStiffeningSpring: {
        ModelEffects::JointTerms& j = e.joints[RevoluteJoint(ie, loc)];
        j.compliance += v[0];
        j.cubic += v[1] / (kinematics::kStiffeningTau0Nm * kinematics::kStiffeningTau0Nm);
        break;
      }
      case K::kTransmissionError:
      case K::kJointErrorCurve: {
        ModelEffects::JointTerms& j = e.joints[RevoluteJoint(ie, loc)];
        for (size_t i = 0; i < v.size(); ++i) j.harmonic[i] += v[i];
        break;
      }
      case K::kLinkBending: {
        const FrameId f = model_.joint_frame(RevoluteJoint(ie, loc));
        SetBendingLink(ie, f);
        e.frames[f].bend += v[0];
        break;
      }
      case K::kLateralCompliance: {
        const FrameId f = model_.joint_frame(RevoluteJoint(ie, loc));
        ModelEffects::FrameTerms& t = e.frames[f];
        t.lateral += Eigen::Vector2d(v[0], v[1]);
        kinematics::TiltAxes(model_.frame(f).joint.axis, &t.lateral_a, &t.lateral_b);
        break;
      }
    }
  }

  // The effect's parameter stds (if given) as ModelEffects::Uncertainty: variances per term;
  // the geometric terms as a twist covariance at the frame's source, whose axes are the fixed
  // part's (a translation d in parent axes is R^T d there). A payload's or a gravity tilt's
  // uncertainty is not carried (it would act through every load-driven term at once).
  void AddVariance(const IdentifiedEffect& ie, const Parsed& p) {
    if (ie.std.empty()) return;
    const std::string& loc = p.loc;
    std::vector<double> v2(ie.std.size());
    for (size_t i = 0; i < v2.size(); ++i) v2[i] = ie.std[i] * ie.std[i];
    ModelEffects::Uncertainty& u = chain_->effects.uncertainty;
    const auto translation = [&](FrameId f, const Vec3& d_parent, double var) {
      const Vec3 d = model_.frame(f).T_parent_ip.rotation().transpose() * d_parent;
      u.frames[f].block<3, 3>(kTransIdx, kTransIdx) += var * d * d.transpose();
    };
    const auto joint = [&] { return JointIndex(ie, loc); };
    switch (p.row->kind) {
      case K::kThermalExpansion:
        u.thermal += v2[0];
        break;
      case K::kCameraOffset:
      case K::kJointOrigin: {
        const FrameId f = p.row->kind == K::kCameraOffset ? Frame(ie, "camera/" + loc, "camera")
                                                          : model_.joint_frame(joint());
        for (int k = 0; k < 6; ++k) u.frames[f](k, k) += v2[k];
        break;
      }
      case K::kLinkLength: {
        const FrameId f = AnyFrame(ie, loc);
        translation(f, model_.frame(f).T_parent_ip.translation().normalized(), v2[0]);
        break;
      }
      case K::kLinkOffset: {
        const FrameId f = AnyFrame(ie, loc);
        for (int k = 0; k < 3; ++k) translation(f, Vec3::Unit(k), v2[k]);
        break;
      }
      case K::kBaseCompliance:
        u.mount_compliance += Eigen::Vector2d(v2[0], v2[1]);
        break;
      case K::kPayload:
      case K::kGravityTilt:
        break;
      case K::kJointOffset:
        u.joints[joint()].offset += v2[0];
        break;
      case K::kAxisTilt: {
        const FrameId f = model_.joint_frame(joint());
        const Vec3 a = TiltAxis(model_.frame(f).joint.axis, p.axis);
        u.frames[f].block<3, 3>(kRotIdx, kRotIdx) += v2[0] * a * a.transpose();
        break;
      }
      case K::kJointCompliance:
        u.joints[joint()].compliance += v2[0];
        break;
      case K::kBacklash:
        u.joints[joint()].backlash += v2[0];
        break;
      case K::kStiffeningSpring: {
        ModelEffects::JointTerms& j = u.joints[joint()];
        j.compliance += v2[0];
        j.cubic += v2[1] / std::pow(kinematics::kStiffeningTau0Nm, 4);
        break;
      }
      case K::kTransmissionError:
      case K::kJointErrorCurve: {
        ModelEffects::JointTerms& j = u.joints[joint()];
        for (size_t i = 0; i < v2.size(); ++i) j.harmonic[i] += v2[i];
        break;
      }
      case K::kLinkBending:
        u.bend[model_.joint_frame(joint())] += v2[0];
        break;
      case K::kLateralCompliance:
        u.lateral[model_.joint_frame(joint())] += Eigen::Vector2d(v2[0], v2[1]);
        break;
    }
  }

  // The identification's tilt axes: a, the first of x, y not along the joint axis w, made
  // normal to w; b = w x a.
  static Vec3 TiltAxis(const Vec3& axis, int which) {
    Vec3 a, b;
    kinematics::TiltAxes(axis, &a, &b);
    return which == 0 ? a : b;
  }

  // The joint variable a joint effect names, which must be a revolute joint's.
  int RevoluteJoint(const IdentifiedEffect& ie, const std::string& loc) const {
    const int k = JointIndex(ie, loc);
    if (model_.frame(model_.joint_frame(k)).joint.type != kinematics::JointType::kRevolute) {
      Fail(ie, "needs a revolute joint; '" + loc + "' is not");
    }
    return k;
  }

  // What a dynamic effect does to a standing arm's poses (sim/dynamic_effects.h): a link's mode
  // bends the link under its load as a spring of the bending joints' stiffness, c = 1 / (scale
  // k), k their mean (the MJCF's pair of bending hinges is isotropic across the link); a payload
  // adds its mass at the body's centre of mass, where ApplyDynamic adds it. The rest (damping,
  // friction, armature, the servo's gain and delay) move nothing at given joint readings, and the
  // base plate's sway has no static form here yet. Returns whether the part acts through loads.
  bool AddStaticPartOf(const IdentifiedEffect& ie, const DeclaredDynamic& dd) {
    ModelEffects& e = chain_->effects;
    const DynamicKind kind = dd.row->kind;
    if (!catalog_)
      catalog_ = std::make_unique<ModelCatalog>(ModelCatalog::Build(m_, d_.model_path));
    // Read only: DynamicParts looks the location up.
    const TruthSetup setup = NominalSetup(const_cast<mjModel*>(m_), catalog_.get(), d_.model_path);
    const std::vector<int> parts = DynamicParts(setup, kind, dd.location);
    if (parts.empty()) {
      std::string known;
      for (const std::string& l : DynamicLocations(setup, kind)) {
        known += (known.empty() ? "" : ", ") + l;
      }
      Fail(ie, "names '" + CapForMessage(dd.location) + "', which " + d_.model_path + " has no " +
                   dd.row->name + " at (it has: " + (known.empty() ? "none" : known) + ")");
    }
    if (!HasStandingPart(kind)) return false;
    if (kind == DynamicKind::kPayloadMass) {
      const FrameId f = Frame(ie, "body/" + dd.location, "body");
      if (e.payload_frame >= 0 && e.payload_frame != f) Fail(ie, "a second payload frame");
      e.payload_frame = f;
      e.payload.mass += dd.values[0];
      e.payload.first_moment += dd.values[0] * Eigen::Map<const Vec3>(m_->body_ipos + 3 * parts[0]);
      return true;
    }
    double k = 0.0;
    for (int j : parts) k += m_->jnt_stiffness[j] / parts.size();
    if (!(k > 0.0)) Fail(ie, "bends joints without stiffness in the MJCF: no standing bend");
    const FrameId f = LinkEndBelow(ie, dd.location);
    if (f < 0) return false;
    SetBendingLink(ie, f);
    const double c = 1.0 / (dd.values[0] * k);
    e.frames[f].bend += c;
    if (dd.stds[0] > 0.0) {
      const double sc = c * dd.stds[0] / dd.values[0];  // |dc/ds| std(s)
      e.uncertainty.bend[f] += sc * sc;
    }
    return true;
  }

  // The frame a bending body's link ends at on the way to the end effector: the next joint's
  // frame below the body, else (the last link) the frame right below it (a body, or the end
  // effector's site). -1 when the body is off that way: its bend moves no frame the estimators
  // report.
  FrameId LinkEndBelow(const IdentifiedEffect& ie, const std::string& body) const {
    const FrameId b = Frame(ie, "body/" + body, "body");
    FrameId joint = -1, below = -1;
    for (FrameId f = chain_->end_effector; f > 0; f = model_.frame(f).parent) {
      if (f == b) return joint >= 0 ? joint : below;
      if (model_.frame(f).q_index >= 0) joint = f;
      below = f;
    }
    return -1;
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
  std::unique_ptr<ModelCatalog> catalog_;  // built for the first dynamic entry
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
