#include "sim/simulation.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <set>
#include <stdexcept>
#include <tuple>

#include "estimators/error.h"
#include "estimators/format.h"
#include "sim/camera.h"
#include "sim/truth_model.h"

namespace flexbench::sim {
namespace {

// Armature added to the DoF of a locked joint in dynamic runs: the rigid limit (its
// acceleration vanishes, the other DoFs see the locked dynamics); the joint is also projected
// back to qpos0 after every step.
constexpr double kLockArmature = 1e6;
// Finite-difference step of the static solve's Jacobian (rad or m).
constexpr double kJacobianStep = 1e-7;
// A load below this (Nm) does not pick a backlash flank.
constexpr double kBacklashLoadEps = 1e-9;
constexpr int kMaxBacklashPasses = 8;

// MuJoCo prints its first warning of each kind through mju_user_warning (and writes
// MUJOCO_LOG.TXT by default). While a thread steps, keep the text for our error message instead.
// The handler is global and rollouts step on several threads, so it is installed once and reads
// a per-thread sink; with none it does what MuJoCo does without a handler.
thread_local std::string* g_step_warning = nullptr;
void (*g_previous_warning)(const char*) = nullptr;
void CaptureWarning(const char* msg) {
  if (g_step_warning) {
    *g_step_warning = msg;
  } else if (g_previous_warning) {
    g_previous_warning(msg);
  } else {
    mju_writeLog("WARNING", msg);
    std::printf("WARNING: %s\n\n", msg);
  }
}
struct StepWarningScope {
  explicit StepWarningScope(std::string* sink) : previous(g_step_warning) {
    static std::once_flag installed;
    std::call_once(installed, [] {
      g_previous_warning = mju_user_warning;
      mju_user_warning = CaptureWarning;
    });
    g_step_warning = sink;
  }
  ~StepWarningScope() { g_step_warning = previous; }
  std::string* previous;
};

double DeadZone(double x, double half_width) {
  if (x > half_width) return x - half_width;
  if (x < -half_width) return x + half_width;
  return 0.0;
}

Eigen::Isometry3d MakePose(const mjtNum* pos, const mjtNum* mat) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = RotFromRowMajor(mat);
  T.translation() = Vec3(pos[0], pos[1], pos[2]);
  return T;
}

Eigen::Isometry3d FramePoseIn(const mjData* d, const FrameRef& f) {
  switch (f.type) {
    case FrameType::kSite:
      return MakePose(d->site_xpos + 3 * f.id, d->site_xmat + 9 * f.id);
    case FrameType::kCamera:
      return WorldFromOptical(d, f.id);
    case FrameType::kGeom:
      return MakePose(d->geom_xpos + 3 * f.id, d->geom_xmat + 9 * f.id);
    case FrameType::kBody:
      return MakePose(d->xpos + 3 * f.id, d->xmat + 9 * f.id);
  }
  return Eigen::Isometry3d::Identity();
}

}  // namespace

Simulation::Simulation(MjModelPtr model, std::string model_name, const EffectList& effects)
    : model_name_(std::move(model_name)), nominal_(std::move(model)) {
  const mjModel* nm = nominal_.get();
  catalog_ = ModelCatalog::Build(nm, model_name_);
  truth_.reset(mj_copyModel(nullptr, nm));
  mjModel* m = truth_.get();
  setup_ = NominalSetup(m, &catalog_, model_name_);
  std::set<std::string> seen;
  for (const auto& effect : effects) {
    // Under its former name an effect is still the same effect: given twice it would apply twice.
    const std::string canonical = CanonicalEffectName(effect->name());
    if (!seen.insert(canonical.empty() ? effect->name() : canonical).second) {
      throw InputError(effect->where() + ": effect '" + effect->name() + "' given twice" +
                       (canonical != effect->name() ? " (it is '" + canonical + "')" : ""));
    }
    effect->Apply(setup_);
    effect_names_.push_back(effect->name());
  }
  if (setup_.constants_changed) {
    MjDataPtr tmp = MakeData(m);
    mj_setConst(m, tmp.get());
  }
  for (const JointEntry& j : catalog_.joints) {
    const bool released = setup_.released[j.id] != 0;
    if (j.role == JointRole::kCoupled) {
      m->eq_active[j.coupling_eq] = released ? 1 : 0;
      for (int k : j.drivers) {
        const JointEntry& driver = catalog_.Joint(k);
        if (released && driver.role != JointRole::kActuated) {
          throw InputError(model_name_ + ": coupled joint '" + j.name + "' follows '" +
                           driver.name +
                           "', which is not actuated (only actuated drivers are supported)");
        }
      }
    }
    if (j.role == JointRole::kCoupled && released) released_linkages_.push_back(j.id);
    if (j.role == JointRole::kCoupled && j.effect.empty()) mechanism_linkages_.push_back(j.id);
    if (j.role != JointRole::kActuated && !released) locked_joints_.push_back(j.id);
    if (j.role == JointRole::kPassive && released) free_joints_.push_back(j.id);
    if (j.role == JointRole::kActuated && setup_.gear[j.id].stiffness > 0) {
      free_joints_.push_back(j.id);
    }
  }
  for (int j : locked_joints_) m->dof_armature[m->jnt_dofadr[j]] += kLockArmature;
  actuated_names_ = catalog_.ActuatedNames();
  data_ = MakeData(m);
  nominal_data_ = MakeData(nm);
  command_.resize(num_actuated());
  for (int i = 0; i < num_actuated(); ++i) {
    command_[i] = m->qpos0[m->jnt_qposadr[catalog_.actuated[i]]];
    max_delay_ = std::max(max_delay_, setup_.servo_delay[catalog_.actuated[i]]);
  }
  mj_forward(m, data_.get());
  kinematics_current_ = true;
}

