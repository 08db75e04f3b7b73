// The truth: a MuJoCo model with effects switched on, commanded through position servos.
//
// Two models live here. The *nominal* model is the MJCF as written, with every passive
// compliance joint at its reference (qpos0) and coupled joints at qpos0: the rigid arm the
// declared kinematics describe. The *truth* is a copy that effects edit (stiffness, masses,
// geometry, gear springs); the joints of an effect that is off are held at qpos0, so with no
// effect the truth's poses equal the nominal ones bit for bit.
//
// Quasi-static settle (Settle) is a direct static solve: actuated joints held at their
// commanded angles, the released passive joints (and elastic gears) solved from
//   tau_spring(q) = g(q)      (g = MuJoCo's qfrc_bias at zero velocity)
// by damped Newton with a numeric Jacobian and a residual check. Dynamic runs (Step) use
// mj_step1/mj_step2 with the MJCF position servos plus gravity feed-forward; locked joints get a
// huge armature (the rigid limit) and are projected back to qpos0 after each step.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "sim/effects/effect.h"
#include "sim/effects/truth_setup.h"
#include "sim/model_catalog.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {

struct SettleOptions {
  double tolerance = 1e-9;  // largest |residual| accepted, Nm (N for slides)
  int max_iterations = 50;  // Newton iterations per backlash pass
};

struct SettleReport {
  int iterations = 0;     // Newton iterations, all passes
  double residual = 0.0;  // final max |residual|
  int free_dofs = 0;      // DoFs solved for
};

enum class FrameType { kSite, kCamera, kGeom, kBody };

// A named frame of the model: sites, cameras (optical frame: x right, y down, z forward), geoms
// and bodies, looked up in that order.
struct FrameRef {
  FrameType type = FrameType::kBody;
  int id = -1;
  std::string name;
};

class Simulation {
 public:
  // Takes the nominal model; `effects` are applied to the truth copy in order. Throws
  // InputError (model name + cause) for unsupported models or effects the model cannot carry.
  Simulation(MjModelPtr model, std::string model_name, const EffectList& effects = {});
  ~Simulation();
  Simulation(const Simulation&) = delete;
  Simulation& operator=(const Simulation&) = delete;

  // An MJCF, or a URDF with a position servo per joint (LoadTruthModel, sim/truth_model.h).
  static std::unique_ptr<Simulation> Load(const std::string& path, const EffectList& effects = {});
  static std::unique_ptr<Simulation> FromString(const std::string& xml, const std::string& name,
                                                const EffectList& effects = {});

  const std::string& model_name() const { return model_name_; }
  const ModelCatalog& catalog() const { return catalog_; }
  const mjModel* model() const { return truth_.get(); }  // truth
  // The truth model for renderers that fill textures (render::ApplyTagTextures); physics
  // parameters must not be changed through it.
  mjModel* mutable_model() { return truth_.get(); }
  const mjData* data() const { return data_.get(); }
  const mjModel* nominal_model() const { return nominal_.get(); }
  const TruthSetup& setup() const { return setup_; }
  const std::vector<std::string>& effect_names() const { return effect_names_; }

  // ---- Commands: motor-side angles of the actuated joints, in actuator order.
  const std::vector<std::string>& actuated_joints() const { return actuated_names_; }
  int num_actuated() const { return static_cast<int>(actuated_names_.size()); }
  void SetCommand(const Eigen::VectorXd& q_motor);
  void SetCommand(const std::string& joint, double q_motor);
  // The command sent at time t (on the simulation's clock; t <= time()), for a servo with a
  // delay (servo_delay): it acts on the command in force `delay` earlier, so a rollout started
  // mid-log is given the commands before its start.
  void SetCommandAt(double t, const Eigen::VectorXd& q_motor);
  const Eigen::VectorXd& command() const { return command_; }
  // Torque commands instead (a log of the motors' torques): from now on each actuated joint is
  // driven by `tau` (N m; N on a slide; actuator order) with its servo off, until the next
  // SetTorque, or a SetCommand switches the servos back on (Settle holds the joints at the
  // command: send one first). Gear springs and play are not modelled under torque; an
  // actuator with activation dynamics is not switched off.
  void SetTorque(const Eigen::VectorXd& tau);
  // The torque the motor of actuated joint i applied at its joint in the last step (the servo's
  // force and feed-forward, or the torque set), friction not included.
  double MotorTorque(int i) const;

