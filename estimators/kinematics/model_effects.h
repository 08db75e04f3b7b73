// Effects identified from measured data, applied to the declared PPOE chain so that every
// estimator predicts with the corrected model (the closed loop's last step).
//
// The effects are the rows of the effect table (effect_table.h), in the form the kinematics
// needs them: the terms below, which the rows' values add to, indexed by the declared model's
// frames and joint variables (a declared file's identified_effects are resolved row by row when
// it is read: sim/declared_effects.cc). At a joint reading q_read they act as
//
//   joint angle   q = q_read + offset + sum_h (a_h cos h q_read + b_h sin h q_read)
//                     + backlash * flank + compliance * tau + cubic * tau^3
//   fixed part    T_parent_ip' = B * (R_ip, t_ip (1 + thermal) + dlen t_ip/|t_ip| + offset)
//                 Exp(origin) * Exp(mount) * Exp(tilt + kappa_a M_a a + kappa_b M_b b)
//
// where tau is the gravity torque the joint holds, B turns a bent link about its middle by
// c * (the moment of the weight beyond it, across the link), a joint's lateral compliance turns its
// frame before the joint moves about its tilt axes a, b (TiltAxes) by kappa times the moment M of
// the weight beyond the joint about its anchor (Tenhumberg & Bauml 2021's kappa_alpha,
// kappa_beta), and Exp(mount) tilts the arm's
// mount by C M at its loaded equilibrium (MountTilt). The loads come from the declared masses at
// the nominal chain's configuration q_read (as the identification computes them), with the payload
// as a mass on its frame. A backlash rests on the flank its gravity torque presses (the
// identification's rule for data without recorded motion; a flank that follows the motion is not
// tracked at run time).
//
// Model/Data split: ModelEffects is constant; EffectiveChain is the per-estimator workspace that
// holds the corrected model at the last reading. Neither allocates after construction.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_data.h"
#include "estimators/kinematics/ppoe_model.h"

namespace flexbench::kinematics {

// Mass riding rigidly on a frame: its total and its first moment m c (c, the centre of mass, in
// the frame's coordinates).
struct FrameMass {
  double mass = 0.0;
  Vec3 first_moment = Vec3::Zero();
};

struct ModelEffects {
  // The reading -> joint-angle map and the gear's load-driven deflection of one joint variable.
  struct JointTerms {
    double offset = 0.0;               // rad (m for a prismatic joint)
    std::array<double, 6> harmonic{};  // a1 b1 a2 b2 a3 b3 [rad]
    double backlash = 0.0;             // rad, times the flank (+1 / -1)
    double compliance = 0.0;           // rad / (N m), times tau
    double cubic = 0.0;                // rad / (N m)^3, times tau^3
  };
  // Geometry of one frame's fixed part, and the compliance of the link that ends at it.
  struct FrameTerms {
    double dlen = 0.0;             // m, along t_ip
    Vec3 offset = Vec3::Zero();    // m, parent coordinates
    Vec6 origin = Vec6::Zero();    // [rho; theta], after the translation
    Vec3 tilt = Vec3::Zero();      // rotation vector, last before the joint
    double bend = 0.0;             // rad / (N m) of the link from bend_start to this frame
    FrameId bend_start = -1;       // the joint frame where that link starts
    Vec3 bend_dir = Vec3::Zero();  // its direction in bend_start's coordinates (unit)
    // Lateral compliance of the frame's joint, rad / (N m) about its tilt axes a and b (frame
    // coordinates, TiltAxes), times the moment about them.
    Eigen::Vector2d lateral = Eigen::Vector2d::Zero();
    Vec3 lateral_a = Vec3::Zero(), lateral_b = Vec3::Zero();
  };

  // The identified parameters' variances (their stds squared; correlations between parameters
  // are not kept). The augmented model is only as certain as its fit: EffectiveChain adds them
  // to the PPOE sources where the parameters act, so an estimator's covariance covers what the
  // identification could not pin down.
  struct Uncertainty {
    std::vector<JointTerms> joints;  // per joint variable: each term's variance
    // Per frame: covariance of the constant geometric terms (length, offset, origin, tilt,
    // thermal) as a twist at F_{i,p}, the frame's source position.
    std::vector<Mat6> frames;
    std::vector<double> bend;              // per frame: variance of the link's bending compliance
    std::vector<Eigen::Vector2d> lateral;  // per frame: variances of its lateral compliances
    Eigen::Vector2d mount_compliance = Eigen::Vector2d::Zero();
    double thermal = 0.0;
    bool empty() const;
  };

