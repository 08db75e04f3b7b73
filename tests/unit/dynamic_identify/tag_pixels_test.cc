// The tag-pixel stream of dynamic identification and its folds. A tag's predicted corners are
// the model's tag frame seen through its camera: checked against corners computed here from raw
// MuJoCo data (geom pose, camera pose, pinhole by hand) at the rollout's own joint angle. A
// fold rolled alone gives its entries bit for bit as the whole rollout does, with the carried
// state of the segments just before it. Bad tag input is one line naming it.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <cmath>
#include <string>

#include "estimators/error.h"
#include "scenarios/identify/dynamic/fit.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"
#include "tests/unit/dynamic_identify/sine_log.h"

namespace flexbench::identify::dynamic {
namespace {

// A pendulum on a position servo with a tag plate at its tip and a camera looking at it.
constexpr char kXml[] = R"(<mujoco model="tagged"><compiler autolimits="true" angle="radian"/>
  <option timestep="0.001" integrator="Euler"/>
  <visual><global offwidth="640" offheight="480"/></visual>
  <worldbody>
    <camera name="cam" pos="0.2 -1.2 1.0" xyaxes="1 0 0 0 0 1" fovy="45"/>
    <body name="arm" pos="0 0 1">
      <joint name="j" axis="0 1 0" range="-2 2" damping="0.1" armature="0.01"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5"/>
      <geom name="tag" type="box" pos="0.3 -0.03 0" size="0.03 0.002 0.03" euler="0.3 0 0.2" mass="0.01"/>
    </body>
  </worldbody>
  <actuator><position name="j" joint="j" kp="20" ctrlrange="-1.5 1.5"/></actuator></mujoco>)";

constexpr double kHalf = 0.03;  // the tag's half side

// One and a half seconds at 500 Hz following a sine, the readings the commands themselves,
// and a tag row every 10 encoder rows whose corners are all (0, 0): its error is the prediction.
sim::RecordedLog TaggedLog() {
  sim::RecordedLog log = SineLog(0.5, 1.5);
  for (size_t k = 5; k < log.joint_t.size(); k += 10) {
    sim::LogTagRow r;
    r.t = log.joint_t[k];
    for (auto& uv : r.uv) uv.setZero();
    log.tag_rows.push_back(r);
  }
  const sim::MjModelPtr m = sim::LoadModelFromString(kXml, "tagged");
  log.cameras.push_back({"cam", "cam", sim::CameraIntrinsics(m.get(), 0)});
  sim::LogTag tag;
  tag.id = 7;
  tag.frame = "tag";
  // In the box's frame: the face towards the camera (-y), libapriltag's order.
  tag.corners_m = {Vec3(-kHalf, -0.002, kHalf), Vec3(kHalf, -0.002, kHalf),
                   Vec3(kHalf, -0.002, -kHalf), Vec3(-kHalf, -0.002, -kHalf)};
  log.tags.push_back(tag);
  log.pixel_std_px = 0.5;
  log.pixel_std_stated = true;
  return log;
}

// The corners by hand: the joint angle into a fresh mjData, the geom's and the camera's poses
// from MuJoCo's arrays, MuJoCo's camera (y up, looking along -z) turned into the optical frame.
std::array<Eigen::Vector2d, 4> CornersByHand(const mjModel* m, double q,
                                             const std::array<Vec3, 4>& corners) {
  mjData* d = mj_makeData(m);
  d->qpos[0] = q;
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_camlight(m, d);
  const int g = mj_name2id(m, mjOBJ_GEOM, "tag");
  Eigen::Matrix3d R_w_geom, R_w_cam;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      R_w_geom(i, j) = d->geom_xmat[9 * g + 3 * i + j];
      R_w_cam(i, j) = d->cam_xmat[3 * i + j];
    }
  }
  const Vec3 p_w_geom(d->geom_xpos[3 * g], d->geom_xpos[3 * g + 1], d->geom_xpos[3 * g + 2]);
  const Vec3 p_w_cam(d->cam_xpos[0], d->cam_xpos[1], d->cam_xpos[2]);
  mj_deleteData(d);
  const double f = 0.5 * 480 / std::tan(0.5 * 45.0 * M_PI / 180.0);
  std::array<Eigen::Vector2d, 4> uv;
  for (int c = 0; c < 4; ++c) {
    const Vec3 p_mj = R_w_cam.transpose() * (R_w_geom * corners[c] + p_w_geom - p_w_cam);
    const Vec3 p_opt(p_mj.x(), -p_mj.y(), -p_mj.z());
    uv[c] = Eigen::Vector2d(f * p_opt.x() / p_opt.z() + 320.0, f * p_opt.y() / p_opt.z() + 240.0);
  }
  return uv;
}

