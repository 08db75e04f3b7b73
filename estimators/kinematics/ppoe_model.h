// The Probabilistic Product-Of-Exponentials (PPOE) robot model (PPOE paper sec. IV), split
// Pinocchio-style into a constant PpoeModel and a PpoeData workspace (ppoe_data.h).
//
// FRAMES. The model is a tree of named frames. Frame 0 is the root "base" (identity, no
// uncertainty). Every other frame i has a parent frame (added earlier, so index order is a
// topological order) and is placed by
//
//   T_parent_i(q) = Exp(p_i) * Exp(xi_i) * Exp(zeta_i q_i)                        [PPOE eq. 16]
//                   \_ T_parent_ip _/  \_ source _/  \_ joint _/
//
// - p_i is stored as the SE(3) pose T_parent_ip of the intermediate frame F_{i,p} (the nominal
//   link geometry, "green" in the paper's Fig. 2) in the parent frame. Storing the pose instead
//   of the twist p_i avoids a Log per link; Exp(p_i) = T_parent_ip.
// - xi_i ~ N(0, Sigma_i) is the perturbation source, a right perturbation at F_{i,p} giving the
//   true geometry F_{i,xi}. Sigma_i is 6x6, [rho; theta] order, symmetric PSD; any DoF may be
//   zero (singular allowed), and an all-zero Sigma_i means "no source".
// - zeta_i is the unit joint twist expressed in F_{i,xi} (equivalently in F_{i,p}: the source is
//   zero-mean). A revolute joint about the unit axis w through the point r has
//   zeta = [r x w; w], a prismatic joint along w has zeta = [w; 0], a fixed frame has zeta = 0
//   and no joint variable. q_i is in rad or m.
// - F_i (the link frame, moving with q_i) is the frame after the joint.
//
// Links are frames with a joint (AddLink); extra frames are rigid (AddFrame, joint fixed):
// end-effector ([PPOE eq. 17]'s Exp(p_{n+1})), tags, camera points, and a grasp frame whose
// uncertain xi_grasp is its source (the paper's grasp-linkage extension). A passive compliance with
// no actuator (e.g. a base plate) is a frame with a fixed joint and a source. Any frame can be a
// parent, so tree-structured robots are chains sharing a trunk.
//
// Joint variables: each frame with a revolute or prismatic joint takes the next index of q in
// the order the frames are added (q_index); fixed frames take none.
#pragma once

#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"
#include "estimators/lie/sincos.h"
#include "estimators/lie/so3.h"

namespace flexbench::kinematics {

using FrameId = int;
inline constexpr FrameId kBaseFrame = 0;

enum class JointType { kFixed, kRevolute, kPrismatic };

// A joint in F_{i,xi} coordinates. Axes need not be unit length (they are normalised when the
// joint is added to a model) but must not be zero.
struct Joint {
  JointType type = JointType::kFixed;
  Vec3 axis = Vec3::UnitZ();
  Vec3 point = Vec3::Zero();  // a point on a revolute axis; unused otherwise

  static Joint Fixed() { return Joint{}; }
  static Joint Revolute(const Vec3& axis, const Vec3& point = Vec3::Zero()) {
    return Joint{JointType::kRevolute, axis, point};
  }
  static Joint Prismatic(const Vec3& axis) {
    return Joint{JointType::kPrismatic, axis, Vec3::Zero()};
  }
};

// One frame of the model, with values precomputed for the FK kernels.
struct PpoeFrame {
  std::string name;
  FrameId parent = -1;
  lie::SE3 T_parent_ip;            // Exp(p_i)
  Mat6 source_cov = Mat6::Zero();  // Sigma_i of xi_i at F_{i,p}
  bool has_source = false;         // source_cov != 0
  Joint joint;                     // axis normalised
  Vec6 zeta = Vec6::Zero();        // unit twist [r x w; w], [w; 0] or 0
  int q_index = -1;                // -1 for fixed frames

  // T_parent_ip * Exp(zeta q) = (R_p + a K1 + b K2, u0 + a u1 + b u2), precomputed:
  // revolute about w through r: a = sin q, b = 1 - cos q, K1 = R_p [w]x, K2 = R_p [w]x^2,
  //   u0 = t_p, u1 = -K1 r, u2 = -K2 r;
  // prismatic along w: a = q, b = 0, K1 = K2 = 0, u0 = t_p, u1 = R_p w; fixed: a = b = 0.
  Mat3 K1 = Mat3::Zero();
  Mat3 K2 = Mat3::Zero();
  Vec3 u0 = Vec3::Zero();
  Vec3 u1 = Vec3::Zero();
  Vec3 u2 = Vec3::Zero();
  // [w]x^2 of the joint axis, for Exp(zeta q) alone.
  Mat3 W2 = Mat3::Zero();

