// Offscreen rendering and the AprilTag pipeline on inline models.
#include <gtest/gtest.h>

#include <cmath>

#include "estimators/error.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"

namespace flexbench::render {
namespace {

// A 0.12 m tag plate (black border 0.08 m) facing a camera 0.5 m away, frontal.
std::string FrontalTagXml(int id, double yaw_deg) {
  return R"(<mujoco><compiler angle="degree"/>
  <visual><global offwidth="640" offheight="480"/></visual>
  <asset>
    <mesh name="plate" scale="0.06 0.06 0.002"
      vertex="-1 -1 0  1 -1 0  1 1 0  -1 1 0  -1 -1 -1  1 -1 -1  1 1 -1  -1 1 -1"
      texcoord="0 1  1 1  1 0  0 0  0.02 0.02  0.02 0.02  0.02 0.02  0.02 0.02"
      face="0 1 2  0 2 3  4 6 5  4 7 6  0 4 5  0 5 1  1 5 6  1 6 2  2 6 7  2 7 3  3 7 4  3 4 0"/>
    <texture name="apriltag_tag36h11_)" +
         std::to_string(id) + R"(" type="2d" builtin="flat" width="240" height="240" rgb1="1 1 1"/>
    <material name="tag" texture="apriltag_tag36h11_)" +
         std::to_string(id) + R"("/>
  </asset>
  <worldbody>
    <light pos="0 0 2" dir="0 0 -1"/>
    <body name="tag" pos="0.02 -0.01 0" euler="0 0 )" +
         std::to_string(yaw_deg) + R"(">
      <geom name="tag" type="mesh" mesh="plate" material="tag" contype="0" conaffinity="0"/>
    </body>
    <camera name="cam" pos="0 0 0.5" xyaxes="1 0 0 0 1 0"/>
  </worldbody></mujoco>)";
}

struct Rendered {
  Image frame;
  std::vector<TagInModel> tags;
  std::array<Eigen::Vector2d, 4> truth;
};

Rendered RenderTag(int id, double yaw_deg, RenderMode mode) {
  sim::MjModelPtr m = sim::LoadModelFromString(FrontalTagXml(id, yaw_deg));
  Rendered r;
  r.tags = ApplyTagTextures(m.get());
  sim::MjDataPtr d = sim::MakeData(m.get());
  mj_forward(m.get(), d.get());
  Renderer renderer(m.get(), mode);
  r.frame = renderer.RenderRgb(d.get(), 0);
  const PinholeCamera cam = sim::CameraIntrinsics(m.get(), 0);
  const Eigen::Isometry3d T_cam_w = sim::WorldFromOptical(d.get(), 0).inverse();
  const auto corners = TagCornersWorld(d.get(), r.tags.at(0));
  for (int k = 0; k < 4; ++k) EXPECT_TRUE(cam.Project(T_cam_w * corners[k], &r.truth[k]));
  return r;
}

class FrontalTag : public ::testing::TestWithParam<std::tuple<int, double, RenderMode>> {};

TEST_P(FrontalTag, DetectedCornersMatchProjectedTruth) {
  const auto [id, yaw, mode] = GetParam();
  const Rendered r = RenderTag(id, yaw, mode);
  ASSERT_EQ(r.tags.size(), 1u);
  EXPECT_NEAR(r.tags[0].size_m, 0.08, 1e-6);
  TagDetector detector(DetectorSettings{});
  const DetectionResult result = detector.Detect(r.frame);
  ASSERT_EQ(result.detections.size(), 1u);
  EXPECT_EQ(result.detections[0].id, id);
  double sum_sq = 0.0;
  for (int k = 0; k < 4; ++k)
    sum_sq += (result.detections[0].corners[k] - r.truth[k]).squaredNorm();
  EXPECT_LT(std::sqrt(sum_sq / 4), 0.5) << "corner RMSE against the projected truth";
}

INSTANTIATE_TEST_SUITE_P(IdsRotationsModes, FrontalTag,
                         ::testing::Values(std::make_tuple(0, 0.0, RenderMode::kQuality),
                                           std::make_tuple(7, 33.0, RenderMode::kQuality),
                                           std::make_tuple(586, -120.0, RenderMode::kFast),
                                           std::make_tuple(101, 180.0, RenderMode::kFast)));

// A camera that sees nothing, and a model whose state is not finite (what a diverging
// simulation leaves): bad input naming the camera, not an internal error.
TEST(Render, AFrameOfOneColourIsBadInputNamingTheCamera) {
  sim::MjModelPtr m = sim::LoadModelFromString(R"(<mujoco>
  <visual><global offwidth="64" offheight="48"/></visual>
  <worldbody>
    <light pos="0 0 2" dir="0 0 -1"/>
    <body name="box" pos="0 0 -1"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>
    <camera name="up" pos="0 0 0" xyaxes="1 0 0 0 -1 0"/>
    <camera name="down" pos="0 0 0" xyaxes="1 0 0 0 1 0"/>
  </worldbody></mujoco>)");
  sim::MjDataPtr d = sim::MakeData(m.get());
  mj_forward(m.get(), d.get());
  Renderer renderer(m.get(), RenderMode::kFast);
  EXPECT_NO_THROW(renderer.RenderRgb(d.get(), 1));  // looks down at the box
  for (bool diverged : {false, true}) {
    if (diverged) {
      d->qpos[0] = std::nan("");
      mj_kinematics(m.get(), d.get());
    }
    try {
      renderer.RenderRgb(d.get(), diverged ? 1 : 0);
      ADD_FAILURE() << "no error, diverged " << diverged;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(diverged ? "camera 'down'" : "camera 'up'"), std::string::npos) << msg;
      EXPECT_EQ(msg.find("not finite") != std::string::npos, diverged) << msg;
      EXPECT_EQ(msg.find('\n'), std::string::npos);
    }
  }
}

TEST(Render, SameStateSameBytes) {
  const Rendered a = RenderTag(3, 10.0, RenderMode::kQuality);
  const Rendered b = RenderTag(3, 10.0, RenderMode::kQuality);
  EXPECT_EQ(a.frame.data, b.frame.data);
  EXPECT_FALSE(IsConstant(a.frame));
}

TEST(Render, TagIdOutsideFamilyIsBadInput) {
  sim::MjModelPtr m = sim::LoadModelFromString(FrontalTagXml(587, 0.0));  // 36h11 has 587 ids
  try {
    ApplyTagTextures(m.get());
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("outside family tag36h11"), std::string::npos) << e.what();
  }
}

TEST(Render, UnknownDetectorFamilyIsBadInput) {
  DetectorSettings s;
  s.family = "tag99h99";
  EXPECT_THROW(TagDetector{s}, InputError);
}

}  // namespace
}  // namespace flexbench::render