  std::vector<JointTerms> joints;  // per joint variable
  std::vector<FrameTerms> frames;  // per frame
  // Frames from the base to the end effector: thermal expansion scales their translations.
  std::vector<char> on_path;
  double thermal = 0.0;
  FrameId mount = -1;                                          // where a compliant base tilts
  Eigen::Vector2d mount_compliance = Eigen::Vector2d::Zero();  // rad / (N m) about x, y
  FrameId payload_frame = -1;
  FrameMass payload;
  // The declared masses (per frame) and gravity in the base frame, for the loads.
  std::vector<FrameMass> masses;
  Vec3 g_base = Vec3(0.0, 0.0, -9.81);
  Uncertainty uncertainty;  // sized by None(); empty: the parameters are taken as exact

  // Sized for `model`, no effect.
  static ModelEffects None(const PpoeModel& model);
  bool empty() const;
  // Whether any term depends on the loads (then `masses` must carry the arm's weight).
  bool NeedsLoads() const;
  // Whether a frame's fixed part changes with the configuration (bending, the mount's tilt).
  bool FrameVaries(FrameId f) const;
};

// Gravity torque each joint variable holds, tau (the torque its actuator must apply: MuJoCo's
// qfrc_bias at rest), from the masses of the frames below it at the poses in `data` (a mean
// forward kinematics of `model`). `subtree_mass` / `subtree_first` are scratch of num_frames
// entries: each frame's subtree mass and first moment in base coordinates.
void SubtreeMasses(const PpoeModel& model, const PpoeData& data, const ModelEffects& effects,
                   std::vector<double>* subtree_mass, std::vector<Vec3>* subtree_first);

// Tilt of a compliant mount (theta_x about its x, theta_y about its y; z = 0) under the weight
// it carries, in the mount's pre-tilt axes: the static equilibrium of two hinges with springs,
// pitch then roll about the pitched axis (MountRotation), which turn the load with them. Each
// spring holds the weight's moment at the tilted pose, theta = C m(theta); to first order
// m(theta) = M0 + S theta with S = g s^T - (s . g) I (s: the load's first moment about the
// pivot), so a load above the pivot tips further than C M0 (the P-delta effect: the stiffness
// seems k - m g h). At the rover's plate (k = 1300 N m/rad, the arm's centre of mass up to
// 0.4 m above it) that is ~1% of the tilt, ~0.1 mm at the hand: what a linear C M0 left when
// fitted stretched out and used raised. Solved exactly (a 2x2 linear solve, then fixed-point
// steps): it equals MuJoCo's own equilibrium of such a plate to 1e-9 (mount_tilt_test.cc).
// `M0` is s x g and `g` gravity, both in the mount's axes; `J_theta_c` (optional) gets
// d theta_xy / d (c_x, c_y), for the compliance's uncertainty; `rotation` (optional) gets
// MountRotation(theta) from the solver's own sines and cosines (equal to it but for the last
// bit: two sincos calls fewer). Used by the identification and by EffectiveChain alike (the
// same bits).
Vec3 MountTilt(const Eigen::Vector2d& compliance, const Vec3& M0, const Vec3& first_moment,
               const Vec3& g, Eigen::Matrix2d* J_theta_c = nullptr, Mat3* rotation = nullptr);

// The mount's rotation for a tilt (theta_x, theta_y): a turn theta_y about y (the plate bending
// about its root line), then theta_x about the turned x (the plate twisting about its own long
// axis), R_y R_x, as a cantilevered plate deforms. Against a single Exp(theta) this differs by
// theta_x theta_y / 2 about z: 23 urad with the rover's arm stretched out (1.3 deg of pitch),
// which a fit of the linear model pushed into a 2% error of the roll compliance.
Mat3 MountRotation(const Vec3& theta);

// Gravity turned by a tilted mounting of the base (the identified gravity_tilt@base): phi_1
// about a_1 and phi_2 about a_2, the base's horizontal axes (normal to g: a_1 the base's x made
// normal to g, or its y where x lies along g; a_2 = (-g / |g|) x a_1; x and y for g along -z).
// The rotation is exact: Exp(phi_1 a_1 + phi_2 a_2) g = w_0 g + w_1 (a_1 x g) + w_2 (a_2 x g)
// with (w_0, w_1, w_2) = GravityTiltWeights (Rodrigues' formula, the axis normal to g). Loads
// are linear in g, so the identification combines loads computed once for g, a_1 x g and
// a_2 x g with these weights instead of recomputing them per parameter value.
void GravityTiltAxes(const Vec3& g, Vec3* a1, Vec3* a2);
Vec3 GravityTiltWeights(double phi1, double phi2);
Vec3 TiltedGravity(const Vec3& g, double phi1, double phi2);

// The axes normal to a joint's axis w that its tilt and lateral compliance turn about: a, the
// first of the frame's x, y not along w, made normal to w; b = w x a (frame coordinates).
void TiltAxes(const Vec3& w, Vec3* a, Vec3* b);

// The declared model at one joint reading with the effects applied: model() and q() are what an
// estimator's kinematics use instead of the declared model and the reading. Without effects
// (nullptr or empty) they are the declared model and the reading themselves.
class EffectiveChain {
 public:
  EffectiveChain(const PpoeModel& declared, const ModelEffects* effects);

