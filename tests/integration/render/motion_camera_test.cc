// closed_loop_dynamic's tag camera (scenarios/runner/common/motion_camera.h) renders the state
// the simulation is in: after a step, MuJoCo's body poses are the step's start's until they are
// asked for, and a frame taken then would show the arm one step late.
#include "scenarios/runner/common/motion_camera.h"

#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <cmath>

#include "sim/recorded_log.h"
#include "sim/simulation.h"
#include "tests/common/test_util.h"

namespace flexbench::scenarios {
namespace {

TEST(MotionCamera, RendersTheStateAfterTheStep) {
  auto sim = sim::Simulation::Load(testing::SourceDir() + "/models/jsk_arm.xml");
  MotionCameraSpec spec;
  spec.camera = "external_camera";
  spec.rate_hz = 1000.0;  // a frame at every step
  MotionTagCamera camera(*sim, spec, {"external_camera", "tag_gripper", "tag_base"});
  Eigen::VectorXd cmd = Eigen::VectorXd::Zero(sim->num_actuated());
  sim->SetCommand(cmd);
  sim->Settle();
  cmd[0] = 1.0;  // the yaw servo swings the arm round
  sim->SetCommand(cmd);
  const mjModel* m = sim->model();
  mjData* fresh = mj_makeData(m);
  const int g = mj_name2id(m, mjOBJ_GEOM, "tag_gripper");
  double moved = 0.0;
  for (int k = 0; k < 40; ++k) {
    const Eigen::Vector3d before(sim->data()->geom_xpos + 3 * g);
    sim->Step(1);
    camera.AfterPoll(*sim);
    // The poses the frame was drawn from against the kinematics of the state now.
    mju_copy(fresh->qpos, sim->data()->qpos, m->nq);
    mj_kinematics(m, fresh);
    const Eigen::Vector3d drawn(sim->data()->geom_xpos + 3 * g), now(fresh->geom_xpos + 3 * g);
    EXPECT_LT((drawn - now).norm(), 1e-12) << "step " << k;
    moved = std::max(moved, (now - before).norm());
  }
  mj_deleteData(fresh);
  EXPECT_GT(moved, 1e-5);  // the tag moved within a step: a stale frame would show it
  sim::RecordedLog log;
  EXPECT_EQ(camera.AddTo(&log), 40);
  EXPECT_EQ(log.cameras.size(), 1u);
  EXPECT_EQ(log.tags.size(), 2u);
  EXPECT_GE(log.tag_rows.size(), 40u);  // a tag in every frame
}

}  // namespace
}  // namespace flexbench::scenarios
