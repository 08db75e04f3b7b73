// Candidate effects a declared model may lack, each with a physical location and a parametric
// form, and the kinematics of the declared chain augmented by any subset of them.
//
// The declared chain is the nominal PPOE chain ([PPOE eqs. 16-17], all sources at their
// mean). An effect perturbs it at its location:
//   joint_offset@J        q_J += a                                  a [rad]
//   joint_compliance@J    q_J += c * tau_J(q)                       c [rad/(N m)] (gear elasticity)
//   backlash@J            q_J += b * s, s the sign of the joint's last motion where the data
//                         records it (CSV `motion_J`), else sign(tau_J(q))  b [rad] (half the play)
//   link_length@F         t_F += l * t_F / |t_F|                    l [m]
//   link_offset@F         t_F += d (3-D, parent coordinates)        d [m] (machining, assembly)
//   joint_axis_tilt_a@J   rotation about a, the first of J's frame axes not along J's axis
//   joint_axis_tilt_b@J   rotation about b = w x a; both before the joint moves [rad] (bearing
//                         misalignment; two candidates, since data often sees only one)
//   lateral_compliance@J  J's frame turns, before J moves, about a and b (joint_axis_tilt's
//                         axes) by kappa_a M_a(q) and kappa_b M_b(q), M the moment of the
//                         weight beyond J about J's anchor in J's pre-motion axes: bearing and
//                         housing compliance (Tenhumberg & Bauml 2021, kappa_alpha and
//                         kappa_beta)                         kappa_a, kappa_b [rad/(N m)]
//   link_bending@J        the link from the previous joint to J turns by c * M_perp(q) about
//                         its middle (Euler-Bernoulli beam under an end moment: the tip
//                         turns like a hinge at mid-length)              c [rad/(N m)]
//   base_compliance@J1    rotation theta = C (M0 + S theta) about the first joint's anchor (the
//                         plate under the arm tilts, the load's moment taken at the tilted
//                         pose: kinematics::MountTilt), frame axes before the joint turns
//                         C = diag(c_x, c_y) [rad/(N m)]
//   thermal_expansion@all every link translation scaled by (1 + e)  e [-] (alpha * delta T)
//   payload@ee            a mass m [kg] with its centre at offset c from the end effector (its
//                         frame); parameters (m, m c) [kg, kg m] keep the loads linear in them
//   camera_offset@C       the camera's pose T_base_cam Exp(xi), xi = [rho; theta] [m, rad]
//                         (extrinsic calibration error; only with pixel observations)
//   transmission_error@J  q_J += a1 cos q + b1 sin q + a2 cos 2q + b2 sin 2q   [rad] (strain-wave
//                         gearing: 1 and 2 cycles per revolution; amplitude and phase as
//                         cos/sin coefficients, so the fit is linear in them; needs_evidence)
//   joint_error_curve@J   q_J += sum_{h=1..3} a_h cos hq + b_h sin hq   [rad] (the generic
//                         fallback for an angle-dependent error; needs_evidence; never named as
//                         the equivalent of a narrower family)
//   stiffening_spring@J   q_J += c1 tau + c3 tau^3 / tau0^2, tau0 = kinematics::kStiffeningTau0Nm
//                         [rad/(N m)] (a gear
//                         spring whose stiffness grows with deflection: c1 = -1/k1 <= 0 and the
//                         cubic term takes some deflection back, c3 >= 0; needs_evidence)
//   joint_origin@J        J's fixed transform T_parent_ip becomes T_parent_ip Exp(xi), xi =
//                         [rho; theta] [m, rad], before the joint moves: any geometric error of
//                         the joint's placement (complete geometry, as the MUKCa authors
//                         calibrate; generic_geometry: chosen after the named effects)
//   gravity_tilt@base     gravity turned by phi_1, phi_2 about the base's horizontal axes (a
//                         base mounted tilted; kinematics::TiltedGravity)   [rad]. It acts
//                         only through the loads of the load-driven effects, so it is
//                         unidentifiable until one of them is in the model. A candidate only
//                         when asked for (EffectModel's `gravity_tilt`); its columns are central
//                         differences (HasTangent)
// Physical bounds (Candidate::lower/upper; a fit outside them is not accepted), units and value
// counts: the effect table's rows (estimators/kinematics/effect_table.cc, with their reasons).
// Signs: tau_J is the torque the joint must hold against gravity (MuJoCo's qfrc_bias at rest),
// so a gear spring of stiffness k fits as c = -1/k and a play resting on the loaded flank as
// b = -play/2; moments M are those of the weight itself, so plates and links that sag fit with
// c > 0. The fit leaves every sign free.
// Coupled joints (sim::DeclaredChain::couplings) are joint variables like the actuated ones, with
// their own candidates (their own offset is the linkage's assembly offset: a parameter of its
// own), but no lateral compliance: a linkage's joint has no bearing of its own to bend. Nor has
// the first joint on a compliant mount one (its housing tilting is base_compliance);
// EffectModel::skipped() lists both. A joint-level correction of a driver (offset, compliance,
// backlash, periodic errors) moves the joints it drives as well, as the driver's true angle
// drives the linkage.
// tau_J is the gravity torque the joint carries (MuJoCo masses, nominal configuration), M the
// moment of the weight beyond a point, in the local frame. Loads are computed once per
// configuration; a model without masses gives zero loads, and the load-driven candidates are
// then unidentifiable (reported, never fitted).
#pragma once
#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <string>
#include <vector>

