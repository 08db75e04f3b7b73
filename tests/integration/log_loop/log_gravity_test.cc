// The closed loop on a log's IMUs at rest (gravity rows): the up direction each accelerometer
// measures where the arm stands still, against the declared model's at the encoders' readings.
// Logs from MuJoCo runs exported with --export-log, and from the independent writer
// (tests/common/jsk_log.h) with rests in its motion; identified on the IMUs alone (`streams:
// [imu]`), the truth.tum kept for scoring the held-out replay only.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/common/jsk_log.h"
#include "tests/common/test_util.h"
#include "tests/integration/log_loop/loop_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;
using testing::ExportMujocoRun;
using testing::HeldOut;
using testing::Print;
using testing::RunLoop;

// The IMUs alone; the encoders are quantised to 4096 counts a turn (0.44 mrad rms a joint):
// the up direction is stated to 1 mrad.
const char kImuOnly[] = ", streams: [imu]";
const char kImuStd[] = "gravity_std_rad: 0.001\n";

// A joint offset in MuJoCo's truth, seen by the IMUs at the trajectory's rests: named first at
// every seed (alone at 8 of seeds 1-10; at 4 and 8 a small second entry at link3), and the
// held-out span's replayed fk error falls below half.
TEST(LogGravity, IMUsAtRestNameAJointOffsetInAMujocoRun) {
  for (int seed = 1; seed <= 3; ++seed) {
    testing::TempDir tmp;
    const fs::path log =
        ExportMujocoRun(tmp.path(), "{joint_offset: {offset_deg: {link2_pitch_joint: 1.5}}}", seed);
    const nlohmann::json m =
        RunLoop(tmp.path(), log, 15.0, {"joint_offset@link2_pitch_joint"}, "", kImuOnly, kImuStd);
    Print(("MuJoCo run, joint offset 1.5 deg, IMUs at rest, seed " + std::to_string(seed)).c_str(),
          m);
    ASSERT_FALSE(m["effects_found"].empty()) << seed;
    EXPECT_EQ(m["effects_found"][0].get<std::string>().rfind("joint_offset@link2_pitch_joint", 0),
              0u)
        << seed;
    EXPECT_LT(HeldOut(m, "after"), 0.5 * HeldOut(m, "before")) << seed;
    // Judged in degrees: every row is a gravity row.
    EXPECT_LT(m["val_err_after_gravity_deg"].get<double>(),
              0.1 * m["val_err_before_gravity_deg"].get<double>());
    EXPECT_EQ(m["calibration_rows"], 6) << "three rests before 15 s, two IMUs";
  }
}

// The independent writer's arm rests 1 s after every 2 s of motion; both pitch encoders read
// 0.05 rad off. Both offsets are named (up to what the data cannot tell apart) and the held-out
// error falls below half.
TEST(LogGravity, IMUsAtRestNameOffsetEncodersInAnIndependentLog) {
  testing::TempDir tmp;
  testing::JskLogOptions o;
  o.duration = 30.0;
  o.move_s = 2.0;
  o.rest_s = 1.0;
  testing::WriteJskLog(tmp.path() / "log", o);
  const nlohmann::json m = RunLoop(
      tmp.path(), tmp.path() / "log", 20.0,
      {"joint_offset@link2_pitch_joint", "joint_offset@link3_pitch_joint"}, "", kImuOnly, kImuStd);
  Print("independent log with rests, pitch encoders 0.05 rad off, IMUs at rest", m);
  EXPECT_TRUE(m["effects_named_up_to_equivalence"].get<bool>());
  EXPECT_LT(HeldOut(m, "after"), 0.5 * HeldOut(m, "before"));
}

// An accelerometer's bias is no effect of the kinematics: whatever the loop names for it from
// the IMUs (it is there in the rows), the held-out truth replays worse with it, the verdict is
// unexplained and no augmented model is written.
TEST(LogGravity, AnAccelerometerBiasIsNeverExplained) {
  for (const double bias : {0.05, 0.1, 0.2}) {
    testing::TempDir tmp;
    testing::JskLogOptions o;
    o.duration = 30.0;
    o.pitch_offset = 0.0;
    o.move_s = 2.0;
    o.rest_s = 1.0;
    o.imu3_accel_bias = Vec3(bias, -0.5 * bias, 0.0);
    testing::WriteJskLog(tmp.path() / "log", o);
    const nlohmann::json m =
        RunLoop(tmp.path(), tmp.path() / "log", 20.0, {}, "", kImuOnly, kImuStd);
    char what[96];
    std::snprintf(what, sizeof(what), "independent log, imu3's accelerometer %.2f m/s^2 off", bias);
    Print(what, m);
    EXPECT_EQ(m["verdict"], "unexplained") << bias;
    EXPECT_TRUE(m["heldout_replay_worse"].get<bool>()) << bias;
    EXPECT_FALSE(fs::exists(tmp.path() / "loop" / "declared_augmented.yaml")) << bias;
  }
}

}  // namespace
}  // namespace flexbench
