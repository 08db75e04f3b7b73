#include "scenarios/identify/effect_model.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <memory>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/model_effects.h"
#include "estimators/lie/se3.h"
#include "estimators/lie/sincos.h"
#include "estimators/lie/so3.h"

// Each row of the effect table has its case in the switches without a default below (the fit's
// terms and tangents): a kind without one fails to build.
#pragma GCC diagnostic error "-Wswitch"

namespace flexbench::identify {
namespace {

// "joint/j2" -> "j2".
std::string Untyped(const std::string& name) {
  const size_t slash = name.find('/');
  return slash == std::string::npos ? name : name.substr(slash + 1);
}

int BodyOfFrame(const mjModel* m, const std::string& typed) {
  const size_t slash = typed.find('/');
  if (slash == std::string::npos) return -1;
  const std::string type = typed.substr(0, slash);
  const std::string name = typed.substr(slash + 1);
  if (type == "joint") {
    const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    return j < 0 ? -1 : m->jnt_bodyid[j];
  }
  if (type == "body") return mj_name2id(m, mjOBJ_BODY, name.c_str());
  if (type == "site") {
    const int s = mj_name2id(m, mjOBJ_SITE, name.c_str());
    return s < 0 ? -1 : m->site_bodyid[s];
  }
  if (type == "geom") {
    const int g = mj_name2id(m, mjOBJ_GEOM, name.c_str());
    return g < 0 ? -1 : m->geom_bodyid[g];
  }
  if (type == "camera") {
    const int c = mj_name2id(m, mjOBJ_CAMERA, name.c_str());
    return c < 0 ? -1 : m->cam_bodyid[c];
  }
  return -1;
}

// The table's unit and physical bounds of the candidate's values (at a prismatic joint its
// row's slide unit and bound, where it has them).
void SetUnitAndBounds(Candidate* c, bool prismatic) {
  const kinematics::EffectRow& row = kinematics::Row(c->type);
  if (prismatic && row.slide_unit != nullptr) {
    c->unit = row.slide_unit;
    c->lower.assign(c->num_params, -row.slide_bound);
    c->upper.assign(c->num_params, row.slide_bound);
    return;
  }
  c->unit = row.unit;
  c->lower.assign(row.lower.begin(), row.lower.begin() + c->num_params);
  c->upper.assign(row.upper.begin(), row.upper.begin() + c->num_params);
}

// A periodic joint error (transmission error, error curve) at joint angle qj, harmonic by
// harmonic onto *dq: sum_h a_h cos(h qj) + b_h sin(h qj).
void AddPeriodicError(const Candidate& c, double qj, const double* t, double* dq) {
  for (int h = 1; 2 * h <= c.num_params; ++h) {
    *dq += t[2 * h - 2] * std::cos(h * qj) + t[2 * h - 1] * std::sin(h * qj);
  }
}

}  // namespace

const char* ToString(EffectType type) { return kinematics::Row(type).name; }

EffectModel::EffectModel(const mjModel* m, const sim::DeclaredChain& chain, FrameId point_frame,
                         const std::string& camera, const std::vector<FrameId>& more_points,
                         bool gravity_tilt)
    : chain_(&chain), point_frame_(point_frame), m_(m) {
  const kinematics::PpoeModel& model = chain.model;
  const int n = model.num_frames();
  SetPoints(more_points);
  frame_body_.assign(n, -1);
  for (FrameId f = 1; f < n; ++f) frame_body_[f] = BodyOfFrame(m, model.frame(f).name);
  FindMount();
  // Below 10 g the model carries no real masses (e.g. a URDF without inertials, where MuJoCo
  // keeps a minimal mass): loads are then zero and the load-driven effects unidentifiable.
  const FrameId first_joint = FirstJointOnPath();
  has_masses_ = first_joint > 0 && frame_body_[first_joint] >= 0 &&
                m->body_subtreemass[frame_body_[first_joint]] > 0.01;
  SetTiltAxes();
  AddJointFamilies();
  AddLinkLengths();
  AddLinkBending();
  AddToolOffsets();
  AddChainWide(camera);
  AddLateralCompliance();
  AddEvidenceFamilies();
  AddJointOrigins();
  FindCoupledDrivers();
  {
    const sim::MjDataPtr d = sim::MakeData(m);
    mj_kinematics(m, d.get());
    const Eigen::Map<const Eigen::Matrix<mjtNum, 3, 3, Eigen::RowMajor>> R_w_base(
        d->xmat + 9 * chain.base_body);
    g_base_ = R_w_base.transpose() * Vec3(m->opt.gravity[0], m->opt.gravity[1], m->opt.gravity[2]);
  }
  if (gravity_tilt) {
    AddCandidate(EffectType::kGravityTilt, "base", -1, -1);
    gravity_tilt_ = static_cast<int>(candidates_.size()) - 1;
  }
}

void EffectModel::SetPoints(const std::vector<FrameId>& more_points) {
  const kinematics::PpoeModel& model = chain_->model;
  const int n = model.num_frames();
  points_ = {point_frame_};
  for (FrameId p : more_points) {
    if (std::find(points_.begin(), points_.end(), p) == points_.end()) points_.push_back(p);
  }
  on_path_.assign(n, 0);
  for (FrameId point : points_) {
    if (point < 0 || point >= n) {
      throw InputError("identify: point frame " + std::to_string(point) + " not in '" +
                       model.name() + "'");
    }
    for (FrameId f = point; f >= 0; f = model.frame(f).parent) {
      on_path_[f] = 1;
      if (f == kinematics::kBaseFrame) break;
    }
  }
}

FrameId EffectModel::FirstJointOnPath() const {
  const kinematics::PpoeModel& model = chain_->model;
  for (FrameId f = 1; f < model.num_frames(); ++f) {
    if (on_path_[f] && model.frame(f).q_index >= 0) return f;
  }
  return -1;
}

bool EffectModel::AboveEveryPoint(FrameId f) const {
  for (FrameId p : points_) {
    FrameId a = p;
    while (a > 0 && a != f) a = chain_->model.frame(a).parent;
    if (a != f) return false;
  }
  return true;
}

// The arm's mount, where a compliant base tilts: the first frame with a declared source ahead of
// the first joint (the declared model says the base is uncertain there), else the first joint's
// anchor (frame axes before the joint turns). On a tree with several measured points the mount
// carries them all: a frame above every point (one hand's shoulder is no mount of the
// other hand; two arms on a fixed torso have none).
void EffectModel::FindMount() {
  const kinematics::PpoeModel& model = chain_->model;
  const int n = model.num_frames();
  FrameId mount_joint = -1;
  for (FrameId f = 1; f < n; ++f) {
    if (on_path_[f] && model.frame(f).q_index >= 0 && AboveEveryPoint(f)) {
      mount_joint = f;
      break;
    }
  }
  mount_ = mount_joint > 0 ? mount_joint : kinematics::kBaseFrame;
  for (FrameId f = 1; f < (mount_joint > 0 ? mount_joint : n); ++f) {
    if (on_path_[f] && model.frame(f).has_source && AboveEveryPoint(f)) {
      mount_ = f;
      break;
    }
  }
}

void EffectModel::SetTiltAxes() {
  const kinematics::PpoeModel& model = chain_->model;
  const int n = model.num_frames();
  tilt_a_.assign(n, Vec3::Zero());
  tilt_b_.assign(n, Vec3::Zero());
  for (FrameId f = 1; f < n; ++f) {
    const kinematics::PpoeFrame& fr = model.frame(f);
    if (fr.q_index < 0) continue;
    kinematics::TiltAxes(fr.joint.axis, &tilt_a_[f], &tilt_b_[f]);
  }
}

Candidate& EffectModel::AddCandidate(EffectType type, const std::string& location, int q,
                                     FrameId f) {
  const kinematics::PpoeModel& model = chain_->model;
  const kinematics::EffectRow& row = kinematics::Row(type);
  const bool prismatic = model.frame(f > 0 ? f : 0).joint.type == kinematics::JointType::kPrismatic;
  Candidate c;
  c.type = type;
  c.location = location;
  c.q_index = q;
  c.frame = f;
  c.num_params = row.num_values;
  c.step = row.fd_step;
  SetUnitAndBounds(&c, prismatic);
  candidates_.push_back(c);
  return candidates_.back();
}

void EffectModel::AddJointFamilies() {
  const kinematics::PpoeModel& model = chain_->model;
  for (int k = 0; k < model.nq(); ++k) {
    const FrameId f = model.joint_frame(k);
    if (!on_path_[f]) continue;
    const std::string& name = chain_->q_joints[k];
    AddCandidate(EffectType::kJointOffset, name, k, f);
    AddCandidate(EffectType::kAxisTilt, name, k, f);
    AddCandidate(EffectType::kAxisTilt, name, k, f).axis = 1;
    AddCandidate(EffectType::kLinkOffset, name, k, f);
    if (model.frame(f).joint.type != kinematics::JointType::kRevolute) continue;
    AddCandidate(EffectType::kJointCompliance, name, k, f);
    AddCandidate(EffectType::kBacklash, name, k, f);
  }
}

void EffectModel::AddLinkLengths() {
  const kinematics::PpoeModel& model = chain_->model;
  for (FrameId f = 1; f < model.num_frames(); ++f) {
    if (!on_path_[f] || model.frame(f).T_parent_ip.translation().norm() < 0.01) continue;
    const std::string name = Untyped(model.frame(f).name);
    AddCandidate(EffectType::kLinkLength, name, -1, f);
  }
}

// Links between consecutive joints (passive frames in between belong to the link).
void EffectModel::AddLinkBending() {
  const kinematics::PpoeModel& model = chain_->model;
  const int n = model.num_frames();
  prev_joint_.assign(n, -1);
  mid_slot_.assign(n, -1);
  kinematics::PpoeData pd(model);
  kinematics::ForwardKinematics(model, pd, Eigen::VectorXd::Zero(model.nq()));
  for (FrameId f = 1; f < n; ++f) {
    if (!on_path_[f] || model.frame(f).q_index < 0) continue;
    FrameId p = model.frame(f).parent;
    while (p > 0 && model.frame(p).q_index < 0) p = model.frame(p).parent;
    if (p <= 0) continue;
    const lie::SE3 T_pre = pd.T_base_frame[model.frame(f).parent] * model.frame(f).T_parent_ip;
    const Vec3 link_p = pd.T_base_frame[p].rotation().transpose() *
                        (T_pre.translation() - pd.T_base_frame[p].translation());
    if (link_p.norm() < 0.05) continue;
    prev_joint_[f] = p;
    mid_slot_[f] = num_mid_++;
    link_dir_.resize(n, Vec3::Zero());
    link_dir_[f] = link_p.normalized();
    AddCandidate(EffectType::kLinkBending, chain_->q_joints[model.frame(f).q_index], -1, f);
  }
}

// The tool: where the measured point sits on the last link (a probe, a ball, a fingertip), unless
// the point frame is a joint frame, which has its link_offset already.
void EffectModel::AddToolOffsets() {
  const kinematics::PpoeModel& model = chain_->model;
  for (FrameId point : points_) {
    if (model.frame(point).q_index < 0)
      AddCandidate(EffectType::kLinkOffset, Untyped(model.frame(point).name), -1, point);
  }
}

// The mount's compliance and the families that act on the whole chain.
void EffectModel::AddChainWide(const std::string& camera) {
  const kinematics::PpoeModel& model = chain_->model;
  if (mount_ != kinematics::kBaseFrame) {
    AddCandidate(EffectType::kBaseCompliance, Untyped(model.frame(mount_).name), -1, mount_);
  }
  AddCandidate(EffectType::kThermalExpansion, "all", -1, -1);
  if (!camera.empty()) AddCandidate(EffectType::kCameraOffset, camera, -1, -1);
  AddCandidate(EffectType::kPayload, Untyped(model.frame(point_frame_).name), -1, point_frame_);
}

// Bearing and housing compliance at each revolute joint; after the families that came before it,
// so those keep their indices.
void EffectModel::AddLateralCompliance() {
  const kinematics::PpoeModel& model = chain_->model;
  for (int k = 0; k < model.nq(); ++k) {
    const FrameId f = model.joint_frame(k);
    if (!on_path_[f] || model.frame(f).joint.type != kinematics::JointType::kRevolute) continue;
    const std::string& name = chain_->q_joints[k];
    const std::string candidate =
        std::string(ToString(EffectType::kLateralCompliance)) + "@" + name;
    if (chain_->IsCoupled(k)) {
      skipped_.push_back({candidate, "'" + name +
                                         "' is a coupled joint: its angle follows a linkage, which "
                                         "has no bearing of its own to bend (lateral compliance of "
                                         "its drivers is offered)"});
      continue;
    }
    if (TiltsWithMount(f)) {
      skipped_.push_back(
          {candidate,
           "'" + name + "' is the first joint on the arm's mount: its housing tilting is " +
               "the mount tilting, base_compliance@" + Untyped(model.frame(mount_).name)});
      continue;
    }
    AddCandidate(EffectType::kLateralCompliance, name, k, f).after_named = true;
  }
}

bool EffectModel::TiltsWithMount(FrameId f) const {
  if (mount_ == kinematics::kBaseFrame) return false;
  const kinematics::PpoeModel& model = chain_->model;
  FrameId g = f;
  while (g > mount_ && (g == f || model.frame(g).q_index < 0)) g = model.frame(g).parent;
  return g == mount_ && (g == f || model.frame(g).q_index < 0);
}

// Families that enter only when the residual diagnostics point at their joint; after the others,
// so those keep their indices.
void EffectModel::AddEvidenceFamilies() {
  const kinematics::PpoeModel& model = chain_->model;
  for (int k = 0; k < model.nq(); ++k) {
    const FrameId f = model.joint_frame(k);
    if (!on_path_[f] || model.frame(f).joint.type != kinematics::JointType::kRevolute) continue;
    const std::string& name = chain_->q_joints[k];
    AddCandidate(EffectType::kTransmissionError, name, k, f).needs_evidence = true;
    AddCandidate(EffectType::kJointErrorCurve, name, k, f).needs_evidence = true;
    AddCandidate(EffectType::kStiffeningSpring, name, k, f).needs_evidence = true;
  }
}

// Complete geometry last, so the named candidates keep their indices.
void EffectModel::AddJointOrigins() {
  const kinematics::PpoeModel& model = chain_->model;
  for (int k = 0; k < model.nq(); ++k) {
    const FrameId f = model.joint_frame(k);
    if (!on_path_[f]) continue;
    AddCandidate(EffectType::kJointOrigin, chain_->q_joints[k], k, f).generic_geometry = true;
  }
}

// Joint variables that drive a coupled joint, directly or through another.
void EffectModel::FindCoupledDrivers() {
  drives_coupled_.assign(chain_->model.nq(), 0);
  for (bool grew = true; grew;) {
    grew = false;
    for (const sim::DeclaredChain::Coupling& cp : chain_->couplings) {
      std::vector<int> drivers;
      for (const auto& [k, coef] : cp.linear) drivers.push_back(k);
      if (cp.poly_driver >= 0) drivers.push_back(cp.poly_driver);
      for (int k : drivers) {
        if (!drives_coupled_[k]) drives_coupled_[k] = 1, grew = true;
      }
    }
  }
}

template <typename F>
void EffectModel::ForEachEffect(const std::vector<int>& active, const double* theta, F&& f) const {
  const double* t = base_theta_.data();
  for (int i : base_) {
    f(i, t);
    t += candidates_[i].num_params;
  }
  t = theta;
  for (int i : active) {
    f(i, t);
    if (t != nullptr) t += candidates_[i].num_params;
  }
}

std::vector<std::string> EffectModel::SetBaseEffects(
    const std::vector<sim::IdentifiedEffect>& effects) {
  base_.clear();
  std::vector<double> theta;
  std::vector<std::string> not_here;
  for (const sim::IdentifiedEffect& e : effects) {
    const int c = FindCandidate(e.effect);
    if (c < 0) {
      not_here.push_back(e.effect);
      continue;
    }
    if (static_cast<int>(e.value.size()) != candidates_[c].num_params) {
      throw InputError(e.where + ": identified_effects: '" + e.effect + "' needs " +
                       std::to_string(candidates_[c].num_params) + " values");
    }
    base_.push_back(c);
    theta.insert(theta.end(), e.value.begin(), e.value.end());
  }
  base_theta_ = Eigen::Map<const Eigen::VectorXd>(theta.data(), theta.size());
  return not_here;
}

int EffectModel::FindCandidate(const std::string& name) const {
  for (size_t i = 0; i < candidates_.size(); ++i) {
    if (candidates_[i].Name() == name) return static_cast<int>(i);
  }
  return -1;
}

ConfigLoads EffectModel::Loads(const Eigen::VectorXd& q) const { return LoadsFor(q, {}, nullptr); }

Eigen::VectorXd EffectModel::ReadingShift(const Eigen::VectorXd& q, const std::vector<int>& active,
                                          const double* theta) const {
  Eigen::VectorXd dq = Eigen::VectorXd::Zero(q.size());
  ForEachEffect(active, theta, [&](int i, const double* t) {
    const Candidate& c = candidates_[i];
    if (c.type == EffectType::kJointOffset) dq[c.q_index] += t[0];
    if (c.type == EffectType::kTransmissionError || c.type == EffectType::kJointErrorCurve) {
      AddPeriodicError(c, q[c.q_index], t, &dq[c.q_index]);
    }
  });
  if (!chain_->couplings.empty()) chain_->PropagateShift(q, &dq);
  return dq;
}

bool EffectModel::LoadsShift(const std::vector<int>& active) const {
  if (!has_masses_) return false;
  bool shift = false, loaded = false;
  for (const std::vector<int>* list : {&base_, &active}) {
    for (int i : *list) {
      switch (candidates_[i].type) {
        case EffectType::kJointOffset:
        case EffectType::kTransmissionError:
        case EffectType::kJointErrorCurve:
          shift = true;
          break;
        case EffectType::kJointCompliance:
        case EffectType::kBacklash:
        case EffectType::kLinkBending:
        case EffectType::kBaseCompliance:
        case EffectType::kStiffeningSpring:
        case EffectType::kPayload:
        case EffectType::kLateralCompliance:
          loaded = true;
          break;
        default:
          break;
      }
    }
  }
  return shift && loaded;
}

ConfigLoads EffectModel::LoadsFor(const Eigen::VectorXd& q, const std::vector<int>& active,
                                  const double* theta) const {
  if (!LoadsShift(active)) return Loads(q, q);
  return Loads(q, q + ReadingShift(q, active, theta));
}

// The arm standing at q_load: its PPOE poses and MuJoCo's (d_), the base's pose in MuJoCo's
// world, gravity in base coordinates and the end effector's position.
struct EffectModel::LoadPose {
  explicit LoadPose(const kinematics::PpoeModel& model) : pd(model) {}
  kinematics::PpoeData pd;
  const mjData* d = nullptr;
  Mat3 R_w_base;
  Vec3 p_w_base, g_base, p_ee;
};

void EffectModel::InitLoads(const Eigen::VectorXd& q, bool nominal_poses, ConfigLoads* L) const {
  const kinematics::PpoeModel& model = chain_->model;
  const int n = model.num_frames();
  L->tau = Eigen::VectorXd::Zero(model.nq());
  L->tau_unit = Eigen::VectorXd::Zero(model.nq());
  L->M_lat = Eigen::Matrix2Xd::Zero(2, model.nq());
  L->M_lat_unit = Eigen::Matrix2Xd::Zero(2, model.nq());
  L->lat_a_base = Eigen::Matrix3Xd::Zero(3, model.nq());
  L->lat_b_base = Eigen::Matrix3Xd::Zero(3, model.nq());
  L->M_mid.assign(num_mid_, Vec3::Zero());
  L->M_mid_unit.assign(num_mid_, Vec3::Zero());
  L->axis_base = Eigen::Matrix3Xd::Zero(3, model.nq());
  L->R_mid_T.assign(num_mid_, Mat3::Identity());
  if (!nominal_poses) {
    L->q_nominal.resize(0);
    L->T_nominal.clear();
    return;
  }
  // PredictPose's untouched-frame form with every dq zero (q + 0.0 as there, same bits).
  L->q_nominal = q;
  L->T_nominal.assign(n, lie::SE3());
  for (FrameId f = 1; f < n; ++f) {
    if (!on_path_[f]) continue;
    const kinematics::PpoeFrame& fr = model.frame(f);
    const double qf = fr.q_index >= 0 ? q[fr.q_index] + 0.0 : 0.0;
    L->T_nominal[f] = L->T_nominal[fr.parent] * fr.FixedTimesMotion(qf);
  }
}

void EffectModel::StandAt(const Eigen::VectorXd& q_load, mjData* d, LoadPose* P) const {
  kinematics::ForwardKinematics(chain_->model, P->pd, q_load);
  mju_copy(d->qpos, m_->qpos0, m_->nq);
  chain_->WriteQpos(q_load, d->qpos);
  mj_kinematics(m_, d);
  mj_comPos(m_, d);
  P->d = d;
  const int base = chain_->base_body;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) P->R_w_base(r, c) = d->xmat[9 * base + 3 * r + c];
  }
  P->p_w_base = Vec3(d->xpos[3 * base], d->xpos[3 * base + 1], d->xpos[3 * base + 2]);
  P->g_base =
      P->R_w_base.transpose() * Vec3(m_->opt.gravity[0], m_->opt.gravity[1], m_->opt.gravity[2]);
  P->p_ee = P->pd.T_base_frame[point_frame_].translation();
}

