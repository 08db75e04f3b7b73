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
  // Observed frames by their declared name.
  std::vector<std::pair<std::string, kinematics::FrameId>> observed;
  // The declared file's identified effects (none when it has none), with the chain's masses and
  // gravity for the load-driven ones: estimators predict with them (EstimatorSetup::effects).
  kinematics::ModelEffects effects;
  // nullptr when there is nothing to apply.
  const kinematics::ModelEffects* effects_or_null() const {
    return effects.empty() ? nullptr : &effects;
  }

  // PPOE joint vector from a MuJoCo qpos.
  Eigen::VectorXd QFromQpos(const double* qpos) const;
  // Writes q into qpos (actuated joints only).
  void WriteQpos(const Eigen::VectorXd& q, double* qpos) const;
  // Index of MJCF joint `name` in q; throws InputError when it is not actuated.
  int QIndex(const std::string& joint) const;
  // Frame of a declared observed frame; throws InputError.
  kinematics::FrameId ObservedFrame(const std::string& name) const;
};

// Builds the chain and applies the declared file's identified effects (sim/declared_effects.h).
// Throws InputError naming the declared file (and line) for a joint, body, site or frame the
// model lacks, a source off the chain, an unsupported joint type, or a bad identified effect.
DeclaredChain BuildDeclaredChain(const mjModel* m, const DeclaredModel& declared);

// Resolves a frame name of the model the way declared files do: a site, then a geom, a camera,
// then a body. Returns the typed PPOE frame name ("site/ee"), or "" when none matches.
std::string TypedFrameName(const mjModel* m, const std::string& name);

}  // namespace flexbench::sim