Simulation::~Simulation() = default;

std::unique_ptr<Simulation> Simulation::Load(const std::string& path, const EffectList& effects) {
  return std::make_unique<Simulation>(LoadTruthModel(path), path, effects);
}

std::unique_ptr<Simulation> Simulation::FromString(const std::string& xml, const std::string& name,
                                                   const EffectList& effects) {
  return std::make_unique<Simulation>(LoadModelFromString(xml, name), name, effects);
}

// ---------------------------------------------------------------- commands

// A vector given per actuated joint (`what`: command, torque) must have one value for each.
void Simulation::CheckPerActuated(const Eigen::VectorXd& v, const char* what) const {
  if (v.size() != num_actuated()) {
    throw std::invalid_argument(model_name_ + ": " + what + " has " + std::to_string(v.size()) +
                                " values for " + std::to_string(num_actuated()) +
                                " actuated joints");
  }
}

void Simulation::SetCommand(const Eigen::VectorXd& q_motor) {
  CheckPerActuated(q_motor, "command");
  command_ = q_motor;
  torque_mode_ = false;
  if (max_delay_ > 0.0) PushCommandHistory(data_->time);
}

void Simulation::SetTorque(const Eigen::VectorXd& tau) {
  CheckPerActuated(tau, "torque");
  torque_ = tau;
  torque_mode_ = true;
}

double Simulation::MotorTorque(int i) const {
  if (i < 0 || i >= num_actuated()) {
    throw std::invalid_argument(model_name_ + ": MotorTorque(" + std::to_string(i) + ") of " +
                                std::to_string(num_actuated()) + " actuated joints");
  }
  const mjModel* m = truth_.get();
  const int a = catalog_.Joint(catalog_.actuated[i]).actuator;
  const double ff = static_cast<int>(feedforward_.size()) > i ? feedforward_[i] : 0.0;
  return data_->actuator_force[a] * m->actuator_gear[6 * a] + ff;
}

void Simulation::SetCommandAt(double t, const Eigen::VectorXd& q_motor) {
  if (max_delay_ > 0.0 && history_t_.size() > history_begin_ && t < history_t_.back()) {
    throw std::invalid_argument(model_name_ + ": commands sent out of time order");
  }
  SetCommand(q_motor);
  if (max_delay_ > 0.0) history_t_.back() = t;
}

void Simulation::PushCommandHistory(double t) {
  if (!history_t_.empty() && t < history_t_.back()) ClearCommandHistory();
  // Entries older than the one in force at t - max_delay are no longer read.
  while (history_t_.size() - history_begin_ >= 2 &&
         history_t_[history_begin_ + 1] <= t - max_delay_) {
    ++history_begin_;
  }
  if (history_begin_ > 0 && 2 * history_begin_ >= history_t_.size()) {
    const int n = num_actuated();
    history_t_.erase(history_t_.begin(), history_t_.begin() + history_begin_);
    history_q_.erase(history_q_.begin(), history_q_.begin() + history_begin_ * n);
    history_begin_ = 0;
  }
  history_t_.push_back(t);
  history_q_.insert(history_q_.end(), command_.data(), command_.data() + num_actuated());
}

void Simulation::ClearCommandHistory() {
  history_t_.clear();
  history_q_.clear();
  history_begin_ = 0;
}