  // ---- Rollouts from a recorded state: the clock at t, the actuated joints at q with velocity
  // qd (actuator order); every other DoF keeps its state. The commands sent before are forgotten:
  // send those a delayed servo still acts on again (SetCommandAt).
  void SetActuatedState(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd);

  // ---- Quasi-static equilibrium under gravity for the current command (direct solve). Leaves
  // the state at rest (qvel = 0). Throws SimulationError naming the model and the iteration when
  // the solve produces NaN or does not converge.
  SettleReport Settle(const SettleOptions& options = {});
  // ---- Dynamics: `steps` mj_step's towards the current command. Throws SimulationError naming
  // the model, the step and the time on NaN/Inf or MuJoCo's bad-qacc/qvel/qpos warnings.
  void Step(int steps = 1);
  // Steps until every |qvel| < velocity_tol; throws SimulationError when not at rest within
  // max_time_s. Returns the simulated time it took.
  double SettleDynamic(double max_time_s, double velocity_tol = 1e-6);
  double time() const { return data_->time; }
  double timestep() const { return truth_->opt.timestep; }
  long step_count() const { return steps_; }
  // True after Settle() until the next Step(): the arm is at rest (IMUs read pure gravity).
  bool at_rest() const { return at_rest_; }

  // ---- Ground truth of the current state.
  FrameRef Frame(const std::string& name) const;  // throws InputError naming the model
  Eigen::Isometry3d Pose(const FrameRef& frame) const;
  Eigen::Isometry3d Pose(const std::string& name) const { return Pose(Frame(name)); }
  Eigen::Isometry3d BodyPose(const std::string& body) const;
  Eigen::Isometry3d SitePose(const std::string& site) const;
  // Link-side joint position (qpos) and motor-side position: the command for joints with an
  // elastic or backlashed gear, the link position for rigid gears.
  double JointPosition(const std::string& joint) const;
  double JointPosition(int joint_id) const;
  double MotorPosition(int joint_id) const;
  // Angular velocity (rad/s) and specific force (m/s^2, +9.81 up at rest) of a site, in the
  // site frame.
  Vec3 SiteAngularVelocity(int site_id) const;
  Vec3 SiteSpecificForce(int site_id) const;

  // ---- Nominal (rigid) model.
  // Pose of a frame with the actuated joints at q (actuator order), every other joint at qpos0
  // but the linkages of the model's own mechanism (coupled joints no effect lists), which follow
  // their drivers. Writes the nominal model's scratch data (nominal_data_).
  Eigen::Isometry3d NominalPose(const FrameRef& frame, const Eigen::VectorXd& q) const;
  Eigen::Isometry3d NominalPose(const std::string& name, const Eigen::VectorXd& q) const {
    return NominalPose(Frame(name), q);
  }
  // Generalised gravity torque g(q) of the nominal model at actuated angles q (actuator order):
  // qfrc_bias at zero velocity (mj_rne, flg_acc = 0), restricted to the actuated DoFs. g is the
  // torque that holds the arm; gravity pulls the joints towards -g. A mechanism's linkage passes
  // its share to its drivers.
  Eigen::VectorXd GravityTorque(const Eigen::VectorXd& q) const;

  // ---- Effect state read by sensors.
  // The joint_offset effect's link - reading (0 without it): an encoder reads motor - offset.
  double JointOffset(int joint_id) const { return setup_.joint_offset.at(joint_id); }
  ImuBiasSpec ImuBias(const std::string& site) const;