#include "estimators/kinematics/effect_table.h"
#include "estimators/kinematics/ppoe_data.h"
#include "estimators/kinematics/ppoe_model.h"
#include "sim/declared_chain.h"
#include "sim/mujoco_model.h"

namespace flexbench::identify {

using kinematics::FrameId;

// The effect families are the rows of kinematics' effect table.
using EffectType = kinematics::EffectKind;

const char* ToString(EffectType type);

struct Candidate {
  EffectType type = EffectType::kJointOffset;
  std::string location;  // joint, frame or "all" / "ee"
  int q_index = -1;      // joint effects
  FrameId frame = -1;    // frame effects
  int num_params = 1;
  double step = 1e-6;  // finite-difference step of each parameter
  std::string unit;
  int axis = 0;  // joint_axis_tilt: 0 = a, 1 = b
  // Enters selection only when the residual diagnostics point at its joint.
  bool needs_evidence = false;
  // Can represent any geometric error at its location; chosen after the named effects.
  bool generic_geometry = false;
  // Chosen after the named effects (and what their diagnostics let in), before complete
  // geometry: a lateral axis can be the axis of the joint before it through the same point (a
  // shoulder's roll joint turned about the pitch axis is the pitch joint turning), so where a
  // named family explains the data as well it is the one chosen.
  bool after_named = false;
  // Physical bounds per parameter (empty: none); a fit outside them is not accepted.
  std::vector<double> lower, upper;
  std::string Name() const { return kinematics::FileName(type, axis) + "@" + location; }
};

// The parts of ConfigLoads that are linear in gravity, for one gravity vector.
struct GravityTerms {
  Eigen::VectorXd tau, tau_unit;
  Eigen::Matrix2Xd M_lat, M_lat_unit;
  std::vector<Vec3> M_mid, M_mid_unit;
  Vec3 M_mount = Vec3::Zero(), M_mount_unit = Vec3::Zero(), g_mount = Vec3::Zero();
  Mat3 M_first = Mat3::Zero();
};

// Gravity loads of one configuration (nominal model), in the frames the effects act in.
struct ConfigLoads {
  Eigen::VectorXd tau;  // per PPOE joint variable, N m
  // Per joint variable: the moment about its anchor of the weight beyond it, about its lateral
  // axes a and b (pre-motion), N m.
  Eigen::Matrix2Xd M_lat;
  // Per link that can bend (a joint frame a link's length after the previous joint; the
  // EffectModel numbers them): the moment at the link's middle, start joint axes.
  std::vector<Vec3> M_mid;
  Vec3 M_mount = Vec3::Zero();  // about the first joint's anchor, its pre-motion axes
  // The same quantities for 1 kg at the end effector (payload sensitivity).
  Eigen::VectorXd tau_unit;
  Eigen::Matrix2Xd M_lat_unit;
  std::vector<Vec3> M_mid_unit;
  Vec3 M_mount_unit = Vec3::Zero();
  // Moment (base axes) per unit first moment m c of the payload about the end effector (ee
  // axes): the same at every point, as a couple. With the axes to carry it into each load.
  Mat3 M_first = Mat3::Zero();
  Eigen::Matrix3Xd axis_base;               // joint axes, base coordinates
  Eigen::Matrix3Xd lat_a_base, lat_b_base;  // joint lateral axes a, b, base coordinates
  std::vector<Mat3> R_mid_T;                // base -> start-joint axes, per link that can bend
  Mat3 R_mount_T = Mat3::Identity();
  // For the mount's tilted equilibrium (kinematics::MountTilt), mount axes: the first moment of
  // its load about the pivot, the same of 1 kg at the end effector, the end effector's axes
  // (to carry a payload's first moment there) and gravity.
  Vec3 s_mount = Vec3::Zero();
  Vec3 s_mount_unit = Vec3::Zero();
  Mat3 R_mount_point = Mat3::Identity();
  Vec3 g_mount = Vec3::Zero();
  // Per joint: the sign of its last motion (+1, -1; 0 unknown), from the data.
  Eigen::VectorXd motion_sign;
  // The chain's poses at `q_nominal` without effects, per frame on the predicted path (for
  // identification on many rows): PredictPose copies the frames before the first one its effects
  // touch instead of recomputing them (the same operations, the same bits). Empty: not cached.
  Eigen::VectorXd q_nominal;
  std::vector<lie::SE3> T_nominal;
  // Where the gravity_tilt candidate exists (and the model has masses): the gravity-linear
  // loads for gravity along a_1 x g and a_2 x g (kinematics::GravityTiltAxes), which the
  // tilt's weights combine with the loads above (EffectModel::TiltedLoads). Else empty.
  std::vector<GravityTerms> horizontal;
};

// The augmented kinematics. Constant after construction; Predict needs a Workspace.
class EffectModel {
 public:
  // `point_frame`: the chain frame whose origin is predicted (the end effector). `camera`: the
  // name of a camera that observes it in pixels ("" for none), for the camera_offset candidate.
  // `more_points`: further measured frames (markers on other branches of a tree); the
  // candidates then cover every joint on the way to any of them, each point gets its tool
  // link_offset, and a prediction names its point (index into points(), 0: point_frame).
  // `gravity_tilt`: add the gravity_tilt candidate (last, so the others keep their indices).
  EffectModel(const mjModel* m, const sim::DeclaredChain& chain, FrameId point_frame,
              const std::string& camera = "", const std::vector<FrameId>& more_points = {},
              bool gravity_tilt = false);