Vec3 EffectModel::SubtreeCom(const LoadPose& P, int b) const {
  const mjData* d = P.d;
  return P.R_w_base.transpose() *
         (Vec3(d->subtree_com[3 * b], d->subtree_com[3 * b + 1], d->subtree_com[3 * b + 2]) -
          P.p_w_base);
}

Vec3 EffectModel::SubtreeMoment(const LoadPose& P, int b, const Vec3& a, const Vec3& g) const {
  const Vec3 c = SubtreeCom(P, b);
  return Vec3((c - a).cross(m_->body_subtreemass[b] * g));
}

namespace {

// The moment about `a` (base coordinates) of 1 kg at p_ee under gravity g.
inline Vec3 UnitMoment(const Vec3& p_ee, const Vec3& a, const Vec3& g) {
  return Vec3((p_ee - a).cross(g));
}

}  // namespace

void EffectModel::JointTorques(const LoadPose& P, const Vec3& g, GravityTerms* t,
                               ConfigLoads* L) const {
  const kinematics::PpoeModel& model = chain_->model;
  for (int k = 0; k < model.nq(); ++k) {
    const FrameId f = model.joint_frame(k);
    if (!on_path_[f] || frame_body_[f] < 0) continue;
    const kinematics::PpoeFrame& fr = model.frame(f);
    const lie::SE3& T = P.pd.T_base_frame[f];
    const Vec3 axis = T.rotation() * fr.joint.axis;
    const Vec3 a = T * fr.joint.point;
    // The torque the joint must hold against gravity (MuJoCo's qfrc_bias at rest).
    const Vec3 M = SubtreeMoment(P, frame_body_[f], a, g);
    const Vec3 M_unit = UnitMoment(P.p_ee, a, g);
    t->tau[k] = -axis.dot(M);
    L->axis_base.col(k) = axis;
    t->tau_unit[k] = -axis.dot(M_unit);
    // The same moment about the lateral axes, which turn with the frame before the joint moves.
    const Mat3 R_pre = P.pd.T_base_frame[fr.parent].rotation() * fr.T_parent_ip.rotation();
    const Vec3 lat_a = R_pre * tilt_a_[f], lat_b = R_pre * tilt_b_[f];
    L->lat_a_base.col(k) = lat_a;
    L->lat_b_base.col(k) = lat_b;
    t->M_lat.col(k) = Eigen::Vector2d(lat_a.dot(M), lat_b.dot(M));
    t->M_lat_unit.col(k) = Eigen::Vector2d(lat_a.dot(M_unit), lat_b.dot(M_unit));
  }
}

