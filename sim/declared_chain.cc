#include "sim/declared_chain.h"

#include <functional>
#include <map>
#include <set>

#include "estimators/error.h"
#include "sim/declared_effects.h"
#include "sim/model_catalog.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

using kinematics::FrameId;
using kinematics::Joint;
using lie::SE3;

SE3 PoseFrom(const double* pos, const double* quat_wxyz) {
  return SE3(QuatFromWxyz(quat_wxyz), Eigen::Map<const Vec3>(pos));
}

class ChainBuilder {
 public:
  ChainBuilder(const mjModel* m, const DeclaredModel& d, DeclaredChain* out)
      : m_(m), d_(d), out_(out) {}

  void Build() {
    const std::string where = d_.file;
    out_->base_body = mj_name2id(m_, mjOBJ_BODY, d_.base.c_str());
    if (d_.base == "world") out_->base_body = 0;
    if (out_->base_body < 0) Fail("base: no body named '" + d_.base + "'");
    for (const std::string& j : d_.actuated_joints) {
      const int id = mj_name2id(m_, mjOBJ_JOINT, j.c_str());
      if (id < 0) Fail("actuated_joints: no joint named '" + j + "' in " + d_.model_path);
      if (m_->jnt_type[id] != mjJNT_HINGE && m_->jnt_type[id] != mjJNT_SLIDE) {
        Fail("actuated_joints: joint '" + j + "' is not a hinge or slide joint");
      }
      if (!actuated_.insert(id).second) Fail("actuated_joints: '" + j + "' is listed twice");
    }
    for (const DeclaredCoupling& c : d_.coupled) {
      const int id = mj_name2id(m_, mjOBJ_JOINT, c.joint.c_str());
      if (id < 0) {
        throw InputError(c.where + ": no joint named '" + CapForMessage(c.joint) + "' in " +
                         d_.model_path);
      }
      if (m_->jnt_type[id] != mjJNT_HINGE && m_->jnt_type[id] != mjJNT_SLIDE) {
        throw InputError(c.where + ": joint '" + c.joint + "' is not a hinge or slide joint");
      }
      if (actuated_.count(id)) {
        throw InputError(c.where + ": joint '" + c.joint +
                         "' is in actuated_joints (read); a coupled joint follows its drivers");
      }
      coupled_.insert(id);
    }
    for (const DeclaredSource& s : d_.sources) {
      const int j = mj_name2id(m_, mjOBJ_JOINT, s.at.c_str());
      const int b = mj_name2id(m_, mjOBJ_BODY, s.at.c_str());
      if (j < 0 && b < 0) {
        throw InputError(s.where + ": source at '" + s.at + "': no joint or body of that name in " +
                         d_.model_path);
      }
      if (j >= 0) {
        joint_sources_[j].push_back(&s);
      } else {
        if (s.about_axis_rad > 0.0) {
          throw InputError(s.where + ": source at body '" + s.at +
                           "': about_axis_deg needs a joint");
        }
        body_sources_[b].push_back(&s);
      }
    }
    // End effector first, so its chain gets the first q indices in root-to-tip order.
    out_->end_effector = AddTarget(d_.end_effector, "end_effector");
    out_->end_effector_name = d_.end_effector;
    for (const std::string& name : d_.observed_frames) {
      out_->observed.emplace_back(name, AddTarget(name, "observed_frames"));
    }
    // Actuated joints off those chains (a gripper's finger joint) still get their branch, so
    // q always holds every declared joint, in a stable order.
    for (const int j : actuated_) {
      if (!used_joints_.count(j)) EnsureBody(m_->jnt_bodyid[j]);
    }
    for (const int j : coupled_) {
      if (!used_joints_.count(j)) EnsureBody(m_->jnt_bodyid[j]);
    }
    ResolveCouplings();
    for (const auto& [j, sources] : joint_sources_) {
      if (!used_joints_.count(j)) {
        throw InputError(sources.front()->where + ": source at '" + sources.front()->at +
                         "' is not on the chain to the end effector or an observed frame");
      }
    }
    for (const auto& [b, sources] : body_sources_) {
      if (!body_frame_.count(b)) {
        throw InputError(sources.front()->where + ": source at '" + sources.front()->at +
                         "' is not on the chain to the end effector or an observed frame");
      }
    }
  }

 private:
  [[noreturn]] void Fail(const std::string& msg) const { throw InputError(d_.file + ": " + msg); }