  // Applies the effects at reading q_read. Does not allocate. Throws InputError on a reading of
  // the wrong size or with a NaN.
  void Update(const Eigen::Ref<const Eigen::VectorXd>& q_read);

  bool active() const { return effects_ != nullptr; }
  // Whether model()'s fixed parts change from one reading to the next (load-driven bending or
  // mount tilt); otherwise they were set once, at construction.
  bool varies() const { return last_varying_ > 0; }
  const PpoeModel& model() const { return effects_ ? effective_ : *declared_; }
  const PpoeModel& declared() const { return *declared_; }
  const Eigen::VectorXd& q() const { return q_; }
  // The gravity torque at the last reading of each joint with a torque-driven term (else 0).
  const Eigen::VectorXd& tau() const { return tau_; }

 private:
  void SetConstantLoads();
  void ComputeLoads(const Eigen::Ref<const Eigen::VectorXd>& q_read);
  void SubtreeLoads(const Eigen::Ref<const Eigen::VectorXd>& q_read);
  void CorrectFrames();
  lie::SE3 BentFixedPart(FrameId f);
  void SetConstantSources();
  void UpdateSources(const Eigen::Ref<const Eigen::VectorXd>& q_read);

  const PpoeModel* declared_;
  const ModelEffects* effects_;
  PpoeModel effective_;
  PpoeData nominal_;  // the declared chain at the reading (for the thermal source only)
  // The loads, in each frame's own coordinates (no base poses needed): constant per-frame and
  // subtree masses (payload included), set at construction.
  std::vector<Vec3> frame_first_;     // per frame: its own first moment
  std::vector<double> subtree_mass_;  // per frame: the mass of its subtree
  std::vector<char> loaded_;          // per frame: its subtree carries a mass
  std::vector<lie::SE3> rel_;         // per frame: T_parent_frame of the declared chain at q_read
  std::vector<Vec3> first_;           // per frame: its subtree's first moment about its origin
  std::vector<Vec3> gravity_;         // per frame: gravity in its axes
  FrameId last_rel_ = 0;              // rel_ is needed up to here
  FrameId last_gravity_ = 0;          // gravity_ is needed up to here
  std::vector<FrameId> varying_frames_;  // ModelEffects::FrameVaries, in increasing order
  std::vector<lie::SE3> static_;         // per frame: the fixed part without load-driven terms
  std::vector<Vec3> bend_;  // per frame: the link's bend (rotation vector, start's axes)
  std::vector<Eigen::Vector2d> lateral_moment_;  // per frame: M_a, M_b of its lateral compliance
  Mat3 mount_R_ = Mat3::Identity();              // the mount's tilt at the reading, MountRotation
  Eigen::Matrix2d J_mount_c_ = Eigen::Matrix2d::Zero();  // d mount tilt / d compliance
  // Parameter uncertainty (ModelEffects::Uncertainty) as PPOE sources.
  std::vector<Mat6> source_fixed_;   // per frame: declared source + the constant terms
  std::vector<char> source_varies_;  // per frame: a term changes with the reading
  std::vector<Vec6> bend_twist_;     // per frame: local twist of a unit bending compliance
  FrameId path_end_ = -1;            // the last frame on the path (carries the thermal term)
  bool sources_vary_ = false;
  Eigen::VectorXd q_, tau_;
  bool needs_loads_ = false;
  std::vector<char> torque_needed_;    // per joint: a term acts through its torque
  std::vector<char> harmonic_;         // per joint: a harmonic term is set
  std::vector<FrameId> joint_frames_;  // per joint: PpoeModel::joint_frame
  FrameId last_varying_ = 0;           // frames past it keep their fixed part
};

}  // namespace flexbench::kinematics