 private:
  void ComputeStaticForces(const std::vector<int>& free_dofs, const Eigen::VectorXd& x,
                           Eigen::VectorXd* residual) const;
  void SetHeldPositions(const std::vector<int>& backlash_sign) const;
  // Steps of Settle, in call order; x_try and r_try are scratch vectors kept across passes.
  void SetGearReferences(const std::vector<int>& backlash_sign);
  void NominalStart(Eigen::VectorXd* x) const;
  Eigen::MatrixXd StaticJacobian(const Eigen::VectorXd& x, const Eigen::VectorXd& r,
                                 Eigen::VectorXd* x_try, Eigen::VectorXd* r_try) const;
  void DampedNewtonStep(double err, int iteration, Eigen::VectorXd* x, Eigen::VectorXd* r,
                        Eigen::VectorXd* x_try, Eigen::VectorXd* r_try) const;
  void SolveFreeJoints(const SettleOptions& options, Eigen::VectorXd* x, Eigen::VectorXd* r,
                       Eigen::VectorXd* x_try, Eigen::VectorXd* r_try, SettleReport* report) const;
  bool PickBacklashFlanks(std::vector<int>* backlash_sign) const;
  void ComeToRest();
  void ApplyServo() const;
  // The nominal model's qpos (nominal_data_) at actuated angles q: qpos0 elsewhere, the
  // mechanism's linkages following their drivers.
  void SetNominalQpos(const Eigen::VectorXd& q) const;
  void ProjectLocked() const;
  void PushCommandHistory(double t);
  void ClearCommandHistory();
  double DelayedCommand(int i, double delay) const;
  void EnsureKinematics() const;
  // Whether the data's position and velocity stages are those of its current state (forward_key_).
  bool ForwardIsCurrent() const;
  void EnsureAccelerations() const;
  void CheckStep(double time_before) const;

  std::string model_name_;
  MjModelPtr nominal_;
  MjModelPtr truth_;
  MjDataPtr data_;
  // Scratch of the nominal model's queries (NominalPose, GravityTorque): each call sets every
  // qpos it reads, so nothing carries from one call to the next and the queries stay const; but
  // two threads may not query one Simulation at once.
  mutable MjDataPtr nominal_data_;
  ModelCatalog catalog_;
  TruthSetup setup_;
  std::vector<std::string> effect_names_;
  std::vector<std::string> actuated_names_;
  void CheckPerActuated(const Eigen::VectorXd& v, const char* what) const;
  Eigen::VectorXd command_;
  bool torque_mode_ = false;
  Eigen::VectorXd torque_;               // SetTorque's, actuator order
  mutable Eigen::VectorXd feedforward_;  // the servos' qfrc_applied of the last step
  // Commands sent and when, from history_begin_ on (kept only when a servo has a delay).
  double max_delay_ = 0.0;
  std::vector<double> history_t_;
  std::vector<double> history_q_;  // num_actuated() per entry
  size_t history_begin_ = 0;
  std::vector<double> gear_reference_;   // per actuated joint: unloaded gear-spring position
  std::vector<int> locked_joints_;       // held at qpos0 (effects off)
  std::vector<int> free_joints_;         // solved in Settle: released passive + elastic gears
  std::vector<int> released_linkages_;   // coupled joints that follow their drivers
  std::vector<int> mechanism_linkages_;  // coupled joints no effect claims: in the nominal too
  mutable std::vector<double> slopes_;   // CoupledValue's scratch
  long steps_ = 0;
  bool at_rest_ = false;
  mutable bool kinematics_current_ = false;
  mutable bool accelerations_current_ = false;
  mutable std::vector<mjtNum> warmstart_;  // EnsureAccelerations' scratch
  // The state (qpos, qvel, act, time) EnsureAccelerations last computed positions and velocities
  // at: a step from that same state skips step1's stages (ForwardIsCurrent). Empty: none.
  mutable std::vector<mjtNum> forward_key_;
  mutable int warning_counts_[mjNWARNING] = {};
};

}  // namespace flexbench::sim