// The command of actuator i in force `delay` seconds ago: the history interpolated linearly
// between the times commands were sent (a smooth function of the delay, which identification
// differentiates), the first command before the history begins.
double Simulation::DelayedCommand(int i, double delay) const {
  if (delay <= 0.0 || history_t_.size() == history_begin_) return command_[i];
  const int n = num_actuated();
  const double t = data_->time - delay;
  const auto first = history_t_.begin() + static_cast<long>(history_begin_);
  const auto it = std::upper_bound(first, history_t_.end(), t);
  if (it == first) return history_q_[history_begin_ * n + i];
  const size_t b = static_cast<size_t>(it - history_t_.begin());
  if (b == history_t_.size()) return history_q_[(b - 1) * n + i];
  const size_t a = b - 1;
  const double span = history_t_[b] - history_t_[a];
  const double s = span > 0.0 ? (t - history_t_[a]) / span : 1.0;
  return (1.0 - s) * history_q_[a * n + i] + s * history_q_[b * n + i];
}

void Simulation::SetActuatedState(double t, const Eigen::VectorXd& q, const Eigen::VectorXd& qd) {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  if (q.size() != num_actuated() || qd.size() != num_actuated()) {
    throw std::invalid_argument(model_name_ + ": state has " + std::to_string(q.size()) + ", " +
                                std::to_string(qd.size()) + " values for " +
                                std::to_string(num_actuated()) + " actuated joints");
  }
  ClearCommandHistory();
  d->time = t;
  for (int i = 0; i < num_actuated(); ++i) {
    const int j = catalog_.actuated[i];
    d->qpos[m->jnt_qposadr[j]] = q[i];
    d->qvel[m->jnt_dofadr[j]] = qd[i];
  }
  mj_forward(m, d);
  at_rest_ = false;
  kinematics_current_ = true;
  accelerations_current_ = false;
}

void Simulation::SetCommand(const std::string& joint, double q_motor) {
  for (int i = 0; i < num_actuated(); ++i) {
    if (actuated_names_[i] == joint) {
      command_[i] = q_motor;
      torque_mode_ = false;
      if (max_delay_ > 0.0) PushCommandHistory(data_->time);
      return;
    }
  }
  throw InputError(model_name_ + ": no actuated joint named '" + joint + "'");
}

// ---------------------------------------------------------------- static solve

// Writes the held joints into qpos: actuated joints with rigid gears at their command (minus
// half the play on the loaded flank), locked joints at qpos0. Coupled joints are updated with
// the free values in ComputeStaticForces.
void Simulation::SetHeldPositions(const std::vector<int>& backlash_sign) const {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  for (int i = 0; i < num_actuated(); ++i) {
    const int j = catalog_.actuated[i];
    const GearSpec& g = setup_.gear[j];
    // Rigid: held there. Elastic: the spring's unloaded position, the Newton start.
    d->qpos[m->jnt_qposadr[j]] =
        command_[i] + g.TransmissionError(command_[i]) - backlash_sign[j] * 0.5 * g.backlash;
  }
  for (int j : locked_joints_) d->qpos[m->jnt_qposadr[j]] = m->qpos0[m->jnt_qposadr[j]];
}

// Residual generalised force of the free DoFs at free positions x: what the springs fail to
// hold, qfrc_bias - qfrc_passive - tau_gear, at zero velocity.
void Simulation::ComputeStaticForces(const std::vector<int>& free_joints, const Eigen::VectorXd& x,
                                     Eigen::VectorXd* residual) const {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  for (size_t k = 0; k < free_joints.size(); ++k) {
    d->qpos[m->jnt_qposadr[free_joints[k]]] = x[k];
  }
  // (coupled joint, driver, d q_coupled / d q_driver)
  std::vector<std::tuple<int, int, double>> couplings;
  std::vector<double> slopes;
  for (const JointEntry& j : catalog_.joints) {
    if (j.role != JointRole::kCoupled || !setup_.released[j.id]) continue;
    double dy;
    CoupledValue(m, j, d->qpos, &dy, &slopes);
    d->qpos[j.qpos_adr] = m->qpos0[j.qpos_adr] + dy;
    for (size_t k = 0; k < slopes.size(); ++k)
      couplings.emplace_back(j.id, j.drivers[k], slopes[k]);
  }
  mju_zero(d->qvel, m->nv);
  mj_kinematics(m, d);
  mj_comPos(m, d);
  if (m->ntendon) mj_tendon(m, d);
  mj_comVel(m, d);
  mj_passive(m, d);
  mj_rne(m, d, 0, d->qfrc_bias);
  residual->resize(static_cast<int>(free_joints.size()));
  for (size_t k = 0; k < free_joints.size(); ++k) {
    const int j = free_joints[k];
    const int dof = m->jnt_dofadr[j];
    double r = d->qfrc_bias[dof] - d->qfrc_passive[dof];
    if (catalog_.Joint(j).role == JointRole::kActuated) {
      const int i =
          static_cast<int>(std::find(catalog_.actuated.begin(), catalog_.actuated.end(), j) -
                           catalog_.actuated.begin());
      // The gear spring around the flank the load presses on (set by the backlash pass through
      // the unloaded position stored in qpos0 of the pass, see Settle).
      r -= setup_.gear[j].SpringTorque(gear_reference_[i] - x[k]);
    }
    (*residual)[static_cast<int>(k)] = r;
  }
  // A linkage driven by a free (elastic) joint passes its load on: virtual work, chain rule.
  for (const auto& [c, driver, slope] : couplings) {
    const auto it = std::find(free_joints.begin(), free_joints.end(), driver);
    if (it == free_joints.end()) continue;
    const int dof = m->jnt_dofadr[c];
    (*residual)[static_cast<int>(it - free_joints.begin())] +=
        slope * (d->qfrc_bias[dof] - d->qfrc_passive[dof]);
  }
}