  // The effects a declared file already carries (its identified_effects): applied under every
  // prediction, loads and tangent, with the candidates acting on top of them (a candidate's
  // value adds to the same one's here, as ModelEffects sums repeated effects). Returns the names
  // of those that are no candidate of this model (they move no measured point: off the chain to
  // every point, or a camera that is not observed); the caller says so. Throws InputError
  // (the entry's file and line) on a wrong number of values.
  std::vector<std::string> SetBaseEffects(const std::vector<sim::IdentifiedEffect>& effects);
  const std::vector<int>& base_effects() const { return base_; }
  const Eigen::VectorXd& base_theta() const { return base_theta_; }

  const kinematics::PpoeModel& chain() const { return chain_->model; }
  const std::vector<Candidate>& candidates() const { return candidates_; }
  // Candidates a family cannot offer at a location, with the reason ("lateral_compliance@J":
  // "J is a coupled joint ...").
  struct Skipped {
    std::string name, reason;
  };
  const std::vector<Skipped>& skipped() const { return skipped_; }
  int FindCandidate(const std::string& name) const;  // -1 when absent
  FrameId mount() const { return mount_; }
  const std::vector<FrameId>& points() const { return points_; }
  bool has_masses() const { return has_masses_; }
  // MuJoCo's gravity in the declared base frame (m/s^2), the base at its qpos0 pose.
  const Vec3& g_base() const { return g_base_; }