TEST(TagPixels, PredictedCornersAreTheModelsTagSeenByItsCamera) {
  RolloutModel model(sim::LoadModelFromString(kXml, "tagged"), "tagged", {});
  const sim::RecordedLog log = TaggedLog();
  const MotionData data = ReadMotionData(log, model.nominal(), {});
  ASSERT_EQ(data.tag_rows.size(), log.tag_rows.size());
  EXPECT_EQ(data.std_px, 0.5);
  EXPECT_TRUE(data.noise_from_log[3]);
  const ResidualLayout L = MakeLayout(data);
  const Prediction p = Rollout(model, {}, data, L);
  ASSERT_EQ(p.num_diverged, 0) << p.first_divergence;
  int checked = 0;
  double spread_px = 0.0;
  for (int k = 0; k < L.size(); ++k) {
    if (L.stream[k] != static_cast<char>(Stream::kTagPixel) || L.channel[k] != 0) continue;
    // The rollout's angle at this time: its encoder entry's error plus the reading.
    double q = std::nan("");
    for (int e = k - 1; e >= 0 && L.t[e] == L.t[k]; --e) {
      if (L.stream[e] == 0) q = p.error[e] + L.value[e];
    }
    for (int e = k + 1; e < L.size() && L.t[e] == L.t[k]; ++e) {
      if (L.stream[e] == 0) q = p.error[e] + L.value[e];
    }
    ASSERT_TRUE(std::isfinite(q)) << "no encoder entry at t = " << L.t[k];
    const auto uv = CornersByHand(model.nominal().model(), q, log.tags[0].corners_m);
    for (int c = 0; c < 4; ++c) {
      for (int x = 0; x < 2; ++x) {
        ASSERT_EQ(L.channel[k + 2 * c + x], 2 * c + x);
        EXPECT_NEAR(p.error[k + 2 * c + x], uv[c][x], 1e-6) << "t " << L.t[k];
        EXPECT_NEAR(p.residual[k + 2 * c + x], uv[c][x] / 0.5, 2e-6);
      }
    }
    spread_px = std::max(spread_px, std::abs(uv[0].x() - 320.0));
    ++checked;
  }
  EXPECT_GT(checked, 50);
  EXPECT_GT(spread_px, 20.0);  // the tag moved across the image
}

// A pendulum whose tip hangs on a passive spring hinge no encoder sees: its state is carried
// from segment to segment.
constexpr char kFlexXml[] = R"(<mujoco model="flex"><compiler autolimits="true" angle="radian"/>
  <option timestep="0.001" integrator="Euler"/>
  <worldbody><body name="arm" pos="0 0 1">
    <joint name="j" axis="0 1 0" range="-2 2" damping="0.1" armature="0.01"/>
    <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="0.5"/>
    <body name="tip" pos="0.3 0 0">
      <joint name="flex" axis="0 1 0" stiffness="20" damping="0.002"/>
      <geom type="sphere" pos="0.1 0 0" size="0.03" mass="0.3"/>
      <site name="imu" pos="0.1 0 0"/>
    </body></body></worldbody>
  <actuator><position name="j" joint="j" kp="20" ctrlrange="-1.5 1.5"/></actuator></mujoco>)";

