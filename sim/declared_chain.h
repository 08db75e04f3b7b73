// The nominal kinematic chain of a MuJoCo model as a PPOE model [PPOE eqs. 16-17],
// extracted for a declared model: actuated joints become PPOE joints, fixed geometry becomes
// the static transforms p_i, passive joints are held at their reference angle, and the declared
// perturbation sources sit at their joints or bodies. With the passive joints at qpos0 the mean
// equals MuJoCo's own body, site, geom and camera poses (tests/integration/declared_chain/).
//
// Frame names are typed so MuJoCo's per-type names never collide: "body/<name>",
// "joint/<name>" (the frame at the joint's anchor, axes of its body, after the joint moved),
// "site/<name>", "geom/<name>", "camera/<name>" (the optical frame: x right, y down, z forward).
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <array>
#include <string>
#include <utility>
#include <vector>

#include "estimators/kinematics/model_effects.h"
#include "estimators/kinematics/ppoe_model.h"
#include "sim/declared_model.h"

namespace flexbench::sim {

struct DeclaredChain {
  kinematics::PpoeModel model;
  // Per PPOE joint variable k: the MJCF joint, its qpos address and reference angle
  // (q[k] = qpos[adr] - qpos0[adr], as MuJoCo's own kinematics measure it).
  std::vector<std::string> q_joints;
  std::vector<int> q_qposadr;
  std::vector<double> q_qpos0;
  // MuJoCo body the PPOE base frame stands for, and the end-effector frame.
  int base_body = 0;
  kinematics::FrameId end_effector = -1;
  std::string end_effector_name;  // as the declared model names it
  // Observed frames by their declared name.
  std::vector<std::pair<std::string, kinematics::FrameId>> observed;
  // The declared file's identified effects (none when it has none), with the chain's masses and
  // gravity for the load-driven ones: estimators predict with them (EstimatorSetup::effects).
  kinematics::ModelEffects effects;
  // nullptr when there is nothing to apply.
  const kinematics::ModelEffects* effects_or_null() const {
    return effects.empty() ? nullptr : &effects;
  }

  // Coupled joints (DeclaredModel::coupled): PPOE joint variables like the actuated ones, whose
  // angle follows from their drivers' instead of a reading. In evaluation order: a driver that
  // is coupled itself comes first.
  struct Coupling {
    int q_index = -1;
    std::vector<std::pair<int, double>> linear;  // (driver variable, coefficient)
    int poly_driver = -1;  // the MJCF's polynomial: q = sum_k poly[k] x^k, x that driver
    std::array<double, 5> poly{};
    std::string where;  // the declared entry, for messages
  };
  std::vector<Coupling> couplings;
  bool IsCoupled(int k) const;
  // The coupled variables of q from their drivers (the readings' entries are left alone).
  void ApplyCouplings(Eigen::VectorXd* q) const;
  // Adds to dq's coupled entries what dq's driver entries move them by at q (a driver's true
  // angle drives the linkage): with q coupled (ApplyCouplings), q + dq is coupled again, plus
  // the coupled joints' own entries of dq.
  void PropagateShift(const Eigen::VectorXd& q, Eigen::VectorXd* dq) const;

  // PPOE joint vector from a MuJoCo qpos.
  Eigen::VectorXd QFromQpos(const double* qpos) const;
  // Writes q into qpos (actuated and coupled joints).
  void WriteQpos(const Eigen::VectorXd& q, double* qpos) const;
  // Index of MJCF joint `name` in q; throws InputError when it is not actuated.
  int QIndex(const std::string& joint) const;
  // Frame of a declared observed frame; throws InputError.
  kinematics::FrameId ObservedFrame(const std::string& name) const;
};

// Builds the chain and applies the declared file's identified effects (sim/declared_effects.h).
// Throws InputError naming the declared file (and line) for a joint, body, site or frame the
// model lacks, a source off the chain, an unsupported joint type, a bad identified effect, or a
// coupling naming a joint the model lacks, an actuated joint as coupled, a driver that is not
// declared, `mjcf` without a two-joint <equality><joint> on the joint, or a cycle.
// `with_couplings`: the caller maps readings to joint variables with ApplyCouplings (the
// identification does); without it a declared file with `coupled:` is refused, since the
// estimators need a reading of every joint variable of their chain.
DeclaredChain BuildDeclaredChain(const mjModel* m, const DeclaredModel& declared,
                                 bool with_couplings = false);

// Resolves a frame name of the model the way declared files do: a site, then a geom, a camera,
// then a body. Returns the typed PPOE frame name ("site/ee"), or "" when none matches.
std::string TypedFrameName(const mjModel* m, const std::string& name);

}  // namespace flexbench::sim
