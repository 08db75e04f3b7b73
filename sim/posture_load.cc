#include "sim/posture_load.h"

#include "estimators/kinematics/forward_kinematics.h"

namespace flexbench::sim {

PostureLoadEvaluator::PostureLoadEvaluator(const mjModel* nominal, const DeclaredChain& chain)
    : m_(nominal), chain_(chain), d_(mj_makeData(nominal)), fk_(chain.model) {
  for (size_t k = 0; k < chain.q_joints.size(); ++k) {
    const int j = mj_name2id(m_, mjOBJ_JOINT, chain.q_joints[k].c_str());
    dofadr_.push_back(j >= 0 ? m_->jnt_dofadr[j] : -1);
  }
}

PostureLoadEvaluator::~PostureLoadEvaluator() { mj_deleteData(d_); }

void PostureLoadEvaluator::Evaluate(const Eigen::VectorXd& q, PostureLoad* out) {
  mju_copy(d_->qpos, m_->qpos0, m_->nq);
  mju_zero(d_->qvel, m_->nv);
  chain_.WriteQpos(q, d_->qpos);
  // Positions, then the bias force: with qvel = 0 it is gravity alone.
  mj_kinematics(m_, d_);
  mj_comPos(m_, d_);
  mj_comVel(m_, d_);
  mj_rne(m_, d_, 0, d_->qfrc_bias);
  out->gravity_torque.resize(static_cast<Eigen::Index>(dofadr_.size()));
  for (size_t k = 0; k < dofadr_.size(); ++k) {
    out->gravity_torque[static_cast<Eigen::Index>(k)] =
        dofadr_[k] >= 0 ? d_->qfrc_bias[dofadr_[k]] : 0.0;
  }
  kinematics::ForwardKinematics(chain_.model, fk_, q);
  out->p_base_ee = fk_.T_base_frame[chain_.end_effector].translation();
}

}  // namespace flexbench::sim
