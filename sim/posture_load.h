// What a posture puts an arm under, for telling whether a run stays where an augmented model was
// fitted (sim::FittedUnder): the gravity torque each joint holds and where the end effector is.
// A bending link or a compliant mount deflects with the torque it carries, so a fit over one
// band of torques says little about another, even at joint angles inside the fitted ranges.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <memory>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_data.h"
#include "sim/declared_chain.h"

namespace flexbench::sim {

struct PostureLoad {
  Eigen::VectorXd gravity_torque;  // N m (N for a slide), per PPOE joint variable of the chain
  Vec3 p_base_ee = Vec3::Zero();   // the declared end effector in the base frame, m
};

// Evaluates PostureLoad for joint vectors of `chain` (built from `nominal`); both must outlive
// it. The torque is MuJoCo's qfrc_bias at rest (gravity alone) of the nominal model with the
// chain's joints set and every other joint at its reference; the position is the chain's mean
// forward kinematics [PPOE eq. 17].
class PostureLoadEvaluator {
 public:
  PostureLoadEvaluator(const mjModel* nominal, const DeclaredChain& chain);
  ~PostureLoadEvaluator();
  PostureLoadEvaluator(const PostureLoadEvaluator&) = delete;
  PostureLoadEvaluator& operator=(const PostureLoadEvaluator&) = delete;
  // q: a joint vector of the chain (chain.model.nq() entries, finite).
  void Evaluate(const Eigen::VectorXd& q, PostureLoad* out);

 private:
  const mjModel* m_;
  const DeclaredChain& chain_;
  mjData* d_ = nullptr;
  kinematics::PpoeData fk_;
  std::vector<int> dofadr_;  // per joint variable, its dof in m_ (-1: not a MuJoCo joint)
};

}  // namespace flexbench::sim