void EffectModel::MidMoments(const LoadPose& P, const Vec3& g, GravityTerms* t,
                             ConfigLoads* L) const {
  const kinematics::PpoeModel& model = chain_->model;
  for (FrameId f = 1; f < model.num_frames(); ++f) {
    const FrameId p = prev_joint_[f];
    if (p < 0 || frame_body_[p] < 0) continue;
    const kinematics::PpoeFrame& fr = model.frame(f);
    const lie::SE3 T_pre = P.pd.T_base_frame[fr.parent] * fr.T_parent_ip;
    const lie::SE3& Tp = P.pd.T_base_frame[p];
    const Vec3 mid = 0.5 * (Tp.translation() + T_pre.translation());
    // The whole link's subtree about its middle (the near half's own weight barely counts).
    const int slot = mid_slot_[f];
    t->M_mid[slot] = Tp.rotation().transpose() * SubtreeMoment(P, frame_body_[p], mid, g);
    t->M_mid_unit[slot] = Tp.rotation().transpose() * UnitMoment(P.p_ee, mid, g);
    L->R_mid_T[slot] = Tp.rotation().transpose();
  }
}

void EffectModel::MountLoads(const LoadPose& P, const Vec3& g, GravityTerms* t,
                             ConfigLoads* L) const {
  if (mount_ == kinematics::kBaseFrame || frame_body_[mount_] < 0) return;
  const kinematics::PpoeFrame& fr = chain_->model.frame(mount_);
  const lie::SE3 T_pre = P.pd.T_base_frame[fr.parent] * fr.T_parent_ip;
  t->M_mount =
      T_pre.rotation().transpose() * SubtreeMoment(P, frame_body_[mount_], T_pre.translation(), g);
  t->M_mount_unit = T_pre.rotation().transpose() * UnitMoment(P.p_ee, T_pre.translation(), g);
  L->R_mount_T = T_pre.rotation().transpose();
  const int b = frame_body_[mount_];
  const Vec3 c = SubtreeCom(P, b);
  L->s_mount = L->R_mount_T * (m_->body_subtreemass[b] * (c - T_pre.translation()));
  L->s_mount_unit = L->R_mount_T * (P.p_ee - T_pre.translation());
  L->R_mount_point = L->R_mount_T * P.pd.T_base_frame[point_frame_].rotation();
  t->g_mount = L->R_mount_T * g;
}