  ConfigLoads Loads(const Eigen::VectorXd& q) const;
  // The loads of the arm standing at q_load, for predictions at reading q (the nominal poses
  // cached at q). The weight acts where the arm is: at the reading corrected by the joint-level
  // kinematic effects (a 0.4 deg encoder offset at j2 moves the centre of mass, and
  // the compliant mount's tilt with it, by ~1% of the tilt: 39-69 um at a raised hand).
  ConfigLoads Loads(const Eigen::VectorXd& q, const Eigen::VectorXd& q_load) const;
  // The joint-level kinematic correction of `active` at reading q (offsets, periodic errors):
  // the reading -> joint angle map's part that does not depend on the load.
  Eigen::VectorXd ReadingShift(const Eigen::VectorXd& q, const std::vector<int>& active,
                               const double* theta) const;
  // Whether `active` moves the loads: a kinematic joint correction beside a load-driven effect.
  bool LoadsShift(const std::vector<int>& active) const;
  // Loads(q, q + ReadingShift(q, active, theta)) where LoadsShift, else Loads(q): the loads a
  // prediction of (active, theta) at reading q uses, as kinematics::EffectiveChain computes them.
  ConfigLoads LoadsFor(const Eigen::VectorXd& q, const std::vector<int>& active,
                       const double* theta) const;

  // A frame's step under the effects' terms (ChainPoses' touched-frame step, intermediates
  // kept; FrameStages):
  // L2 = (R_p, t) Exp(origin) and L4 (with the bend and the mount's turn) relative to the
  // parent, T2, T4, T5 in the base frame, the tilt's and the mount's rotations, the bend's
  // rotation vector (base axes) and pivot.
  struct Stages {
    lie::SE3 L2, L4, T2, T4, T5;
    Mat3 R_mount = Mat3::Identity(), R_tilt = Mat3::Identity();
    Vec3 phi = Vec3::Zero(), mid = Vec3::Zero();
  };
  struct LoadScratch;  // Workspace::load_scratch (effect_model.cc)
  struct Workspace {
    Eigen::VectorXd dq;
    std::vector<double> dlen;
    std::vector<Vec3> bend;
    std::vector<Vec3> offset;
    std::vector<Vec3> tilt;
    std::vector<Vec6> origin;
    std::vector<lie::SE3> T;
    std::vector<Vec3> y;  // PoseTangents: the point in each frame's coordinates before its joint
                          // moves (T5 of its step)
    std::vector<char> touched;  // PoseTangents: whether the frame's step is ChainPoses' touched one
    std::vector<Stages> stages;  // PoseTangents: a touched frame's stages
    // Chain-wide terms of the last AccumulateTerms (payload, its couple in base axes, thermal
    // strain, the mount's rotation vector).
    double payload = 0.0;
    Vec3 couple = Vec3::Zero();
    double scale = 0.0;
    Vec3 mount_rot = Vec3::Zero();
    // d mount_rot_xy / d (c_x, c_y) where a base compliance is active (kinematics::MountTilt).
    bool mount_active = false;
    Eigen::Matrix2d mount_J = Eigen::Matrix2d::Zero();
    FrameId point = -1;  // the predicted point frame of the current call
    ConfigLoads tilted;  // TiltedLoads' result where a gravity tilt is active
    // RowLoads: a row's loads computed in a pass, and their scratch (the arm's poses, its own
    // MuJoCo data, the gravity terms), kept between rows so that the next allocates nothing.
    ConfigLoads row_loads;
    std::unique_ptr<LoadScratch, void (*)(LoadScratch*)> load_scratch{nullptr, nullptr};
  };
  Workspace MakeWorkspace() const;
  // LoadsFor(q, active, theta) into ws.row_loads without the nominal poses (a prediction computes
  // them), on ws's own MuJoCo data: for a pass over rows whose loads are not kept (RowLoads), on
  // any thread.
  ConfigLoads& LoadsFor(const Eigen::VectorXd& q, const std::vector<int>& active,
                        const double* theta, Workspace& ws) const;

