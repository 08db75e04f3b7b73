#include "scenarios/runner/kinds/jsk/rig.h"

#include <algorithm>
#include <utility>

#include "estimators/error.h"
#include "scenarios/runner/common/model_config.h"

namespace flexbench::scenarios::jsk {

Rig LoadRig(const ConfigNode& root, bool with_effects) {
  Rig rig;
  std::string model_path;
  sim::DeclaredModel declared = ReadModelAndDeclared(root, &model_path);
  sim::EffectList effects;
  if (with_effects) {
    if (const auto e = root.Optional("effects")) effects = sim::ParseEffects(*e);
  }
  static_cast<TruthRig&>(rig) = LoadTruthRig(model_path, effects, std::move(declared));
  const ConfigNode imus = root.Child("imus");
  for (const ConfigNode& item : imus.Items()) {
    const std::string site = item.AsString();
    const auto& sites = rig.sim->catalog().imu_sites;
    if (std::find(sites.begin(), sites.end(), site) == sites.end()) {
      item.Fail("'" + site + "' is not an IMU site of " + model_path +
                " (a site with an MJCF gyro and accelerometer)");
    }
    rig.imu_sites.push_back(site);
    rig.imu_frames.push_back(rig.chain->ObservedFrame(site));
  }
  for (kinematics::FrameId f : rig.imu_frames) rig.setup.imus.push_back(estimators::ImuSetup{f});
  const std::vector<std::string>& act = rig.sim->actuated_joints();
  for (const std::string& j : rig.chain->q_joints) {
    const auto it = std::find(act.begin(), act.end(), j);
    if (it == act.end()) {
      root.Child("declared").Fail("declared joint '" + j + "' has no actuator in " + model_path);
    }
    rig.act_of_q.push_back(static_cast<int>(it - act.begin()));
  }
  if (rig.nq() != rig.sim->num_actuated()) {
    root.Child("declared").Fail("the declared model must list every actuated joint");
  }
  return rig;
}

Eigen::VectorXd Rig::ToActuators(const Eigen::VectorXd& q) const {
  Eigen::VectorXd a(sim->num_actuated());
  for (int k = 0; k < nq(); ++k) a[act_of_q[k]] = q[k] + chain->q_qpos0[k];
  return a;
}

Eigen::VectorXd Rig::LinkAngles() const {
  Eigen::VectorXd q(nq());
  for (int k = 0; k < nq(); ++k) q[k] = sim->JointPosition(chain->q_joints[k]) - chain->q_qpos0[k];
  return q;
}

}  // namespace flexbench::scenarios::jsk