// A fold's rollout starts from the static state a few segments before it, those rolled and not
// scored: a fold rolled alone is the whole rollout's fold, the tip's ringing reaches it from the
// segments just before, and what happens further back (here: the first segment's start speed)
// moves no later fold.
TEST(Folds, AFoldRollsAloneFromTheSegmentsJustBeforeIt) {
  RolloutModel model(sim::LoadModelFromString(kFlexXml, "flex"), "flex", {});
  sim::RecordedLog log = SineLog(0.6, 6.0, 0.7);  // 12 segments, 4 a fold
  log.imus.push_back({"imu", "imu", false, Quat::Identity()});
  log.gyro_std = 0.01;
  log.accel_std = 0.1;
  for (double t : log.joint_t) {
    estimators::ImuReading z;
    z.t = t;
    z.imu = 0;
    z.gyro = Vec3::Zero();
    z.accel = Vec3::Zero();
    log.imu.push_back(z);
  }
  const MotionData data = ReadMotionData(log, model.nominal(), {});
  ASSERT_EQ(data.segments.size(), 12u);
  const ResidualLayout L = MakeLayout(data);
  const Prediction whole = Rollout(model, {}, data, L);
  MotionData pushed = data;
  pushed.start_qd(0, 0) += 0.5;  // the first segment of fold 0 only
  const Prediction moved = Rollout(model, {}, pushed, L);
  for (int f = 0; f < data.folds; ++f) {
    Prediction alone = NewPrediction(data, L);
    EXPECT_EQ(RolloutFold(model, {}, data, L, f, &alone), "");
    double change = 0.0;
    for (int k = 0; k < L.size(); ++k) {
      if (data.segments[L.segment[k]].fold != f) {
        EXPECT_EQ(alone.residual[k], 0.0);
        continue;
      }
      ASSERT_EQ(alone.residual[k], whole.residual[k]) << "fold " << f << " entry " << k;
      change = std::max(change, std::abs(moved.residual[k] - whole.residual[k]));
    }
    if (f == 2) {
      EXPECT_EQ(change, 0.0) << "fold 2 saw the first segment";
    } else {
      // Fold 0 holds the pushed segment; fold 1's warm-up starts there, and the tip carries it.
      EXPECT_GT(change, 1e-3) << "fold " << f;
    }
  }
}

std::string ErrorOf(const sim::RecordedLog& log) {
  RolloutModel model(sim::LoadModelFromString(kXml, "tagged"), "tagged", {});
  try {
    ReadMotionData(log, model.nominal(), {});
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    return e.what();
  }
  return "";
}

TEST(TagPixels, BadTagInputIsOneLineNamingIt) {
  sim::RecordedLog no_frame = TaggedLog();
  no_frame.tags[0].frame = "sticker";
  EXPECT_NE(ErrorOf(no_frame).find("tag 7: frame 'sticker'"), std::string::npos)
      << ErrorOf(no_frame);
  sim::RecordedLog no_camera = TaggedLog();
  no_camera.cameras[0].frame = "eye";
  EXPECT_NE(ErrorOf(no_camera).find("camera 'cam': frame 'eye'"), std::string::npos);
  sim::RecordedLog images = TaggedLog();
  images.tag_rows.clear();
  images.images.push_back({0.1, 0, "images/cam/100000000.png"});
  EXPECT_NE(ErrorOf(images).find("images only"), std::string::npos);
  EXPECT_EQ(ErrorOf(TaggedLog()), "");
}

// A log that does not state its pixels' noise: the format's 1 px is not taken for it; the
// spread of the declared model's residual is (as for every stream a log leaves out).
TEST(TagPixels, UnstatedPixelNoiseComesFromTheResidual) {
  RolloutModel model(sim::LoadModelFromString(kXml, "tagged"), "tagged", {});
  sim::RecordedLog log = TaggedLog();
  log.pixel_std_stated = false;
  MotionData data = ReadMotionData(log, model.nominal(), {});
  EXPECT_FALSE(data.noise_from_log[3]);
  EXPECT_EQ(data.std_px, 0.0);
  const ResidualLayout L = MakeLayout(data);
  SetUnknownNoise(L, Rollout(model, {}, data, L).error, &data);
  // The readings are all (0, 0) while the tag moves: its first differences are the motion's.
  EXPECT_GT(data.std_px, 1.0);
  EXPECT_TRUE(std::isfinite(data.std_px));
}

}  // namespace
}  // namespace flexbench::identify::dynamic