  // Position of the point frame in the base frame, with effects `active` (indices into
  // candidates()) at parameters `theta` (concatenated in that order).
  Vec3 Predict(const Eigen::VectorXd& q, const ConfigLoads& loads, const std::vector<int>& active,
               const double* theta, Workspace& ws, int point = 0) const {
    return PredictPose(q, loads, active, theta, ws, point).translation();
  }
  // The point frame's pose (its orientation for pose observations); `point` indexes points().
  lie::SE3 PredictPose(const Eigen::VectorXd& q, const ConfigLoads& loads,
                       const std::vector<int>& active, const double* theta, Workspace& ws,
                       int point = 0) const;

  // A first-order change of the point frame's pose (base frame): d R = [w]x R, and d p.
  struct Tangent {
    Vec3 w = Vec3::Zero();
    Vec3 dp = Vec3::Zero();
  };
  // Whether PoseTangents' analytic derivatives cover every parameter of candidate c with the
  // effects `active` in the model (c itself may be active or not). Not covered (the caller
  // differentiates numerically): thermal expansion, payload and gravity tilt (they act on every
  // frame or load), the camera offset (not on the chain), and a translation or joint origin on a
  // link that an active link_bending turns (the bend's pivot moves with it).
  bool HasTangent(int c, const std::vector<int>& active) const;
  // PredictPose, and the derivative of the point frame's pose with respect to each parameter
  // k of candidate cs[i] (its value adds to any active one's; derivatives at theta) in
  // out[offset(i) + k], offsets being the running sum of num_params. Every cs[i] must pass
  // HasTangent(cs[i], active). Allocates nothing.
  lie::SE3 PoseTangents(const Eigen::VectorXd& q, const ConfigLoads& loads,
                        const std::vector<int>& active, const double* theta,
                        const std::vector<int>& cs, Workspace& ws, Tangent* out,
                        int point = 0) const;