  // The couplings' drivers as joint variables, in evaluation order (drivers first).
  void ResolveCouplings() {
    const auto index = [&](const std::string& name, const std::string& where) {
      for (size_t k = 0; k < out_->q_joints.size(); ++k) {
        if (out_->q_joints[k] == name) return static_cast<int>(k);
      }
      throw InputError(where + ": driver '" + CapForMessage(name) +
                       "' is not an actuated or coupled joint of the declared model");
    };
    std::vector<DeclaredChain::Coupling> all;
    for (const DeclaredCoupling& c : d_.coupled) {
      DeclaredChain::Coupling k;
      k.q_index = index(c.joint, c.where);
      k.where = c.where;
      for (size_t i = 0; i < c.drivers.size(); ++i) {
        k.linear.emplace_back(index(c.drivers[i].first, c.driver_where[i]), c.drivers[i].second);
      }
      if (c.from_mjcf) {
        const int id = mj_name2id(m_, mjOBJ_JOINT, c.joint.c_str());
        int eq = -1;
        for (int e = 0; e < m_->neq && eq < 0; ++e) {
          if (m_->eq_type[e] == mjEQ_JOINT && m_->eq_obj1id[e] == id && m_->eq_obj2id[e] >= 0) {
            eq = e;
          }
        }
        if (eq < 0) {
          throw InputError(c.where + ": mjcf: the model has no <equality><joint> with joint1 '" +
                           c.joint + "' and a joint2");
        }
        k.poly_driver = index(ObjectName(m_, mjOBJ_JOINT, m_->eq_obj2id[eq]), c.where);
        for (int i = 0; i < 5; ++i) k.poly[i] = m_->eq_data[eq * mjNEQDATA + i];
      }
      all.push_back(std::move(k));
    }
    // Depth-first, drivers before what they drive; a driver met again on the way is a cycle.
    std::vector<int> state(all.size(), 0);  // 0 new, 1 on the path, 2 done
    std::vector<std::string> path;
    const std::function<void(size_t)> visit = [&](size_t i) {
      if (state[i] == 2) return;
      path.push_back(out_->q_joints[all[i].q_index]);
      if (state[i] == 1) {
        std::string cycle;
        for (const std::string& n : path) cycle += (cycle.empty() ? "" : " -> ") + n;
        throw InputError(all[i].where + ": coupled joints form a cycle: " + cycle);
      }
      state[i] = 1;
      std::vector<int> drivers;
      for (const auto& [k, coef] : all[i].linear) drivers.push_back(k);
      if (all[i].poly_driver >= 0) drivers.push_back(all[i].poly_driver);
      for (int k : drivers) {
        for (size_t o = 0; o < all.size(); ++o) {
          if (all[o].q_index == k) visit(o);
        }
      }
      state[i] = 2;
      path.pop_back();
      out_->couplings.push_back(all[i]);
    };
    for (size_t i = 0; i < all.size(); ++i) visit(i);
  }

  FrameId AddTarget(const std::string& name, const std::string& key) {
    const std::string typed = TypedFrameName(m_, name);
    if (typed.empty()) {
      Fail(key + ": no site, geom, camera or body named '" + name + "' in " + d_.model_path);
    }
    const std::string kind = typed.substr(0, typed.find('/'));
    // A fitted marker offset (marker_offsets:) moves the frame in its own axes. A body's frame
    // carries its children, so a moved body is a frame of its own below it.
    const Vec3 offset = d_.MarkerOffset(name);
    const SE3 moved = SE3::Translation(offset);
    if (kind == "body") {
      const FrameId b = EnsureBody(mj_name2id(m_, mjOBJ_BODY, name.c_str()));
      if (offset.isZero(0.0)) return b;
      const std::string typed_moved = typed + "/moved";
      if (out_->model.HasFrame(typed_moved)) return out_->model.FindFrame(typed_moved);
      return out_->model.AddFrame(b, typed_moved, moved);
    }
    if (out_->model.HasFrame(typed)) return out_->model.FindFrame(typed);
    if (kind == "site") {
      const int s = mj_name2id(m_, mjOBJ_SITE, name.c_str());
      return out_->model.AddFrame(EnsureBody(m_->site_bodyid[s]), typed,
                                  PoseFrom(m_->site_pos + 3 * s, m_->site_quat + 4 * s) * moved);
    }
    if (kind == "geom") {
      const int g = mj_name2id(m_, mjOBJ_GEOM, name.c_str());
      return out_->model.AddFrame(EnsureBody(m_->geom_bodyid[g]), typed,
                                  PoseFrom(m_->geom_pos + 3 * g, m_->geom_quat + 4 * g) * moved);
    }
    const int c = mj_name2id(m_, mjOBJ_CAMERA, name.c_str());
    const SE3 T_body_mjcam = PoseFrom(m_->cam_pos + 3 * c, m_->cam_quat + 4 * c);
    // MuJoCo cameras look along -z with y up; the optical frame has y down, z forward.
    const SE3 T_mjcam_optical(Mat3(Vec3(1.0, -1.0, -1.0).asDiagonal()), Vec3::Zero());
    return out_->model.AddFrame(EnsureBody(m_->cam_bodyid[c]), typed,
                                T_body_mjcam * T_mjcam_optical * moved);
  }