void EffectModel::GravityLoads(const LoadPose& P, const Vec3& g, GravityTerms* t,
                               ConfigLoads* L) const {
  const int nq = chain_->model.nq();
  t->tau = Eigen::VectorXd::Zero(nq);
  t->tau_unit = Eigen::VectorXd::Zero(nq);
  t->M_lat = Eigen::Matrix2Xd::Zero(2, nq);
  t->M_lat_unit = Eigen::Matrix2Xd::Zero(2, nq);
  t->M_mid.assign(num_mid_, Vec3::Zero());
  t->M_mid_unit.assign(num_mid_, Vec3::Zero());
  JointTorques(P, g, t, L);
  MidMoments(P, g, t, L);
  MountLoads(P, g, t, L);
  // (R_ee s) x g = -[g]x R_ee s.
  t->M_first = -lie::Skew(g) * P.pd.T_base_frame[point_frame_].rotation();
}

struct EffectModel::LoadScratch {
  explicit LoadScratch(const kinematics::PpoeModel& model) : P(model) {}
  LoadPose P;
  GravityTerms t;
  sim::MjDataPtr d;
};

void EffectModel::FillLoads(const Eigen::VectorXd& q, const Eigen::VectorXd& q_load,
                            bool nominal_poses, LoadScratch* s, ConfigLoads* L) const {
  InitLoads(q, nominal_poses, L);
  if (!has_masses_) return;
  if (!s->d) s->d = sim::MakeData(m_);
  LoadPose& P = s->P;
  StandAt(q_load, s->d.get(), &P);
  GravityTerms& t = s->t;
  GravityLoads(P, P.g_base, &t, L);
  // Swapped, not moved: the zeroed buffers go to the scratch for the next call.
  L->tau.swap(t.tau);
  L->tau_unit.swap(t.tau_unit);
  L->M_lat.swap(t.M_lat);
  L->M_lat_unit.swap(t.M_lat_unit);
  L->M_mid.swap(t.M_mid);
  L->M_mid_unit.swap(t.M_mid_unit);
  L->M_mount = t.M_mount;
  L->M_mount_unit = t.M_mount_unit;
  L->g_mount = t.g_mount;
  L->M_first = t.M_first;
  if (gravity_tilt_ >= 0) {
    Vec3 a1, a2;
    kinematics::GravityTiltAxes(P.g_base, &a1, &a2);
    L->horizontal.resize(2);
    GravityLoads(P, a1.cross(P.g_base), &L->horizontal[0], L);
    GravityLoads(P, a2.cross(P.g_base), &L->horizontal[1], L);
  }
}

ConfigLoads EffectModel::Loads(const Eigen::VectorXd& q, const Eigen::VectorXd& q_load) const {
  ConfigLoads L;
  LoadScratch s(chain_->model);
  s.d = std::move(d_);
  FillLoads(q, q_load, true, &s, &L);
  d_ = std::move(s.d);
  return L;
}

EffectModel::LoadScratch* EffectModel::ScratchOf(Workspace& ws) const {
  if (!ws.load_scratch) {
    ws.load_scratch = std::unique_ptr<LoadScratch, void (*)(LoadScratch*)>(
        new LoadScratch(chain_->model), [](LoadScratch* p) { delete p; });
  }
  return ws.load_scratch.get();
}

ConfigLoads& EffectModel::LoadsFor(const Eigen::VectorXd& q, const std::vector<int>& active,
                                   const double* theta, Workspace& ws) const {
  LoadScratch* s = ScratchOf(ws);
  if (!LoadsShift(active)) {
    FillLoads(q, q, false, s, &ws.row_loads);
  } else {
    FillLoads(q, q + ReadingShift(q, active, theta), false, s, &ws.row_loads);
  }
  return ws.row_loads;
}

const ConfigLoads& EffectModel::TiltedLoads(const ConfigLoads& L, const std::vector<int>& active,
                                            const double* theta, Workspace& ws) const {
  if (L.horizontal.size() != 2) return L;
  bool tilted = false;
  Eigen::Vector2d phi = Eigen::Vector2d::Zero();
  ForEachEffect(active, theta, [&](int i, const double* t) {
    if (i == gravity_tilt_) {
      phi += Eigen::Vector2d(t[0], t[1]);
      tilted = true;
    }
  });
  if (!tilted) return L;
  const Vec3 w = kinematics::GravityTiltWeights(phi[0], phi[1]);
  const GravityTerms& h1 = L.horizontal[0];
  const GravityTerms& h2 = L.horizontal[1];
  ConfigLoads& T = ws.tilted;
  T.tau = w[0] * L.tau + w[1] * h1.tau + w[2] * h2.tau;
  T.tau_unit = w[0] * L.tau_unit + w[1] * h1.tau_unit + w[2] * h2.tau_unit;
  T.M_lat = w[0] * L.M_lat + w[1] * h1.M_lat + w[2] * h2.M_lat;
  T.M_lat_unit = w[0] * L.M_lat_unit + w[1] * h1.M_lat_unit + w[2] * h2.M_lat_unit;
  T.M_mid.resize(L.M_mid.size());
  T.M_mid_unit.resize(L.M_mid_unit.size());
  for (size_t f = 0; f < L.M_mid.size(); ++f) {
    T.M_mid[f] = w[0] * L.M_mid[f] + w[1] * h1.M_mid[f] + w[2] * h2.M_mid[f];
    T.M_mid_unit[f] = w[0] * L.M_mid_unit[f] + w[1] * h1.M_mid_unit[f] + w[2] * h2.M_mid_unit[f];
  }
  T.M_mount = w[0] * L.M_mount + w[1] * h1.M_mount + w[2] * h2.M_mount;
  T.M_mount_unit = w[0] * L.M_mount_unit + w[1] * h1.M_mount_unit + w[2] * h2.M_mount_unit;
  T.g_mount = w[0] * L.g_mount + w[1] * h1.g_mount + w[2] * h2.g_mount;
  T.M_first = w[0] * L.M_first + w[1] * h1.M_first + w[2] * h2.M_first;
  // The geometry stays.
  T.axis_base = L.axis_base;
  T.lat_a_base = L.lat_a_base;
  T.lat_b_base = L.lat_b_base;
  T.R_mid_T = L.R_mid_T;
  T.R_mount_T = L.R_mount_T;
  T.s_mount = L.s_mount;
  T.s_mount_unit = L.s_mount_unit;
  T.R_mount_point = L.R_mount_point;
  T.motion_sign = L.motion_sign;
  return T;
}