 private:
  // The constructor's steps: the measured points and the frames on their way (points_,
  // on_path_); the first joint on that way (-1: none); whether frame f is f or an ancestor of
  // every point; the mount; each joint's tilt axes.
  void SetPoints(const std::vector<FrameId>& more_points);
  FrameId FirstJointOnPath() const;
  bool AboveEveryPoint(FrameId f) const;
  void FindMount();
  void SetTiltAxes();
  // A candidate at the end of candidates_, with its family's bounds (for more fields).
  Candidate& AddCandidate(EffectType type, const std::string& location, int q, FrameId f);
  // The candidates family by family, in candidates_' order: per joint (offset, tilts, link
  // offset, compliance, backlash), link lengths, link bending (with prev_joint_, link_dir_), the
  // tools' offsets, the chain-wide ones (base compliance, thermal expansion, camera, payload),
  // those that need evidence, the joint origins.
  void AddJointFamilies();
  void AddLinkLengths();
  void AddLinkBending();
  void AddToolOffsets();
  void AddChainWide(const std::string& camera);
  void AddLateralCompliance();
  // Whether joint frame f is the mount or the first joint below it: its lateral turn is then
  // the mount's tilt (base_compliance), about the same point within the mount's offset.
  bool TiltsWithMount(FrameId f) const;
  void AddEvidenceFamilies();
  void AddJointOrigins();
  void FindCoupledDrivers();  // drives_coupled_
  // L's loads under the active gravity tilt (in ws.tilted, without the cached poses), or L
  // itself when none is active.
  const ConfigLoads& TiltedLoads(const ConfigLoads& L, const std::vector<int>& active,
                                 const double* theta, Workspace& ws) const;
  // PredictPose in three steps: the per-frame terms of `active` into ws, the chain's poses
  // ws.T under them, and the terms back to zero.
  void AccumulateTerms(const Eigen::VectorXd& q, const ConfigLoads& L,
                       const std::vector<int>& active, const double* theta, Workspace& ws) const;
  // AccumulateTerms' steps: the payload's terms, then each active effect's.
  struct ChainTerms;
  void PayloadTerms(const ConfigLoads& L, const std::vector<int>& active, const double* theta,
                    ChainTerms* ct) const;
  void AddTerms(const Candidate& c, const Eigen::VectorXd& q, const ConfigLoads& L, const double* t,
                ChainTerms* ct, Workspace& ws) const;
  void ChainPoses(const Eigen::VectorXd& q, const ConfigLoads& L, Workspace& ws) const;
  // ChainPoses' step of a frame the effects touch (Touched).
  void TouchedStep(FrameId f, const Eigen::VectorXd& q, Workspace& ws) const;
  void ClearTerms(const std::vector<int>& active, Workspace& ws) const;
  // Loads' steps: the zero loads and the nominal poses at q; the arm standing at q_load; the
  // centre of mass of body b's subtree (base coordinates) and the moment of its weight about
  // a under gravity g; the gravity-linear loads under g into t, the geometry into L, per
  // joint torque, link middle and mount.
  struct LoadPose;
  void InitLoads(const Eigen::VectorXd& q, bool nominal_poses, ConfigLoads* L) const;
  void StandAt(const Eigen::VectorXd& q_load, mjData* d, LoadPose* P) const;
  // Loads(q, q_load) into L through the scratch `s` (its buffers reused).
  void FillLoads(const Eigen::VectorXd& q, const Eigen::VectorXd& q_load, bool nominal_poses,
                 LoadScratch* s, ConfigLoads* L) const;
  LoadScratch* ScratchOf(Workspace& ws) const;
  Vec3 SubtreeCom(const LoadPose& P, int b) const;
  Vec3 SubtreeMoment(const LoadPose& P, int b, const Vec3& a, const Vec3& g) const;
  void GravityLoads(const LoadPose& P, const Vec3& g, GravityTerms* t, ConfigLoads* L) const;
  void JointTorques(const LoadPose& P, const Vec3& g, GravityTerms* t, ConfigLoads* L) const;
  void MidMoments(const LoadPose& P, const Vec3& g, GravityTerms* t, ConfigLoads* L) const;
  void MountLoads(const LoadPose& P, const Vec3& g, GravityTerms* t, ConfigLoads* L) const;
  // The load a load-driven effect at joint k answers to (tau_J with the payload's share).
  double JointLoad(const ConfigLoads& L, int k, const Workspace& ws) const;
  // The rotation vector (frame f's pre-motion axes) of lateral compliances kappa at joint
  // variable k under the loads L with the payload's share.
  Vec3 LateralTurn(const ConfigLoads& L, int k, FrameId f, const double* kappa, double payload,
                   const Vec3& couple) const;
  // How many active link_bendings turn a link that frame f lies on: the bend's pivot (the
  // link's middle) moves when f's translation does (`at_bend`: f's own bend counts too).
  int BendsOnLink(FrameId f, const std::vector<int>& active, bool at_bend) const;
  // The path frame whose nonzero bend's pivot moves with frame f (f itself or a frame below it
  // on f's link), -1 when none.
  FrameId PivotBend(FrameId f, const Workspace& ws) const;
  // out[0, n): tangents of a parameter at frame f taken with the bend at frame b held rigid,
  // made exact: the bend turns about the link's middle, which moves by half as much.
  void ThroughBend(FrameId f, FrameId b, const Workspace& ws, int n, Tangent* out) const;
  Stages FrameStages(FrameId f, const Workspace& ws) const;
  // Whether ChainPoses takes frame f's touched-frame step.
  bool Touched(FrameId f, const Workspace& ws) const;
  // ws.y: the point in each path frame's T5 coordinates, from the point frame up to frame `top`
  // (the steps below in their own coordinates: structural zeros stay exact); ws.touched.
  void PointInFrames(const Eigen::VectorXd& q, FrameId top, Workspace& ws) const;
  // Whether frame a is f or one of f's ancestors (a candidate there moves f).
  bool MovesFrame(FrameId a, FrameId f) const;
  // The tangents of candidate c's parameters at the terms in ws (PointInFrames done).
  void CandidateTangents(const Candidate& c, const Eigen::VectorXd& q, const ConfigLoads& L,
                         const Workspace& ws, Tangent* out) const;
  // CandidateTangents' steps: the stages of c's frame (those PointInFrames kept, else built in
  // *local), and the tangents per family: joint-level corrections (their joint moving, T5 the
  // frame's pose before it does), the mount's tilt (T4, y4: the mount stage and the point
  // there), a bend, a link's length or offset.
  const Stages& TangentStages(const Candidate& c, const Workspace& ws, Stages* local) const;
  void JointTangents(const Candidate& c, const Eigen::VectorXd& q, const ConfigLoads& L,
                     const Workspace& ws, const lie::SE3& T5, Tangent* out) const;
  void BaseComplianceTangents(const ConfigLoads& L, const Workspace& ws, const lie::SE3& T4,
                              const Vec3& y4, Tangent* out) const;
  void LinkBendingTangent(FrameId f, const ConfigLoads& L, const Workspace& ws, const Stages& st,
                          Tangent* out) const;
  void TranslationTangents(const Candidate& c, const Workspace& ws, Tangent* out) const;

