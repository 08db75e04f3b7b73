// What a truth model contains, read from the compiled mjModel: which joints are actuated
// (position servos), which are passive compliance joints and which are kinematically coupled,
// and which model parts each effect acts on.
//
// MJCF convention (models/*.xml): effects name their parts in <custom> fields,
//   <text name="effect:base_compliance" data="plate_pitch plate_roll"/>
//   <numeric name="effect:joint_compliance:stiffness" data="120 80"/>
// (an effect's former name is still read, with a note: effect:joint_elasticity).
// A passive joint is a hinge or slide without an actuator; a coupled joint is joint1 of an
// active two-joint <equality><joint> (its value is a polynomial of joint2, e.g. a linkage), or
// the one joint without an actuator in a fixed tendon that an active one-tendon
// <equality><tendon> holds at its reference length (a linear linkage of several drivers:
// sum_k coef_k (q_k - qpos0_k) = polycoef[0]).
#pragma once

#include <mujoco/mujoco.h>

#include <map>
#include <string>
#include <vector>

namespace flexbench::sim {

enum class JointRole { kActuated, kPassive, kCoupled };

struct JointEntry {
  std::string name;
  int id = -1;
  int type = mjJNT_HINGE;  // mjJNT_HINGE or mjJNT_SLIDE
  int qpos_adr = -1;
  int dof_adr = -1;
  JointRole role = JointRole::kPassive;
  int actuator = -1;     // position actuator driving the joint (actuated joints)
  int coupling_eq = -1;  // equality constraint defining the joint (coupled joints)
  // The joints it follows: joint2 of a joint equality, or the tendon's other joints.
  std::vector<int> drivers;
  // Tendon linkages: d q / d q_driver per driver, and q - qpos0 with the drivers at qpos0.
  std::vector<double> driver_slopes;
  double linkage_offset = 0.0;
  std::string effect;  // effect whose custom field lists the joint ("" when none)
};

// A coupled joint's value from its drivers' qpos: q - qpos0 into *dq and d q / d q_driver per
// driver (JointEntry::drivers' order) into slopes.
void CoupledValue(const mjModel* m, const JointEntry& joint, const mjtNum* qpos, double* dq,
                  std::vector<double>* slopes);

struct ModelCatalog {
  std::string model_name;
  std::vector<JointEntry> joints;  // indexed by joint id
  std::vector<int> actuated;       // joint ids in actuator order: the command vector's order
  // "effect:<name>" text fields: effect -> listed names, in file order.
  std::map<std::string, std::vector<std::string>> effect_parts;
  // "effect:<name>:<param>" numeric fields.
  std::map<std::string, std::vector<double>> effect_numbers;
  // Sites carrying both an MJCF gyro and an accelerometer (6-axis IMU mounts).
  std::vector<std::string> imu_sites;

  // Reads `m`. Throws InputError naming `model_name` for ball or free joints, actuators that
  // are not position servos on a joint, and effect fields naming missing or unsuitable parts.
  static ModelCatalog Build(const mjModel* m, const std::string& model_name);

  const JointEntry& Joint(int id) const { return joints.at(id); }
  // Joint ids listed under "effect:<effect>" (empty when the model lacks the field).
  std::vector<int> JointsOfEffect(const std::string& effect) const;
  bool HasEffectParts(const std::string& effect) const { return effect_parts.count(effect) > 0; }
  // Actuated joint names in command order.
  std::vector<std::string> ActuatedNames() const;
};

// Lateral compliance hinges (truth effect lateral_compliance): at joint J the MJCF provides two
// passive hinges named J_lateral_a and J_lateral_b in J's body, listed before J (they turn the
// parent-side housing, before J turns), at J's anchor, about a (the first of the body frame's x,
// y not along J's axis w, made normal to w) and b = w x a: the axes of the identification's
// joint_axis_tilt_a/b@J and lateral_compliance@J. The catalogue claims such hinges for the
// effect, so they stay locked at their reference unless it releases them.
// The name of J's hinge about a (axis 0) or b (axis 1).
std::string LateralHingeName(const std::string& joint, int axis);
// J's joint id when joint j is a passive hinge named J_lateral_a or J_lateral_b with J a later
// hinge of the same body; else -1.
int LateralHingeOf(const mjModel* m, int j);

}  // namespace flexbench::sim