EffectModel::Workspace EffectModel::MakeWorkspace() const {
  const kinematics::PpoeModel& model = chain_->model;
  Workspace ws;
  ws.dq = Eigen::VectorXd::Zero(model.nq());
  ws.dlen.assign(model.num_frames(), 0.0);
  ws.bend.assign(model.num_frames(), Vec3::Zero());
  ws.offset.assign(model.num_frames(), Vec3::Zero());
  ws.tilt.assign(model.num_frames(), Vec3::Zero());
  ws.origin.assign(model.num_frames(), Vec6::Zero());
  ws.T.assign(model.num_frames(), lie::SE3());
  ws.y.assign(model.num_frames(), Vec3::Zero());
  ws.touched.assign(model.num_frames(), 0);
  ws.stages.resize(model.num_frames());
  return ws;
}

lie::SE3 EffectModel::PredictPose(const Eigen::VectorXd& q, const ConfigLoads& L,
                                  const std::vector<int>& active, const double* theta,
                                  Workspace& ws, int point) const {
  AccumulateTerms(q, TiltedLoads(L, active, theta, ws), active, theta, ws);
  ChainPoses(q, L, ws);
  ClearTerms(active, ws);
  return ws.T[points_[point]];
}

namespace {

// The load a load-driven effect at joint k answers to: tau_J with the payload's share (its mass
// `payload`, its couple in base axes).
inline double JointLoadOf(const ConfigLoads& L, int k, double payload, const Vec3& couple) {
  return L.tau[k] + payload * L.tau_unit[k] - L.axis_base.col(k).dot(couple);
}

// The backlash's flank: the last motion's direction where the data records it, else the one the
// gravity load `tau` presses on (below a millinewton-metre it picks none).
inline double Flank(const ConfigLoads& L, int k, double tau) {
  const double motion = L.motion_sign.size() ? L.motion_sign[k] : 0.0;
  return motion != 0.0 ? motion : tau > 1e-3 ? 1.0 : tau < -1e-3 ? -1.0 : 0.0;
}

// The moment about joint k's lateral axes (M_a, M_b) with the payload's share (its mass
// `payload`, its couple in base axes).
inline Eigen::Vector2d LateralLoadOf(const ConfigLoads& L, int k, double payload,
                                     const Vec3& couple) {
  return L.M_lat.col(k) + payload * L.M_lat_unit.col(k) +
         Eigen::Vector2d(L.lat_a_base.col(k).dot(couple), L.lat_b_base.col(k).dot(couple));
}

// The stiffening spring's reference torque tau0 [N m].

// The moment at a link's middle (start joint axes; `slot`: the link's entry in the loads) with
// the payload's share.
inline Vec3 MidMoment(const ConfigLoads& L, int slot, double payload, const Vec3& couple) {
  return L.M_mid[slot] + payload * L.M_mid_unit[slot] + L.R_mid_T[slot] * couple;
}

// The part of moment M across the link direction `dir` (the part that bends it).
inline Vec3 Across(const Vec3& M, const Vec3& dir) { return M - M.dot(dir) * dir; }

// The joint-level correction of a load-driven joint effect (compliance, backlash, stiffening
// spring) at load tau, onto the joint's dq.
inline void AddLoadDriven(const Candidate& c, const ConfigLoads& L, double tau, const double* t,
                          double* dq) {
  switch (c.type) {
    case EffectType::kJointCompliance:
      *dq += t[0] * tau;
      break;
    case EffectType::kBacklash:
      *dq += t[0] * Flank(L, c.q_index, tau);
      break;
    case EffectType::kStiffeningSpring:
      *dq += t[0] * tau + t[1] * tau * tau * tau /
                              (kinematics::kStiffeningTau0Nm * kinematics::kStiffeningTau0Nm);
      break;
    default:
      break;
  }
}

}  // namespace

Vec3 EffectModel::LateralTurn(const ConfigLoads& L, int k, FrameId f, const double* kappa,
                              double payload, const Vec3& couple) const {
  const Eigen::Vector2d M = LateralLoadOf(L, k, payload, couple);
  return kappa[0] * M.x() * tilt_a_[f] + kappa[1] * M.y() * tilt_b_[f];
}

// The chain-wide terms of AccumulateTerms while the effects add up.
struct EffectModel::ChainTerms {
  double payload = 0.0;
  Vec3 couple = Vec3::Zero();         // base axes
  Vec3 payload_first = Vec3::Zero();  // end-effector axes
  double scale = 0.0;
  Eigen::Vector2d mount_c = Eigen::Vector2d::Zero();
};

// The payload's parameters among `active` (mass, first moment) and its couple, into *ct.
inline void EffectModel::PayloadTerms(const ConfigLoads& L, const std::vector<int>& active,
                                      const double* theta, ChainTerms* ct) const {
  bool any = false;
  ForEachEffect(active, theta, [&](int i, const double* t) {
    if (candidates_[i].type == EffectType::kPayload) {
      ct->payload += t[0];
      ct->payload_first += Vec3(t[1], t[2], t[3]);
      any = true;
    }
  });
  if (any) ct->couple = L.M_first * ct->payload_first;
}

// One active effect's terms (parameters t) onto ws and *ct.
inline void EffectModel::AddTerms(const Candidate& c, const Eigen::VectorXd& q,
                                  const ConfigLoads& L, const double* t, ChainTerms* ct,
                                  Workspace& ws) const {
  switch (c.type) {
    case EffectType::kJointOffset:
      ws.dq[c.q_index] += t[0];
      break;
    case EffectType::kJointCompliance:
    case EffectType::kBacklash:
    case EffectType::kStiffeningSpring:
      AddLoadDriven(c, L, JointLoadOf(L, c.q_index, ct->payload, ct->couple), t, &ws.dq[c.q_index]);
      break;
    case EffectType::kLinkLength:
      ws.dlen[c.frame] += t[0];
      break;
    case EffectType::kLinkOffset:
      ws.offset[c.frame] += Vec3(t[0], t[1], t[2]);
      break;
    case EffectType::kAxisTilt:
      ws.tilt[c.frame] += t[0] * (c.axis ? tilt_b_[c.frame] : tilt_a_[c.frame]);
      break;
    case EffectType::kLateralCompliance:
      ws.tilt[c.frame] += LateralTurn(L, c.q_index, c.frame, t, ct->payload, ct->couple);
      break;
    case EffectType::kLinkBending:
      ws.bend[c.frame] += t[0] * Across(MidMoment(L, mid_slot_[c.frame], ct->payload, ct->couple),
                                        link_dir_[c.frame]);
      break;
    case EffectType::kBaseCompliance:
      // Copies add their compliances (a screened candidate on top of itself): one mount.
      ct->mount_c += Eigen::Vector2d(t[0], t[1]);
      ws.mount_active = true;
      break;
    case EffectType::kThermalExpansion:
      ct->scale += t[0];
      break;
    case EffectType::kJointOrigin:
      for (int k = 0; k < 6; ++k) ws.origin[c.frame][k] += t[k];
      break;
    case EffectType::kTransmissionError:
    case EffectType::kJointErrorCurve:
      AddPeriodicError(c, q[c.q_index], t, &ws.dq[c.q_index]);
      break;
    case EffectType::kPayload:
    case EffectType::kCameraOffset:  // acts on the camera, not on the chain
    case EffectType::kGravityTilt:   // acts on the loads (TiltedLoads)
      break;
  }
}