  // Calls f(candidate index, its parameters) for the base effects, then for `active`.
  template <typename F>
  void ForEachEffect(const std::vector<int>& active, const double* theta, F&& f) const;

  const sim::DeclaredChain* chain_;
  std::vector<int> base_;       // SetBaseEffects: candidate indices
  Eigen::VectorXd base_theta_;  // and their parameters, concatenated
  FrameId point_frame_;
  std::vector<FrameId> points_;  // point_frame_, then the further measured frames
  FrameId mount_ = 0;
  bool has_masses_ = false;
  std::vector<Candidate> candidates_;
  std::vector<Skipped> skipped_;
  Vec3 g_base_ = Vec3::Zero();
  int gravity_tilt_ = -1;              // the gravity_tilt candidate, -1 without one
  std::vector<char> drives_coupled_;   // per joint variable: it drives a coupled joint
  std::vector<char> on_path_;          // frames between the base and the point frame
  std::vector<Vec3> tilt_a_, tilt_b_;  // per joint frame: unit normals of its axis
  std::vector<FrameId> prev_joint_;    // per joint frame: the joint at its link's start, or -1
  std::vector<int> mid_slot_;          // per frame with a prev_joint_: its link's loads entry
  int num_mid_ = 0;                    // links with a prev_joint_
  std::vector<Vec3> link_dir_;         // that link's direction in the start joint's frame
  // MuJoCo bodies behind each chain frame (-1: none) for loads.
  std::vector<int> frame_body_;
  const mjModel* m_;
  mutable sim::MjDataPtr d_;  // scratch for Loads (not thread-safe, like the rest of a model)
};

}  // namespace flexbench::identify