// The unloaded gear-spring position of each actuated joint for the flanks in `backlash_sign`.
void Simulation::SetGearReferences(const std::vector<int>& backlash_sign) {
  for (int i = 0; i < num_actuated(); ++i) {
    const int j = catalog_.actuated[i];
    const GearSpec& g = setup_.gear[j];
    gear_reference_[i] =
        command_[i] + g.TransmissionError(command_[i]) - backlash_sign[j] * 0.5 * g.backlash;
  }
}

// Start from the nominal state: the result does not depend on the previous configuration.
void Simulation::NominalStart(Eigen::VectorXd* x) const {
  const mjModel* m = truth_.get();
  const mjData* d = data_.get();
  for (int k = 0; k < static_cast<int>(free_joints_.size()); ++k) {
    const int j = free_joints_[k];
    (*x)[k] = catalog_.Joint(j).role == JointRole::kActuated ? d->qpos[m->jnt_qposadr[j]]
                                                             : m->qpos0[m->jnt_qposadr[j]];
  }
}

// Forward differences of the residual r at x.
Eigen::MatrixXd Simulation::StaticJacobian(const Eigen::VectorXd& x, const Eigen::VectorXd& r,
                                           Eigen::VectorXd* x_try, Eigen::VectorXd* r_try) const {
  const int n = static_cast<int>(x.size());
  Eigen::MatrixXd J(n, n);
  for (int k = 0; k < n; ++k) {
    *x_try = x;
    (*x_try)[k] += kJacobianStep;
    ComputeStaticForces(free_joints_, *x_try, r_try);
    J.col(k) = (*r_try - r) / kJacobianStep;
  }
  return J;
}

// One Newton step from x (residual r, largest |r| err); `iteration` counts all passes.
void Simulation::DampedNewtonStep(double err, int iteration, Eigen::VectorXd* x, Eigen::VectorXd* r,
                                  Eigen::VectorXd* x_try, Eigen::VectorXd* r_try) const {
  Eigen::FullPivLU<Eigen::MatrixXd> lu(StaticJacobian(*x, *r, x_try, r_try));
  if (!lu.isInvertible()) {
    throw SimulationError(model_name_ +
                          ": quasi-static settle has a singular stiffness at iteration " +
                          std::to_string(iteration) + " (a free joint without stiffness?)");
  }
  const Eigen::VectorXd dx = lu.solve(-*r);
  // Damped Newton: halve the step until the residual decreases.
  double alpha = 1.0;
  for (int ls = 0; ls < 30; ++ls, alpha *= 0.5) {
    *x_try = *x + alpha * dx;
    ComputeStaticForces(free_joints_, *x_try, r_try);
    if (r_try->allFinite() && r_try->cwiseAbs().maxCoeff() < err) break;
  }
  *x = *x_try;
  *r = *r_try;
}