void EffectModel::AccumulateTerms(const Eigen::VectorXd& q, const ConfigLoads& L,
                                  const std::vector<int>& active, const double* theta,
                                  Workspace& ws) const {
  ChainTerms ct;
  PayloadTerms(L, active, theta, &ct);
  // The per-frame terms are zero between calls (MakeWorkspace, and the reset below): only the
  // active effects' frames are touched, so a call costs what its effects cost, not the model's
  // frame count (the rover's chain has dozens of frames; a fill of all was ~1/3 of a call).
  ws.dq.setZero();
  Vec3 mount_rot = Vec3::Zero();
  ws.mount_active = false;
  ForEachEffect(active, theta,
                [&](int i, const double* t) { AddTerms(candidates_[i], q, L, t, &ct, ws); });
  // A driver's true angle drives its coupled joints (sim::DeclaredChain::couplings).
  if (!chain_->couplings.empty()) chain_->PropagateShift(q, &ws.dq);
  if (ws.mount_active) {
    const Vec3 M = L.M_mount + ct.payload * L.M_mount_unit + L.R_mount_T * ct.couple;
    const Vec3 s = L.s_mount + ct.payload * L.s_mount_unit + L.R_mount_point * ct.payload_first;
    mount_rot = kinematics::MountTilt(ct.mount_c, M, s, L.g_mount, &ws.mount_J);
  }
  ws.payload = ct.payload;
  ws.couple = ct.couple;
  ws.scale = ct.scale;
  ws.mount_rot = mount_rot;
}

inline bool EffectModel::Touched(FrameId f, const Workspace& ws) const {
  return ws.scale != 0.0 || ws.dlen[f] != 0.0 || !ws.offset[f].isZero(0.0) ||
         !ws.origin[f].isZero(0.0) || !ws.bend[f].isZero(0.0) || !ws.tilt[f].isZero(0.0) ||
         (f == mount_ && !ws.mount_rot.isZero());
}

// Frame f's step where the active effects touch it (Touched): its translation scaled,
// lengthened and offset, its origin moved, its link bent, the mount turned, the axis tilted,
// then the joint's motion.
inline void EffectModel::TouchedStep(FrameId f, const Eigen::VectorXd& q, Workspace& ws) const {
  const kinematics::PpoeFrame& fr = chain_->model.frame(f);
  const Vec3& t0 = fr.T_parent_ip.translation();
  Vec3 tr = t0 * (1.0 + ws.scale);
  if (ws.dlen[f] != 0.0) tr += ws.dlen[f] * t0.normalized();
  tr += ws.offset[f];
  lie::SE3 T_parent_f(fr.T_parent_ip.rotation(), tr);
  if (!ws.origin[f].isZero()) T_parent_f = T_parent_f * lie::SE3::Exp(ws.origin[f]);
  ws.T[f] = ws.T[fr.parent] * T_parent_f;
  if (!ws.bend[f].isZero()) {
    // The link turns about its middle: an Euler-Bernoulli beam under an end moment.
    const FrameId p = prev_joint_[f];
    const Mat3 Rb = lie::SO3Exp(ws.T[p].rotation() * ws.bend[f]);
    const Vec3 mid = 0.5 * (ws.T[p].translation() + ws.T[f].translation());
    ws.T[f] = lie::SE3(Rb, mid - Rb * mid) * ws.T[f];
  }
  if (f == mount_ && !ws.mount_rot.isZero()) {
    ws.T[f] = ws.T[f] * lie::SE3(kinematics::MountRotation(ws.mount_rot), Vec3::Zero());
  }
  if (!ws.tilt[f].isZero()) ws.T[f] = ws.T[f] * lie::SE3(lie::SO3Exp(ws.tilt[f]), Vec3::Zero());
  if (fr.q_index >= 0) ws.T[f] = ws.T[f] * fr.JointMotion(q[fr.q_index] + ws.dq[fr.q_index]);
}

void EffectModel::ChainPoses(const Eigen::VectorXd& q, const ConfigLoads& L, Workspace& ws) const {
  const kinematics::PpoeModel& model = chain_->model;
  const int n = model.num_frames();
  ws.T[0] = lie::SE3();
  // Until the first frame the effects touch, the poses are the cached nominal ones (when cached
  // for this very q: the diagnostics predict at perturbed readings with a row's loads).
  bool nominal =
      static_cast<int>(L.T_nominal.size()) == n && L.q_nominal.size() == q.size() &&
      std::equal(q.data(), q.data() + q.size(), L.q_nominal.data(),
                 [](double a, double b) { return std::memcmp(&a, &b, sizeof(double)) == 0; });
  for (FrameId f = 1; f < n; ++f) {
    if (!on_path_[f]) continue;
    if (Touched(f, ws)) {
      nominal = false;
      TouchedStep(f, q, ws);
      continue;
    }
    // Untouched by the active effects (most frames, most calls): the FK kernels' form.
    const kinematics::PpoeFrame& fr = model.frame(f);
    const double dqf = fr.q_index >= 0 ? ws.dq[fr.q_index] : 0.0;
    if (nominal && dqf == 0.0 && !std::signbit(dqf)) {
      ws.T[f] = L.T_nominal[f];
      continue;
    }
    nominal = false;
    const double qf = fr.q_index >= 0 ? q[fr.q_index] + dqf : 0.0;
    ws.T[f] = ws.T[fr.parent] * fr.FixedTimesMotion(qf);
  }
}

void EffectModel::ClearTerms(const std::vector<int>& active, Workspace& ws) const {
  ForEachEffect(active, nullptr, [&](int i, const double*) {
    const int f = candidates_[i].frame;
    if (f < 0) return;
    ws.dlen[f] = 0.0;
    ws.bend[f].setZero();
    ws.offset[f].setZero();
    ws.tilt[f].setZero();
    ws.origin[f].setZero();
  });
}

// Analytic derivatives of PredictPose (finite differences re-predicted every row twice
// per parameter). PredictPose's step of frame f is T1 = T_parent (R_p, t), T2 = T1 Exp(origin),
// T3 = Bend T2, T4 = T3 Exp(mount), T5 = T4 Exp(tilt), T_f = T5 Exp(zeta (q + dq)). A parameter
// acting at one stage moves the frames below it rigidly (they are that stage's pose times
// factors the parameter does not touch; a link_bending below turns about a pivot that moves
// with them), so the point moves as a point fixed in that stage's frame: d p = R_s (w_s x y_s +
// v_s) for a body twist (v_s, w_s) of stage pose T_s and y_s the point in T_s's coordinates.
// The body twists use d Exp(x) = Exp(x) [Jr(x) dx] on SO(3) and SE(3) (Sola et al., "A micro
// Lie theory", eqs. 143-144 and 179-180). y_s comes from the frames below in their own
// coordinates (ChainPoses' steps without the base pose), so a point on a joint's axis, or on
// an origin's rotation axis, gets a derivative of exactly zero, as the finite differences did:
// selection tells an unobservable candidate by its zero column.

double EffectModel::JointLoad(const ConfigLoads& L, int k, const Workspace& ws) const {
  return JointLoadOf(L, k, ws.payload, ws.couple);
}

namespace {

// A load below a nanonewton-metre is the rounding residue of a zero one (gravity about a
// vertical axis): its effect's derivative is zero, as the finite differences found (the change
// it makes falls below the last bit of the joint angle), and selection tells an unidentifiable
// candidate by its zero column.
double Load(double load) { return std::abs(load) < 1e-9 ? 0.0 : load; }
Vec3 Load(const Vec3& load) { return Vec3(Load(load.x()), Load(load.y()), Load(load.z())); }

}  // namespace

int EffectModel::BendsOnLink(FrameId f, const std::vector<int>& active, bool at_bend) const {
  const kinematics::PpoeModel& model = chain_->model;
  int count = 0;
  ForEachEffect(active, nullptr, [&](int i, const double*) {
    const Candidate& b = candidates_[i];
    if (b.type != EffectType::kLinkBending) return;
    bool on = at_bend && b.frame == f;
    for (FrameId g = model.frame(b.frame).parent; g > 0 && g != prev_joint_[b.frame];
         g = model.frame(g).parent) {
      on = on || g == f;
    }
    count += on;
  });
  return count;
}