  Mat6 SourceCov(const std::vector<const DeclaredSource*>& sources, const Vec3& axis) const {
    Mat6 cov = Mat6::Zero();
    for (const DeclaredSource* s : sources) {
      cov += s->cov;
      cov.block<3, 3>(kRotIdx, kRotIdx) +=
          s->about_axis_rad * s->about_axis_rad * axis * axis.transpose();
    }
    return cov;
  }

  FrameId EnsureBody(int b) {
    if (b == out_->base_body) return kinematics::kBaseFrame;
    if (const auto it = body_frame_.find(b); it != body_frame_.end()) return it->second;
    if (b == 0) {
      Fail("a frame is not below the base body '" + d_.base + "'");
    }
    const FrameId parent = EnsureBody(m_->body_parentid[b]);
    // Offsets accumulate until a frame takes them: body pose, then per joint the move to its
    // anchor and back (MuJoCo rotates each joint about its anchor in the current body frame).
    SE3 pending = PoseFrom(m_->body_pos + 3 * b, m_->body_quat + 4 * b);
    FrameId current = parent;
    for (int j = m_->body_jntadr[b]; j >= 0 && j < m_->body_jntadr[b] + m_->body_jntnum[b]; ++j) {
      const std::string jname = ObjectName(m_, mjOBJ_JOINT, j);
      const int type = m_->jnt_type[j];
      if (type != mjJNT_HINGE && type != mjJNT_SLIDE) {
        Fail("joint '" + jname + "' (ball or free) on the chain is not supported");
      }
      const Vec3 anchor = Eigen::Map<const Vec3>(m_->jnt_pos + 3 * j);
      const Vec3 axis = Eigen::Map<const Vec3>(m_->jnt_axis + 3 * j).normalized();
      // A coupled joint moves like an actuated one; its angle comes from its drivers.
      const bool actuated = actuated_.count(j) > 0 || coupled_.count(j) > 0;
      if (!actuated && SkippedLateralHinge(j)) continue;
      Joint joint = Joint::Fixed();
      if (actuated) joint = type == mjJNT_HINGE ? Joint::Revolute(axis) : Joint::Prismatic(axis);
      const auto src = joint_sources_.find(j);
      const Mat6 cov = src == joint_sources_.end() ? Mat6::Zero() : SourceCov(src->second, axis);
      current = out_->model.AddLink(current, "joint/" + jname, pending * SE3::Translation(anchor),
                                    joint, cov);
      if (actuated) {
        const int adr = m_->jnt_qposadr[j];
        out_->q_joints.push_back(jname);
        out_->q_qposadr.push_back(adr);
        out_->q_qpos0.push_back(m_->qpos0[adr]);
      }
      used_joints_.insert(j);
      pending = SE3::Translation(-anchor);
    }
    const auto src = body_sources_.find(b);
    const Mat6 cov =
        src == body_sources_.end() ? Mat6::Zero() : SourceCov(src->second, Vec3::Zero());
    const FrameId frame =
        out_->model.AddFrame(current, "body/" + ObjectName(m_, mjOBJ_BODY, b), pending, cov);
    body_frame_[b] = frame;
    return frame;
  }

  // A lateral compliance hinge (ModelCatalog's convention) at the anchor of its joint J adds no
  // frame: locked at its reference it is the identity, and J's frame then carries the link as in
  // a model without the hinges (the same candidates, names and bits). A declared source there is
  // refused: J's frame is the place for it.
  bool SkippedLateralHinge(int j) {
    const int J = LateralHingeOf(m_, j);
    if (J < 0 || !(Eigen::Map<const Vec3>(m_->jnt_pos + 3 * j) ==
                   Eigen::Map<const Vec3>(m_->jnt_pos + 3 * J))) {
      return false;
    }
    if (const auto src = joint_sources_.find(j); src != joint_sources_.end()) {
      throw InputError(src->second.front()->where + ": source at '" + src->second.front()->at +
                       "': a lateral compliance hinge is not in the declared chain; put the "
                       "source at '" +
                       ObjectName(m_, mjOBJ_JOINT, J) + "'");
    }
    used_joints_.insert(j);
    return true;
  }