// Iterates from x (residual r) to |r| <= tolerance; counts its iterations into `report`.
void Simulation::SolveFreeJoints(const SettleOptions& options, Eigen::VectorXd* x,
                                 Eigen::VectorXd* r, Eigen::VectorXd* x_try, Eigen::VectorXd* r_try,
                                 SettleReport* report) const {
  const int n = static_cast<int>(r->size());
  int it = 0;
  for (;; ++it) {
    const double err = n ? r->cwiseAbs().maxCoeff() : 0.0;
    if (!std::isfinite(err)) {
      throw SimulationError(model_name_ + ": quasi-static settle diverged at iteration " +
                            std::to_string(report->iterations + it) +
                            ": non-finite residual torque");
    }
    report->residual = err;
    if (err <= options.tolerance) break;
    if (it >= options.max_iterations) {
      int worst = 0;
      r->cwiseAbs().maxCoeff(&worst);
      throw SimulationError(model_name_ + ": quasi-static settle did not converge in " +
                            std::to_string(options.max_iterations) + " iterations (residual " +
                            ShortNum(err) + " Nm at joint '" +
                            catalog_.Joint(free_joints_[worst]).name + "', iteration " +
                            std::to_string(report->iterations + it) + ")");
    }
    DampedNewtonStep(err, report->iterations + it, x, r, x_try, r_try);
  }
  report->iterations += it;
}

// The load each backlashed gear carries (in data_ after the solve) picks its flank. Returns
// whether a flank changed.
bool Simulation::PickBacklashFlanks(std::vector<int>* backlash_sign) const {
  const mjModel* m = truth_.get();
  const mjData* d = data_.get();
  bool changed = false;
  for (int j : catalog_.actuated) {
    if (setup_.gear[j].backlash <= 0) continue;
    const int dof = m->jnt_dofadr[j];
    const double load = d->qfrc_bias[dof] - d->qfrc_passive[dof];
    const int s = load > kBacklashLoadEps ? 1 : (load < -kBacklashLoadEps ? -1 : 0);
    changed |= s != (*backlash_sign)[j];
    (*backlash_sign)[j] = s;
  }
  return changed;
}

// Leaves the solved state at rest, with the servo forces and accelerations of that state.
void Simulation::ComeToRest() {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  mju_zero(d->qvel, m->nv);
  mju_zero(d->qacc_warmstart, m->nv);
  mj_forward(m, d);
  ApplyServo();
  mj_forwardSkip(m, d, mjSTAGE_VEL, 0);
  at_rest_ = true;
  kinematics_current_ = true;
  accelerations_current_ = true;
}

SettleReport Simulation::Settle(const SettleOptions& options) {
  SettleReport report;
  report.free_dofs = static_cast<int>(free_joints_.size());
  std::vector<int> sign(truth_->njnt, 0);
  bool has_backlash = false;
  for (int j : catalog_.actuated) has_backlash |= setup_.gear[j].backlash > 0;
  gear_reference_.resize(num_actuated());

  const int n = static_cast<int>(free_joints_.size());
  Eigen::VectorXd x(n), r(n), r_try(n), x_try(n);
  for (int pass = 0; pass < kMaxBacklashPasses; ++pass) {
    SetHeldPositions(sign);
    SetGearReferences(sign);
    NominalStart(&x);
    ComputeStaticForces(free_joints_, x, &r);
    SolveFreeJoints(options, &x, &r, &x_try, &r_try, &report);
    ComputeStaticForces(free_joints_, x, &r);
    // Repeat until the flanks agree with the loads they carry.
    if (!has_backlash || !PickBacklashFlanks(&sign)) break;
  }
  ComeToRest();
  return report;
}

// ---------------------------------------------------------------- dynamics