FrameId EffectModel::PivotBend(FrameId f, const Workspace& ws) const {
  // Frame ids grow away from the base, so on the path a frame's ancestors have smaller ids.
  for (FrameId g = ws.point; g >= f && g > 0; g = chain_->model.frame(g).parent) {
    if (prev_joint_[g] >= 0 && prev_joint_[g] < f && !ws.bend[g].isZero()) return g;
  }
  return -1;
}

void EffectModel::ThroughBend(FrameId f, FrameId b, const Workspace& ws, int n,
                              Tangent* out) const {
  // The point P = Rb X + (I - Rb) mid, X where it would be unbent, mid = (t_prev + t_2b) / 2
  // the link's middle, t_2b frame b's origin before the bend; Rb = Exp(phi) does not depend on
  // the parameter (phi turns with the previous joint's frame, above f). The parameter moves X
  // and t_2b rigidly with one twist (world rate w): dX, and d t_2b = dX - w x (X - t_2b).
  const Stages& st = ws.stages[b];
  const Mat3 Rb = lie::SO3Exp(st.phi);
  const Vec3& P = ws.T[ws.point].translation();
  const Vec3 X = Rb.transpose() * (P - st.mid) + st.mid;
  const Vec3& t_2b = st.T2.translation();
  for (int k = 0; k < n; ++k) {
    const Vec3 w = out[k].w;
    // Below b (f above it) the tangent saw the bent point; at b its stage is before the bend.
    const Vec3 dX = f == b ? out[k].dp : Vec3(out[k].dp + w.cross(X - P));
    const Vec3 d_mid = 0.5 * (dX - w.cross(X - t_2b));
    out[k].dp = Rb * dX + d_mid - Rb * d_mid;
    out[k].w = Rb * w;
  }
}

bool EffectModel::HasTangent(int c, const std::vector<int>& active) const {
  const Candidate& cand = candidates_[c];
  switch (cand.type) {
    case EffectType::kThermalExpansion:
    case EffectType::kPayload:
    case EffectType::kCameraOffset:
    case EffectType::kGravityTilt:  // through every load-driven term at once, as the payload
      return false;
    case EffectType::kLinkLength:
    case EffectType::kLinkOffset:
    case EffectType::kJointOrigin:
      // Before the bend of f: the pivot of one bend at f or around it (ThroughBend).
      return BendsOnLink(cand.frame, active, true) <= 1;
    case EffectType::kBaseCompliance:
      return BendsOnLink(cand.frame, active, false) == 0;
    case EffectType::kJointOffset:
    case EffectType::kJointCompliance:
    case EffectType::kBacklash:
    case EffectType::kTransmissionError:
    case EffectType::kJointErrorCurve:
    case EffectType::kStiffeningSpring:
      // At a driver the correction moves its coupled joints too: not in the tangents.
      return !drives_coupled_[cand.q_index];
    default:
      return true;
  }
}

EffectModel::Stages EffectModel::FrameStages(FrameId f, const Workspace& ws) const {
  const kinematics::PpoeFrame& fr = chain_->model.frame(f);
  Stages st;
  const Vec3& t0 = fr.T_parent_ip.translation();
  Vec3 tr = t0 * (1.0 + ws.scale);
  if (ws.dlen[f] != 0.0) tr += ws.dlen[f] * t0.normalized();
  tr += ws.offset[f];
  st.L2 = lie::SE3(fr.T_parent_ip.rotation(), tr);
  if (!ws.origin[f].isZero()) st.L2 = st.L2 * lie::SE3::Exp(ws.origin[f]);
  const lie::SE3& T_parent = ws.T[fr.parent];
  st.T2 = T_parent * st.L2;
  st.L4 = st.L2;
  if (prev_joint_[f] >= 0) {
    const lie::SE3& Tp = ws.T[prev_joint_[f]];
    st.phi = Tp.rotation() * ws.bend[f];
    st.mid = 0.5 * (Tp.translation() + st.T2.translation());
    if (!ws.bend[f].isZero()) {
      // The bend, a base-frame turn about the middle, seen from the parent.
      const Mat3 Rb = lie::SO3Exp(st.phi);
      st.L4 = T_parent.Inverse() * lie::SE3(Rb, st.mid - Rb * st.mid) * st.T2;
    }
  }
  if (f == mount_ && !ws.mount_rot.isZero()) st.R_mount = kinematics::MountRotation(ws.mount_rot);
  if (!ws.tilt[f].isZero()) st.R_tilt = lie::SO3Exp(ws.tilt[f]);
  st.L4 = st.L4 * lie::SE3(st.R_mount, Vec3::Zero());
  st.T4 = T_parent * st.L4;
  st.T5 = st.T4 * lie::SE3(st.R_tilt, Vec3::Zero());
  return st;
}

void EffectModel::PointInFrames(const Eigen::VectorXd& q, FrameId top, Workspace& ws) const {
  const kinematics::PpoeModel& model = chain_->model;
  Vec3 y = Vec3::Zero();  // in the current frame's coordinates
  for (FrameId g = ws.point; g >= top && g > 0; g = model.frame(g).parent) {
    const kinematics::PpoeFrame& fr = model.frame(g);
    const lie::SE3 motion =
        fr.q_index >= 0 ? fr.JointMotion(q[fr.q_index] + ws.dq[fr.q_index]) : lie::SE3();
    ws.y[g] = motion * y;
    ws.touched[g] = Touched(g, ws);
    if (!ws.touched[g]) {
      y = fr.T_parent_ip * ws.y[g];
      continue;
    }
    ws.stages[g] = FrameStages(g, ws);
    y = ws.stages[g].L4 * (ws.stages[g].R_tilt * ws.y[g]);
  }
}

bool EffectModel::MovesFrame(FrameId a, FrameId f) const {
  for (; f > a; f = chain_->model.frame(f).parent) {
  }
  return f == a;
}

namespace {

using Tangent = EffectModel::Tangent;

// A body twist (v, w) of the stage pose T with the point at y there.
inline Tangent BodyTangent(const lie::SE3& T, const Vec3& y, const Vec3& v, const Vec3& w) {
  Tangent d;
  d.w = T.rotation() * w;
  d.dp = T.rotation() * (w.cross(y) + v);
  return d;
}

// The joint of frame fr moving by dq' (d/dq Exp(zeta q) = Exp(zeta q) zeta), T5 the frame's
// pose before it moves and y5 the point there.
inline Tangent JointTangent(const kinematics::PpoeFrame& fr, const lie::SE3& T5, const Vec3& y5,
                            double dq_ds) {
  const Vec3 w = dq_ds * fr.joint.axis;
  if (fr.joint.type == kinematics::JointType::kPrismatic) {
    return BodyTangent(T5, y5, w, Vec3::Zero());
  }
  return BodyTangent(T5, y5 - fr.joint.point, Vec3::Zero(), w);
}

}  // namespace

inline const EffectModel::Stages& EffectModel::TangentStages(const Candidate& c,
                                                             const Workspace& ws,
                                                             Stages* local) const {
  const FrameId f = c.frame;
  // Most candidates sit at frames the active effects leave alone: there T2 = T4 = T5 = T_parent
  // T_parent_ip, and only their rotation matters below (a bend needs its pivot: all stages).
  if (ws.touched[f]) return ws.stages[f];  // PointInFrames'
  if (c.type == EffectType::kLinkBending) {
    *local = FrameStages(f, ws);
    return *local;
  }
  const kinematics::PpoeFrame& fr = chain_->model.frame(f);
  local->T2 = lie::SE3(ws.T[fr.parent].rotation() * fr.T_parent_ip.rotation(), Vec3::Zero());
  local->T4 = local->T5 = local->T2;
  return *local;
}