  // The source expressed at the parent frame, Ad_{T_parent_ip} Sigma_i Ad^T: T_parent Exp(eta)
  // T_parent_ip Exp(xi_i) = T_parent Exp(eta) Exp(Ad xi_i) T_parent_ip exactly, so to 2nd order
  // [PPOE eq. 18] a frame's covariance is one transport of (Sigma_parent + this) through
  // T_parent_i(q): one 6x6 congruence per frame.
  Mat6 source_cov_parent = Mat6::Zero();

  // T_parent_ip * Exp(zeta q) from the precomputed Rodrigues terms (the FK kernels' form).
  // Forced inline: the augmented chain's loads and the identification take it for every frame.
  EIGEN_ALWAYS_INLINE lie::SE3 FixedTimesMotion(double q) const {
    switch (joint.type) {
      case JointType::kRevolute: {
        double sh, ch;
        lie::SinCos(0.5 * q, &sh, &ch);
        const double a = 2.0 * sh * ch, b = 2.0 * sh * sh;
        return lie::SE3(T_parent_ip.rotation() + a * K1 + b * K2, u0 + a * u1 + b * u2);
      }
      case JointType::kPrismatic:
        return lie::SE3(T_parent_ip.rotation(), u0 + q * u1);
      case JointType::kFixed:
        break;
    }
    return T_parent_ip;
  }

  // Exp(zeta q) (the joint motion alone), by Rodrigues' formula with one inline sincos of q/2
  // (as the FK kernels; the general SE3::Exp costs ~3x as much).
  lie::SE3 JointMotion(double q) const {
    switch (joint.type) {
      case JointType::kRevolute: {
        double sh, ch;
        lie::SinCos(0.5 * q, &sh, &ch);
        const Mat3 R =
            Mat3::Identity() + (2.0 * sh * ch) * lie::Skew(joint.axis) + (2.0 * sh * sh) * W2;
        return lie::SE3(R, joint.point - R * joint.point);
      }
      case JointType::kPrismatic:
        return lie::SE3::Translation(q * joint.axis);
      case JointType::kFixed:
        break;
    }
    return lie::SE3();
  }
};

class PpoeModel {
 public:
  // `name` appears in error messages (e.g. the declared model's file name).
  explicit PpoeModel(std::string name = "ppoe");

  // Adds a frame with a joint (revolute or prismatic; Joint::Fixed() is allowed too) below
  // `parent`: T_parent_i(q) = T_parent_ip * Exp(xi_i) * Exp(zeta_i q_i) [PPOE eq. 16], xi_i ~ N(0,
  // source_cov). Returns the new frame's id. Throws InputError on an unknown parent, an empty or
  // duplicate name, a non-rotation in T_parent_ip, a zero or non-finite joint axis, or a source
  // covariance that is not finite, symmetric and positive semi-definite (naming the frame).
  FrameId AddLink(FrameId parent, const std::string& name, const lie::SE3& T_parent_ip,
                  const Joint& joint, const Mat6& source_cov = Mat6::Zero());

  // Adds a rigid frame: T_parent_f = T_parent_fp * Exp(xi_f), xi_f ~ N(0, source_cov); e.g. the
  // end-effector Exp(p_{n+1}) of [PPOE eq. 17] (no source) or a grasp frame with its xi_grasp.
  FrameId AddFrame(FrameId parent, const std::string& name, const lie::SE3& T_parent_fp,
                   const Mat6& source_cov = Mat6::Zero());

  // Replaces frame `id`'s fixed transform T_parent_ip (its joint and source stay) and updates the
  // precomputed terms; does not allocate. For a model corrected at run time (model_effects.h);
  // the caller keeps T_parent_ip a rigid transform. With move_source false the source keeps its
  // covariance at the parent (source_cov_parent), which saves a 6x6 transport when the change is
  // a milliradian turn. Throws std::invalid_argument for an unknown frame.
  void SetFixedTransform(FrameId id, const lie::SE3& T_parent_ip, bool move_source = true);

  // Replaces frame `id`'s source covariance (at F_{i,p}) and its transport to the parent, e.g.
  // with an identified effect's parameter uncertainty that changes with the load. For hot
  // loops: no validation beyond the id; the caller keeps `source_cov` symmetric PSD.
  void SetSourceCovariance(FrameId id, const Mat6& source_cov);

  const std::string& name() const { return name_; }
  int num_frames() const { return static_cast<int>(frames_.size()); }
  // Number of joint variables (size of q).
  int nq() const { return static_cast<int>(q_frames_.size()); }

  const PpoeFrame& frame(FrameId id) const { return frames_.at(id); }
  const std::vector<PpoeFrame>& frames() const { return frames_; }
  // The frame moved by q[k].
  FrameId joint_frame(int k) const { return q_frames_.at(k); }

  // Throws InputError naming the model and the missing frame.
  FrameId FindFrame(const std::string& name) const;
  bool HasFrame(const std::string& name) const;

 private:
  static void Precompute(PpoeFrame* f, bool move_source = true);

  std::string name_;
  std::vector<PpoeFrame> frames_;
  std::vector<FrameId> q_frames_;
};

}  // namespace flexbench::kinematics
