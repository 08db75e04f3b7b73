#include "scenarios/runner/common/sim_readings.h"

#include <algorithm>

#include "sim/mujoco_model.h"

namespace flexbench::scenarios {

estimators::JointReading EncoderReading(const sim::Simulation& sim, const sim::DeclaredChain& chain,
                                        double t) {
  estimators::JointReading r;
  r.t = t;
  r.q.resize(chain.model.nq());
  r.std.setZero(chain.model.nq());
  for (int k = 0; k < chain.model.nq(); ++k) {
    const int jid = sim::JointId(sim.model(), chain.q_joints[k]);
    r.q[k] = sim.MotorPosition(jid) - sim.JointOffset(jid) - chain.q_qpos0[k];
  }
  return r;
}

std::vector<int> ActuatorIndices(const sim::Simulation& sim, const sim::DeclaredChain& chain) {
  const std::vector<std::string>& names = sim.actuated_joints();
  std::vector<int> out;
  for (const std::string& j : chain.q_joints) {
    const auto it = std::find(names.begin(), names.end(), j);
    out.push_back(it == names.end() ? -1 : static_cast<int>(it - names.begin()));
  }
  return out;
}

}  // namespace flexbench::scenarios