void EffectModel::JointTangents(const Candidate& c, const Eigen::VectorXd& q, const ConfigLoads& L,
                                const Workspace& ws, const lie::SE3& T5, Tangent* out) const {
  const kinematics::PpoeFrame& fr = chain_->model.frame(c.frame);
  const Vec3& y5 = ws.y[c.frame];
  const auto joint = [&](double dq_ds) { return JointTangent(fr, T5, y5, dq_ds); };
  switch (c.type) {
    case EffectType::kJointOffset:
      out[0] = joint(1.0);
      break;
    case EffectType::kJointCompliance:
      out[0] = joint(Load(JointLoad(L, c.q_index, ws)));
      break;
    case EffectType::kBacklash:
      // The flank as AccumulateTerms picks it (a sign: constant in the parameter).
      out[0] = joint(Flank(L, c.q_index, JointLoad(L, c.q_index, ws)));
      break;
    case EffectType::kTransmissionError:
    case EffectType::kJointErrorCurve: {
      const double qj = q[c.q_index];
      for (int h = 1; 2 * h <= c.num_params; ++h) {
        out[2 * h - 2] = joint(std::cos(h * qj));
        out[2 * h - 1] = joint(std::sin(h * qj));
      }
      break;
    }
    case EffectType::kStiffeningSpring: {
      const double tau = Load(JointLoad(L, c.q_index, ws));
      out[0] = joint(tau);
      out[1] =
          joint(tau * tau * tau / (kinematics::kStiffeningTau0Nm * kinematics::kStiffeningTau0Nm));
      break;
    }
    default:
      break;  // not a joint-level effect
  }
}

void EffectModel::BaseComplianceTangents(const ConfigLoads& L, const Workspace& ws,
                                         const lie::SE3& T4, const Vec3& y4, Tangent* out) const {
  // d tilt / d c: MountTilt's at the active compliance; at none, the moment at rest.
  const Vec3 M = Load(L.M_mount + ws.payload * L.M_mount_unit + L.R_mount_T * ws.couple);
  const Eigen::Matrix2d J =
      ws.mount_active ? ws.mount_J : Eigen::Matrix2d(Eigen::Vector2d(M.x(), M.y()).asDiagonal());
  // Body rates of MountRotation = R_y(theta_y) R_x(theta_x): x for theta_x, R_x^T y for
  // theta_y.
  double sx, cx;
  lie::SinCos(ws.mount_rot.x(), &sx, &cx);
  const Vec3 by(0.0, cx, -sx);
  for (int k = 0; k < 2; ++k) {
    out[k] = BodyTangent(T4, y4, Vec3::Zero(), Vec3(J(0, k), 0.0, 0.0) + J(1, k) * by);
  }
}

void EffectModel::LinkBendingTangent(FrameId f, const ConfigLoads& L, const Workspace& ws,
                                     const Stages& st, Tangent* out) const {
  // T3 = (Rb, mid - Rb mid) T2, Rb = Exp(phi): a base-frame turn about the link's middle.
  const Vec3& dir = link_dir_[f];
  const Vec3 M = MidMoment(L, mid_slot_[f], ws.payload, ws.couple);
  const Vec3 dphi = ws.T[prev_joint_[f]].rotation() * Load(Vec3(M - M.dot(dir) * dir));
  out[0].w = lie::SO3LeftJacobian(st.phi) * dphi;
  out[0].dp = out[0].w.cross(ws.T[ws.point].translation() - st.mid);
}

void EffectModel::TranslationTangents(const Candidate& c, const Workspace& ws, Tangent* out) const {
  const kinematics::PpoeFrame& fr = chain_->model.frame(c.frame);
  if (c.type == EffectType::kLinkLength) {
    out[0].w.setZero();
    out[0].dp = ws.T[fr.parent].rotation() * fr.T_parent_ip.translation().normalized();
    return;
  }
  for (int k = 0; k < 3; ++k) {  // link_offset
    out[k].w.setZero();
    out[k].dp = ws.T[fr.parent].rotation().col(k);
  }
}

void EffectModel::CandidateTangents(const Candidate& c, const Eigen::VectorXd& q,
                                    const ConfigLoads& L, const Workspace& ws, Tangent* out) const {
  const FrameId f = c.frame;
  if (!MovesFrame(f, ws.point)) {  // on another branch of the tree than the point
    for (int k = 0; k < c.num_params; ++k) out[k] = Tangent();
    return;
  }
  Stages local;
  const Stages& st = TangentStages(c, ws, &local);
  // The point in the coordinates of T5 (before the joint moves), T4 and T2.
  const Vec3& y5 = ws.y[f];
  const Vec3 y4 = st.R_tilt * y5;
  const Vec3 y2 = st.R_mount * y4;  // at a bent frame: the point before the bend
  switch (c.type) {
    case EffectType::kJointOffset:
    case EffectType::kJointCompliance:
    case EffectType::kBacklash:
    case EffectType::kTransmissionError:
    case EffectType::kJointErrorCurve:
    case EffectType::kStiffeningSpring:
      JointTangents(c, q, L, ws, st.T5, out);
      break;
    case EffectType::kAxisTilt:
      out[0] = BodyTangent(st.T5, y5, Vec3::Zero(),
                           lie::SO3RightJacobian(ws.tilt[f]) * (c.axis ? tilt_b_[f] : tilt_a_[f]));
      break;
    case EffectType::kLateralCompliance: {
      // The tilt's rate, each axis's turn scaled by its moment (T5 = T4 Exp(tilt)).
      const Mat3 Jr = lie::SO3RightJacobian(ws.tilt[f]);
      const Eigen::Vector2d M = LateralLoadOf(L, c.q_index, ws.payload, ws.couple);
      out[0] = BodyTangent(st.T5, y5, Vec3::Zero(), Jr * (Load(M.x()) * tilt_a_[f]));
      out[1] = BodyTangent(st.T5, y5, Vec3::Zero(), Jr * (Load(M.y()) * tilt_b_[f]));
      break;
    }
    case EffectType::kBaseCompliance:
      BaseComplianceTangents(L, ws, st.T4, y4, out);
      break;
    case EffectType::kLinkBending:
      LinkBendingTangent(f, L, ws, st, out);
      break;
    case EffectType::kLinkLength:
    case EffectType::kLinkOffset:
      TranslationTangents(c, ws, out);
      break;
    case EffectType::kJointOrigin: {
      // T2 = T1 Exp(xi): body twist Jr(xi) e_k, xi = [rho; theta].
      const Mat6 Jr = lie::SE3RightJacobian(ws.origin[f]);
      for (int k = 0; k < 6; ++k) {
        out[k] = BodyTangent(st.T2, y2, Jr.col(k).head<3>(), Jr.col(k).tail<3>());
      }
      break;
    }
    case EffectType::kThermalExpansion:
    case EffectType::kPayload:
    case EffectType::kCameraOffset:
    case EffectType::kGravityTilt:
      break;  // HasTangent is false
  }
  if (c.type == EffectType::kLinkLength || c.type == EffectType::kLinkOffset ||
      c.type == EffectType::kJointOrigin) {
    const FrameId b = PivotBend(f, ws);
    if (b >= 0) ThroughBend(f, b, ws, c.num_params, out);
  }
}

lie::SE3 EffectModel::PoseTangents(const Eigen::VectorXd& q, const ConfigLoads& L,
                                   const std::vector<int>& active, const double* theta,
                                   const std::vector<int>& cs, Workspace& ws, Tangent* out,
                                   int point) const {
  const ConfigLoads& Lt = TiltedLoads(L, active, theta, ws);
  AccumulateTerms(q, Lt, active, theta, ws);
  ChainPoses(q, L, ws);
  ws.point = points_[point];
  // Frames ids grow away from the base: the point is needed from the highest candidate down
  // (candidates on other branches have zero tangents and need no coordinates).
  FrameId top = ws.point;
  for (int c : cs) {
    if (MovesFrame(candidates_[c].frame, ws.point)) top = std::min(top, candidates_[c].frame);
  }
  PointInFrames(q, top, ws);
  for (int c : cs) {
    CandidateTangents(candidates_[c], q, Lt, ws, out);
    out += candidates_[c].num_params;
  }
  ClearTerms(active, ws);
  return ws.T[ws.point];
}

}  // namespace flexbench::identify
