// The truth models as a camera and an estimator see them: the rover's end-effector tags are
// visible and detectable from the mast camera in typical poses (libapriltag against the true
// corners projected through the model's camera), and the declared-model files agree with
// their MJCF.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <set>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "sim/camera.h"
#include "sim/declared_check.h"
#include "sim/effects/effect.h"
#include "sim/simulation.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

std::string Models() { return std::string(FLEXBENCH_SOURCE_DIR) + "/models/"; }

Eigen::VectorXd Command(const sim::Simulation& sim, const std::map<std::string, double>& deg) {
  Eigen::VectorXd q = Eigen::VectorXd::Zero(sim.num_actuated());
  const auto& names = sim.actuated_joints();
  for (const auto& [j, v] : deg)
    q[std::find(names.begin(), names.end(), j) - names.begin()] = v * kDeg;
  return q;
}

// Pan and tilt the mast so that the camera looks at the nominal end effector.
void AimMast(const sim::Simulation& sim, Eigen::VectorXd* q) {
  const auto& names = sim.actuated_joints();
  const int pan = std::find(names.begin(), names.end(), "mast_pan") - names.begin();
  const int tilt = std::find(names.begin(), names.end(), "mast_tilt") - names.begin();
  (*q)[pan] = (*q)[tilt] = 0.0;
  const Vec3 d =
      sim.NominalPose("ee", *q).translation() - sim.NominalPose("mast_tilt_link", *q).translation();
  (*q)[pan] = std::atan2(d.y(), d.x());
  (*q)[tilt] = std::atan2(-d.z(), std::hypot(d.x(), d.y()));
}

TEST(RoverTags, DistinctIdsAndDetectableSize) {
  sim::MjModelPtr m = sim::LoadModel(Models() + "rover_arm.xml");
  const auto tags = render::ApplyTagTextures(m.get());
  ASSERT_EQ(tags.size(), 4u);
  std::set<int> ids;
  for (const auto& t : tags) {
    EXPECT_EQ(t.family, "tag36h11");
    ids.insert(t.id);
    EXPECT_GE(t.size_m, 0.06 - 1e-6);
    EXPECT_LE(t.size_m, 0.08);
    EXPECT_EQ(sim::ObjectName(m.get(), mjOBJ_BODY, m->geom_bodyid[t.geom_id]), "hand");
  }
  EXPECT_EQ(ids.size(), 4u);
}

TEST(RoverTags, VisibleAndDetectedFromTheMastCameraInTypicalPoses) {
  sim::EffectList fx;
  fx.push_back(sim::MakeEffect("base_compliance"));
  fx.push_back(sim::MakeEffect("link_bending"));
  auto sim = sim::Simulation::Load(Models() + "rover_arm.xml", fx);
  const auto tags = render::ApplyTagTextures(sim->mutable_model());
  render::Renderer renderer(sim->model(), render::RenderMode::kQuality);
  render::TagDetector detector(render::DetectorSettings{});
  const int cam_id = sim::CameraId(sim->model(), "mast_camera");
  const PinholeCamera cam = sim::CameraIntrinsics(sim->model(), cam_id);
  // Stretched out (PPOE exp. II) and close in (exp. I), forward, diagonal and sideways.
  const std::vector<std::map<std::string, double>> poses = {
      {{"j2", 90}, {"j5", -30}},
      {{"j1", 20}, {"j2", 75}, {"j3", 20}, {"j5", -35}},
      {{"j1", -25}, {"j2", 95}, {"j3", 10}, {"j5", -40}},
      {{"j1", 45}, {"j2", 60}, {"j3", 40}, {"j5", -40}},
      {{"j1", 90}, {"j2", 90}, {"j5", -30}},
      {{"j1", -90}, {"j2", 80}, {"j3", 10}, {"j5", -30}},
      {{"j2", 0}, {"j3", 150}, {"j5", -90}},
      {{"j2", 30}, {"j3", 100}, {"j5", -70}, {"j6", 30}},
  };
  for (size_t p = 0; p < poses.size(); ++p) {
    Eigen::VectorXd q = Command(*sim, poses[p]);
    AimMast(*sim, &q);
    sim->SetCommand(q);
    sim->Settle();
    mjData* d = const_cast<mjData*>(sim->data());
    const render::Image frame = renderer.RenderRgb(d, cam_id);
    const render::DetectionResult result = detector.Detect(frame);
    const Eigen::Isometry3d T_cam_w = sim::WorldFromOptical(d, cam_id).inverse();
    int matched = 0;
    double worst = 0.0;
    double sum_sq = 0.0;
    for (const auto& det : result.detections) {
      for (const auto& tag : tags) {
        if (tag.id != det.id) continue;
        ++matched;
        const auto corners = render::TagCornersWorld(d, tag);
        for (int k = 0; k < 4; ++k) {
          Eigen::Vector2d uv;
          ASSERT_TRUE(cam.Project(T_cam_w * corners[k], &uv));
          worst = std::max(worst, (det.corners[k] - uv).norm());
          sum_sq += (det.corners[k] - uv).squaredNorm();
        }
      }
    }
    EXPECT_EQ(matched, static_cast<int>(result.detections.size())) << "pose " << p;
    EXPECT_GE(matched, 1) << "pose " << p << ": no end-effector tag detected";
    // Sub-pixel corners (the smoke scenario's bar), a little more at grazing angles.
    EXPECT_LT(std::sqrt(sum_sq / std::max(1, 4 * matched)), 1.0) << "pose " << p;
    EXPECT_LT(worst, 2.0) << "pose " << p;
    std::printf("pose %zu: %d tags, corner rmse %.3f px, worst %.3f px\n", p, matched,
                std::sqrt(sum_sq / std::max(1, 4 * matched)), worst);
    const double dist =
        (sim->Pose("ee").translation() - sim->Pose("mast_camera").translation()).norm();
    EXPECT_LT(dist, 1.7) << "pose " << p;
  }
}