// Position servos towards the command. Rigid gear: the MJCF servo plus feed-forward of
// qfrc_bias (so it holds the command at rest). Elastic gear and/or backlash: the transmission
// torque K * deadzone(command - q) through the servo's ctrl (force = kp (ctrl - q)).
void Simulation::ApplyServo() const {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  feedforward_.resize(num_actuated());
  for (int i = 0; i < num_actuated(); ++i) {
    const int j = catalog_.actuated[i];
    const int a = catalog_.Joint(j).actuator;
    const int dof = m->jnt_dofadr[j];
    const double q = d->qpos[m->jnt_qposadr[j]];
    const double kp = m->actuator_gainprm[a * mjNGAIN];
    if (torque_mode_) {
      // The servo off: the control at which its force (gain ctrl + bias) is zero here, within
      // its range; what a clamped control leaves is taken off the torque applied.
      const double* b = m->actuator_biasprm + a * mjNBIAS;
      const double bias = b[0] + b[1] * d->actuator_length[a] + b[2] * d->actuator_velocity[a];
      double ctrl = kp != 0.0 ? -bias / kp : 0.0;
      if (m->actuator_ctrllimited[a]) {
        ctrl = std::clamp(ctrl, m->actuator_ctrlrange[2 * a], m->actuator_ctrlrange[2 * a + 1]);
      }
      d->ctrl[a] = ctrl;
      d->qfrc_applied[dof] = torque_[i] - m->actuator_gear[6 * a] * (kp * ctrl + bias);
      continue;
    }
    const GearSpec& g = setup_.gear[j];
    const double command = DelayedCommand(i, setup_.servo_delay[j]);
    const double link_command = command + g.TransmissionError(command);
    if (g.stiffness <= 0 && g.backlash <= 0) {
      d->ctrl[a] = link_command;
      d->qfrc_applied[dof] = d->qfrc_bias[dof];
    } else {
      const double dz = DeadZone(link_command - q, 0.5 * g.backlash);
      const double tau = g.stiffness > 0 ? g.SpringTorque(dz) : kp * dz;
      d->ctrl[a] = q + tau / kp;
      d->qfrc_applied[dof] = 0.0;
    }
  }
  // A rigid gear holds the load of the linkages it drives as well (virtual work), as the
  // static solve's drivers do.
  for (int c : released_linkages_) {
    if (torque_mode_) break;  // the logged torques are the motors' whole torques
    const JointEntry& linkage = catalog_.Joint(c);
    double dy;
    CoupledValue(m, linkage, d->qpos, &dy, &slopes_);
    for (size_t k = 0; k < slopes_.size(); ++k) {
      const GearSpec& g = setup_.gear[linkage.drivers[k]];
      if (g.stiffness > 0 || g.backlash > 0) continue;
      d->qfrc_applied[m->jnt_dofadr[linkage.drivers[k]]] +=
          slopes_[k] * d->qfrc_bias[m->jnt_dofadr[c]];
    }
  }
  for (int i = 0; i < num_actuated(); ++i) {
    feedforward_[i] = d->qfrc_applied[m->jnt_dofadr[catalog_.actuated[i]]];
  }
  for (int i = 0; i < num_actuated(); ++i) {
    const int j = catalog_.actuated[i];
    if (!setup_.stribeck[j].active()) continue;
    const int dof = m->jnt_dofadr[j];
    d->qfrc_applied[dof] += setup_.stribeck[j].Torque(d->qvel[dof]);
  }
}

void Simulation::ProjectLocked() const {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  for (int j : locked_joints_) {
    d->qpos[m->jnt_qposadr[j]] = m->qpos0[m->jnt_qposadr[j]];
    d->qvel[m->jnt_dofadr[j]] = 0.0;
  }
}

void Simulation::CheckStep(double time_before) const {
  const mjModel* m = truth_.get();
  const mjData* d = data_.get();
  std::string reason;
  // MuJoCo resets the state on a bad acceleration; the warning's count restarts with it, so a
  // reset the count hides still shows as the clock going back.
  if (!(d->time > time_before)) {
    reason = "MuJoCo reset the state (the clock went back from " + ShortNum(time_before) +
             " s to " + ShortNum(d->time) + " s)";
  }
  for (int w : {mjWARN_BADQACC, mjWARN_BADQVEL, mjWARN_BADQPOS}) {
    if (d->warning[w].number != warning_counts_[w]) {
      const int dof = d->warning[w].lastinfo;
      const char* what = w == mjWARN_BADQACC   ? "acceleration"
                         : w == mjWARN_BADQVEL ? "velocity"
                                               : "position";
      std::string joint = "?";
      if (w != mjWARN_BADQPOS && dof >= 0 && dof < m->nv) {
        joint = ObjectName(m, mjOBJ_JOINT, m->dof_jntid[dof]);
      }
      reason = std::string("NaN, Inf or huge ") + what + " (MuJoCo reset the state) at joint '" +
               joint + "'";
    }
  }
  if (reason.empty()) {
    for (int i = 0; i < m->nv; ++i) {
      if (!std::isfinite(d->qvel[i]) || !std::isfinite(d->qacc[i])) {
        reason = "non-finite velocity or acceleration at joint '" +
                 ObjectName(m, mjOBJ_JOINT, m->dof_jntid[i]) + "'";
        break;
      }
    }
  }
  if (!reason.empty()) {
    throw SimulationError(model_name_ + ": simulation diverged at step " + std::to_string(steps_) +
                          " (t = " + ShortNum(time_before + m->opt.timestep) + " s): " + reason);
  }
}

void Simulation::Step(int steps) {
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  std::string warning;
  StepWarningScope scope(&warning);
  for (int w = 0; w < mjNWARNING; ++w) warning_counts_[w] = d->warning[w].number;
  for (int k = 0; k < steps; ++k) {
    const double time_before = d->time;
    if (ForwardIsCurrent()) {
      // Positions and velocities were computed at this very state for a reading
      // (EnsureAccelerations): step1's checks only, unless one reset the state.
      mj_checkPos(m, d);
      mj_checkVel(m, d);
      if (!ForwardIsCurrent()) mj_step1(m, d);
    } else {
      mj_step1(m, d);
    }
    forward_key_.clear();
    ApplyServo();
    mj_step2(m, d);
    ProjectLocked();
    ++steps_;
    CheckStep(time_before);
  }
  at_rest_ = false;
  kinematics_current_ = false;
  accelerations_current_ = false;
}