  const mjModel* m_;
  const DeclaredModel& d_;
  DeclaredChain* out_;
  std::set<int> actuated_;
  std::set<int> coupled_;
  std::set<int> used_joints_;
  std::map<int, std::vector<const DeclaredSource*>> joint_sources_;
  std::map<int, std::vector<const DeclaredSource*>> body_sources_;
  std::map<int, FrameId> body_frame_;
};

}  // namespace

std::string TypedFrameName(const mjModel* m, const std::string& name) {
  if (mj_name2id(m, mjOBJ_SITE, name.c_str()) >= 0) return "site/" + name;
  if (mj_name2id(m, mjOBJ_GEOM, name.c_str()) >= 0) return "geom/" + name;
  if (mj_name2id(m, mjOBJ_CAMERA, name.c_str()) >= 0) return "camera/" + name;
  if (mj_name2id(m, mjOBJ_BODY, name.c_str()) >= 0) return "body/" + name;
  return "";
}

DeclaredChain BuildDeclaredChain(const mjModel* m, const DeclaredModel& declared,
                                 bool with_couplings) {
  if (!with_couplings && !declared.coupled.empty()) {
    throw InputError(declared.coupled.front().where +
                     ": coupled joints are read by identification only (closed_loop, identify); "
                     "the estimators need a reading of every joint of their chain. To score this "
                     "model on measured rows run `flexbench identify --declared " +
                     CapForMessage(declared.file) +
                     " --calibration ROWS.csv --validation ROWS.csv --max-effects 0`; to "
                     "estimate with it, move the joint into actuated_joints and give its angle "
                     "with the readings");
  }
  DeclaredChain chain{kinematics::PpoeModel(declared.file), {}, {}, {}, 0, -1, {}, {}, {}};
  ChainBuilder(m, declared, &chain).Build();
  ApplyIdentifiedEffects(m, declared, &chain);
  return chain;
}

bool DeclaredChain::IsCoupled(int k) const {
  for (const Coupling& c : couplings) {
    if (c.q_index == k) return true;
  }
  return false;
}

namespace {

double Polynomial(const std::array<double, 5>& a, double x) {
  return a[0] + x * (a[1] + x * (a[2] + x * (a[3] + x * a[4])));
}

}  // namespace

void DeclaredChain::ApplyCouplings(Eigen::VectorXd* q) const {
  for (const Coupling& c : couplings) {
    double v = 0.0;
    for (const auto& [k, coef] : c.linear) v += coef * (*q)[k];
    if (c.poly_driver >= 0) v += Polynomial(c.poly, (*q)[c.poly_driver]);
    (*q)[c.q_index] = v;
  }
}

void DeclaredChain::PropagateShift(const Eigen::VectorXd& q, Eigen::VectorXd* dq) const {
  for (const Coupling& c : couplings) {
    double v = 0.0;
    for (const auto& [k, coef] : c.linear) v += coef * (*dq)[k];
    if (c.poly_driver >= 0) {
      const double x = q[c.poly_driver];
      v += Polynomial(c.poly, x + (*dq)[c.poly_driver]) - Polynomial(c.poly, x);
    }
    (*dq)[c.q_index] += v;
  }
}

Eigen::VectorXd DeclaredChain::QFromQpos(const double* qpos) const {
  Eigen::VectorXd q(q_qposadr.size());
  for (size_t k = 0; k < q_qposadr.size(); ++k) q[k] = qpos[q_qposadr[k]] - q_qpos0[k];
  return q;
}

void DeclaredChain::WriteQpos(const Eigen::VectorXd& q, double* qpos) const {
  for (size_t k = 0; k < q_qposadr.size(); ++k) qpos[q_qposadr[k]] = q[k] + q_qpos0[k];
}

int DeclaredChain::QIndex(const std::string& joint) const {
  for (size_t k = 0; k < q_joints.size(); ++k) {
    if (q_joints[k] == joint) return static_cast<int>(k);
  }
  throw InputError(model.name() + ": joint '" + joint + "' is not an actuated joint");
}

kinematics::FrameId DeclaredChain::ObservedFrame(const std::string& name) const {
  for (const auto& [n, f] : observed) {
    if (n == name) return f;
  }
  throw InputError(model.name() + ": '" + name + "' is not an observed frame");
}

}  // namespace flexbench::sim