TEST(DeclaredFiles, AgreeWithTheirModels) {
  for (const std::string name : {"rover_arm", "humanoid_upper", "jsk_arm"}) {
    const sim::DeclaredCheckSummary d = sim::CheckDeclaredFile(Models() + name + ".declared.yaml");
    EXPECT_EQ(d.model_path, Models() + name + ".xml");
    EXPECT_FALSE(d.actuated_joints.empty());
    EXPECT_FALSE(d.sources.empty());
    // Declared actuated joints are actuated in the truth; its end effector exists.
    auto sim = sim::Simulation::Load(d.model_path);
    for (const std::string& j : d.actuated_joints) {
      EXPECT_EQ(sim->catalog().Joint(sim::JointId(sim->model(), j)).role, sim::JointRole::kActuated)
          << name << ": " << j;
    }
  }
}

TEST(DeclaredFiles, NamesTheMissingJointOrFrameWithFileAndLine) {
  testing::TempDir tmp;
  const std::string model = Models() + "rover_arm.xml";
  const auto write = [&](const std::string& body) {
    const auto p = tmp.path() / "bad.declared.yaml";
    testing::WriteFile(p, "model: " + model + "\n" + body);
    return p.string();
  };
  const auto expect_error = [&](const std::string& path, const std::string& what) {
    try {
      sim::CheckDeclaredFile(path);
      FAIL() << "accepted: " << what;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  };
  expect_error(write("actuated_joints: [j1, j9]\nend_effector: ee\n"),
               ":2: key 'actuated_joints[1]'");
  expect_error(write("actuated_joints: [j1, j9]\nend_effector: ee\n"),
               "no hinge or slide joint named 'j9'");
  expect_error(write("actuated_joints: [j1]\nend_effector: nowhere\n"),
               "no site or body named 'nowhere'");
  expect_error(write("actuated_joints: [j1]\nend_effector: ee\nobserved_frames: [tag_99]\n"),
               "no site, camera, geom or body named 'tag_99'");
  expect_error(write("actuated_joints: [j1]\nend_effector: ee\nsources:\n  - {at: plate_yaw, "
                     "about_axis_deg: 1}\n"),
               "no joint or body named 'plate_yaw'");
  expect_error(write("actuated_joints: [j1]\nend_effector: ee\nsources:\n  - {at: base_plate, "
                     "about_axis_deg: 1}\n"),
               "about_axis_deg needs a joint");
  expect_error(write("actuated_joints: [j1]\nend_effector: ee\ncolour: red\n"),
               "unknown key 'colour'");
}

}  // namespace
}  // namespace flexbench