double Simulation::SettleDynamic(double max_time_s, double velocity_tol) {
  const mjModel* m = truth_.get();
  const double t0 = time();
  double worst = 0.0;
  int worst_dof = 0;
  while (time() - t0 < max_time_s) {
    Step(1);
    worst = 0.0;
    for (int i = 0; i < m->nv; ++i) {
      if (std::abs(data_->qvel[i]) > worst) {
        worst = std::abs(data_->qvel[i]);
        worst_dof = i;
      }
    }
    if (worst < velocity_tol) return time() - t0;
  }
  throw SimulationError(model_name_ + ": no equilibrium within " + ShortNum(max_time_s) +
                        " s (step " + std::to_string(steps_) + ", |qvel| = " + ShortNum(worst) +
                        " at joint '" + ObjectName(m, mjOBJ_JOINT, m->dof_jntid[worst_dof]) + "')");
}

// ---------------------------------------------------------------- ground truth

bool Simulation::ForwardIsCurrent() const {
  const mjModel* m = truth_.get();
  const mjData* d = data_.get();
  if (forward_key_.size() != static_cast<size_t>(m->nq + m->nv + m->na + 1)) return false;
  const mjtNum* key = forward_key_.data();
  return std::equal(d->qpos, d->qpos + m->nq, key) &&
         std::equal(d->qvel, d->qvel + m->nv, key + m->nq) &&
         std::equal(d->act, d->act + m->na, key + m->nq + m->nv) &&
         d->time == key[m->nq + m->nv + m->na];
}

void Simulation::EnsureKinematics() const {
  if (kinematics_current_) return;
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_camlight(m, d);
  kinematics_current_ = true;
}

// Accelerations of the current state as the next step will see them, without changing the
// trajectory (the constraint solver's warm start is restored).
void Simulation::EnsureAccelerations() const {
  if (accelerations_current_) return;
  const mjModel* m = truth_.get();
  mjData* d = data_.get();
  // Positions and velocities first: the servo's force depends on them (ApplyServo), and the
  // acceleration stages then run once, with it.
  warmstart_.assign(d->qacc_warmstart, d->qacc_warmstart + m->nv);
  mj_fwdPosition(m, d);
  mj_sensorPos(m, d);
  if (mjENABLED(mjENBL_ENERGY)) mj_energyPos(m, d);
  mj_fwdVelocity(m, d);
  mj_sensorVel(m, d);
  if (mjENABLED(mjENBL_ENERGY)) mj_energyVel(m, d);
  ApplyServo();
  mj_forwardSkip(m, d, mjSTAGE_VEL, 0);
  mj_rnePostConstraint(m, d);
  std::copy(warmstart_.begin(), warmstart_.end(), d->qacc_warmstart);
  forward_key_.assign(d->qpos, d->qpos + m->nq);
  forward_key_.insert(forward_key_.end(), d->qvel, d->qvel + m->nv);
  forward_key_.insert(forward_key_.end(), d->act, d->act + m->na);
  forward_key_.push_back(d->time);
  kinematics_current_ = true;
  accelerations_current_ = true;
}

FrameRef Simulation::Frame(const std::string& name) const {
  const mjModel* m = truth_.get();
  const std::pair<mjtObj, FrameType> order[] = {{mjOBJ_SITE, FrameType::kSite},
                                                {mjOBJ_CAMERA, FrameType::kCamera},
                                                {mjOBJ_GEOM, FrameType::kGeom},
                                                {mjOBJ_BODY, FrameType::kBody}};
  for (const auto& [obj, type] : order) {
    const int id = mj_name2id(m, obj, name.c_str());
    if (id >= 0) return FrameRef{type, id, name};
  }
  throw InputError(model_name_ + ": no site, camera, geom or body named '" + name + "'");
}

Eigen::Isometry3d Simulation::Pose(const FrameRef& frame) const {
  EnsureKinematics();
  return FramePoseIn(data_.get(), frame);
}

Eigen::Isometry3d Simulation::BodyPose(const std::string& body) const {
  return Pose(FrameRef{FrameType::kBody, BodyId(truth_.get(), body, model_name_), body});
}

Eigen::Isometry3d Simulation::SitePose(const std::string& site) const {
  return Pose(FrameRef{FrameType::kSite, SiteId(truth_.get(), site, model_name_), site});
}

double Simulation::JointPosition(const std::string& joint) const {
  return JointPosition(JointId(truth_.get(), joint, model_name_));
}

double Simulation::JointPosition(int joint_id) const {
  return data_->qpos[truth_->jnt_qposadr[joint_id]];
}

double Simulation::MotorPosition(int joint_id) const {
  const JointEntry& j = catalog_.Joint(joint_id);
  if (j.role != JointRole::kActuated) return JointPosition(joint_id);
  const GearSpec& g = setup_.gear[joint_id];
  if (g.stiffness <= 0 && g.backlash <= 0 && !g.has_transmission_error()) {
    return JointPosition(joint_id);
  }
  const auto it = std::find(catalog_.actuated.begin(), catalog_.actuated.end(), joint_id);
  return command_[static_cast<int>(it - catalog_.actuated.begin())];
}

Vec3 Simulation::SiteAngularVelocity(int site_id) const {
  if (at_rest_) return Vec3::Zero();
  EnsureAccelerations();
  mjtNum v[6];
  mj_objectVelocity(truth_.get(), data_.get(), mjOBJ_SITE, site_id, v, 1);
  return Vec3(v[0], v[1], v[2]);
}

Vec3 Simulation::SiteSpecificForce(int site_id) const {
  if (at_rest_) {
    EnsureKinematics();
    const Mat3 R = RotFromRowMajor(data_->site_xmat + 9 * site_id);
    const Vec3 g(truth_->opt.gravity[0], truth_->opt.gravity[1], truth_->opt.gravity[2]);
    return R.transpose() * (-g);
  }
  EnsureAccelerations();
  mjtNum a[6];
  mj_objectAcceleration(truth_.get(), data_.get(), mjOBJ_SITE, site_id, a, 1);
  return Vec3(a[3], a[4], a[5]);
}

ImuBiasSpec Simulation::ImuBias(const std::string& site) const {
  auto it = setup_.imu_bias.find(site);
  if (it == setup_.imu_bias.end()) it = setup_.imu_bias.find("*");
  return it == setup_.imu_bias.end() ? ImuBiasSpec{} : it->second;
}

// ---------------------------------------------------------------- nominal model

void Simulation::SetNominalQpos(const Eigen::VectorXd& q) const {
  const mjModel* m = nominal_.get();
  mjData* d = nominal_data_.get();
  mju_copy(d->qpos, m->qpos0, m->nq);
  for (int i = 0; i < num_actuated(); ++i) d->qpos[m->jnt_qposadr[catalog_.actuated[i]]] = q[i];
  for (int c : mechanism_linkages_) {
    double dy;
    CoupledValue(m, catalog_.Joint(c), d->qpos, &dy, &slopes_);
    d->qpos[m->jnt_qposadr[c]] = m->qpos0[m->jnt_qposadr[c]] + dy;
  }
}

Eigen::Isometry3d Simulation::NominalPose(const FrameRef& frame, const Eigen::VectorXd& q) const {
  if (q.size() != num_actuated()) {
    throw std::invalid_argument(model_name_ + ": NominalPose needs " +
                                std::to_string(num_actuated()) + " actuated angles");
  }
  SetNominalQpos(q);
  const mjModel* m = nominal_.get();
  mjData* d = nominal_data_.get();
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_camlight(m, d);
  return FramePoseIn(d, frame);
}

Eigen::VectorXd Simulation::GravityTorque(const Eigen::VectorXd& q) const {
  if (q.size() != num_actuated()) {
    throw std::invalid_argument(model_name_ + ": GravityTorque needs " +
                                std::to_string(num_actuated()) + " actuated angles");
  }
  SetNominalQpos(q);
  const mjModel* m = nominal_.get();
  mjData* d = nominal_data_.get();
  mju_zero(d->qvel, m->nv);
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_comVel(m, d);
  std::vector<mjtNum> bias(m->nv);
  mj_rne(m, d, 0, bias.data());
  // A linkage's load rests on its drivers (virtual work).
  for (int c : mechanism_linkages_) {
    double dy;
    CoupledValue(m, catalog_.Joint(c), d->qpos, &dy, &slopes_);
    for (size_t k = 0; k < slopes_.size(); ++k) {
      bias[m->jnt_dofadr[catalog_.Joint(c).drivers[k]]] += slopes_[k] * bias[m->jnt_dofadr[c]];
    }
  }
  Eigen::VectorXd g(num_actuated());
  for (int i = 0; i < num_actuated(); ++i) g[i] = bias[m->jnt_dofadr[catalog_.actuated[i]]];
  return g;
}

}  // namespace flexbench::sim
