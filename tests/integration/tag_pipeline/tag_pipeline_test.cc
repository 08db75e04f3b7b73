// The camera pipeline of render/: deterministic frames and degradations, the frame clock, tag
// detection against the projected truth, the grazing/size/border gates (a tag is reported
// missing, never with a wrong pose), tag pose with det(R) = +1, overlays, and the
// tag_detection_sweep scenario's bad-input handling.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <nlohmann/json.hpp>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "render/camera_stream.h"
#include "render/degrade.h"
#include "render/overlay.h"
#include "render/renderer.h"
#include "render/tag_covariance.h"
#include "render/tag_detector.h"
#include "render/tag_pose.h"
#include "render/tag_texture.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::render {
namespace {

namespace fs = std::filesystem;
using testing::CommandResult;
using testing::RunCommand;
using testing::TempDir;

// models/tag_board.xml: camera at the world origin with MuJoCo's identity orientation, so the
// optical frame is diag(1, -1, -1) in the world. The board is a mocap body whose origin is the
// tag centre.
struct TagScene {
  sim::MjModelPtr model;
  sim::MjDataPtr data;
  std::vector<TagInModel> tags;
  PinholeCamera cam;

  TagScene() {
    model = sim::LoadModel(testing::SourceDir() + "/models/tag_board.xml");
    tags = ApplyTagTextures(model.get());
    data = sim::MakeData(model.get());
    cam = sim::CameraIntrinsics(model.get(), 0);
  }

  // Tag centre `distance` in front of the camera (optical x, y offsets), rotated out of plane
  // by `view_deg` about the tag's y axis and in plane by `rot_deg`.
  void Place(double distance, double view_deg, double rot_deg, double x = 0.0, double y = 0.0) {
    const Quat q(Eigen::AngleAxisd(view_deg * M_PI / 180, Eigen::Vector3d::UnitY()) *
                 Eigen::AngleAxisd(rot_deg * M_PI / 180, Eigen::Vector3d::UnitZ()));
    data->mocap_pos[0] = x;
    data->mocap_pos[1] = -y;
    data->mocap_pos[2] = -distance;
    QuatToWxyz(q, data->mocap_quat);
    mj_forward(model.get(), data.get());
  }

  std::array<Eigen::Vector3d, 4> CornersCam() const {
    const Eigen::Isometry3d T_cam_w = sim::WorldFromOptical(data.get(), 0).inverse();
    const auto w = TagCornersWorld(data.get(), tags.at(0));
    std::array<Eigen::Vector3d, 4> out;
    for (int k = 0; k < 4; ++k) out[k] = T_cam_w * w[k];
    return out;
  }

  std::array<Eigen::Vector2d, 4> Truth() const {
    std::array<Eigen::Vector2d, 4> uv;
    const auto c = CornersCam();
    for (int k = 0; k < 4; ++k) EXPECT_TRUE(cam.Project(c[k], &uv[k]));
    return uv;
  }
};

double CornerRmse(const TagDetection& det, const std::array<Eigen::Vector2d, 4>& truth) {
  double sq = 0.0;
  for (int k = 0; k < 4; ++k) sq += (det.corners[k] - truth[k]).squaredNorm();
  return std::sqrt(sq / 4);
}

TEST(Rendering, SameStateSameBytesInBothModesAndGrayMatchesToGray) {
  TagScene s;
  s.Place(0.7, 20, 15);
  for (RenderMode mode : {RenderMode::kFast, RenderMode::kQuality}) {
    Renderer r(s.model.get(), mode);
    const Image a = r.RenderRgb(s.data.get(), 0);
    const Image b = r.RenderRgb(s.data.get(), 0);
    EXPECT_EQ(a.data, b.data);
    EXPECT_EQ(a.width, 640);
    EXPECT_EQ(a.height, 480);
    Image gray;
    r.RenderGrayInto(s.data.get(), 0, &gray);
    EXPECT_EQ(gray.data, ToGray(a).data);
  }
}

TEST(Degradation, SameSeedSameBytesAndTheNoiseHasItsStd) {
  Image flat{200, 100, 1, std::vector<std::uint8_t>(200 * 100, 100)};
  Degradation deg;
  deg.noise_std = 6.0;
  deg.blur_sigma_px = 0.8;
  deg.gain = 0.9;
  deg.offset = 5.0;
  Image a = flat, b = flat, c = flat;
  std::mt19937_64 ra(42), rb(42), rc(43);
  ApplyDegradation(deg, ra, &a);
  ApplyDegradation(deg, rb, &b);
  ApplyDegradation(deg, rc, &c);
  EXPECT_EQ(a.data, b.data);
  EXPECT_NE(a.data, c.data);
  double sum = 0.0, sq = 0.0;
  for (std::uint8_t v : a.data) {
    sum += v;
    sq += v * v;
  }
  const double n = a.data.size();
  const double mean = sum / n;
  EXPECT_NEAR(mean, 0.9 * 100 + 5, 0.2);
  // Rounding to 8 bits adds 1/12 gray level^2.
  EXPECT_NEAR(std::sqrt(sq / n - mean * mean), std::sqrt(36.0 + 1.0 / 12), 0.1);
  // Identity leaves the frame alone.
  Image d = flat;
  std::mt19937_64 rd(1);
  ApplyDegradation(Degradation{}, rd, &d);
  EXPECT_EQ(d.data, flat.data);
}

TEST(Degradation, OccluderFallsInsideTheRegionOfInterest) {
  Degradation deg;
  deg.occlusion_probability = 1.0;
  deg.occlusion_size_px = 10;
  const PixelRect roi{100, 50, 120, 60};
  std::mt19937_64 rng(5);
  for (int i = 0; i < 20; ++i) {
    Image img{200, 100, 3, std::vector<std::uint8_t>(200 * 100 * 3, 0)};
    const DegradationReport rep = ApplyDegradation(deg, rng, &img, &roi);
    ASSERT_TRUE(rep.occluded);
    const double cx = 0.5 * (rep.occluder.x0 + rep.occluder.x1);
    const double cy = 0.5 * (rep.occluder.y0 + rep.occluder.y1);
    EXPECT_GE(cx, roi.x0 - 1);
    EXPECT_LE(cx, roi.x1 + 1);
    EXPECT_GE(cy, roi.y0 - 1);
    EXPECT_LE(cy, roi.y1 + 1);
  }
}

TEST(Degradation, BadParametersAreInputErrors) {
  Degradation deg;
  deg.noise_std = -1;
  EXPECT_THROW(ValidateDegradation(deg), InputError);
  deg = Degradation{};
  deg.occlusion_probability = 1.5;
  EXPECT_THROW(ValidateDegradation(deg), InputError);
  deg = Degradation{};
  deg.gain = 0.0;
  EXPECT_THROW(ValidateDegradation(deg), InputError);
}

TEST(FrameClock, FramesAtTheRateWithoutDriftAndSkipsCounted) {
  FrameClock clock(30.0);
  std::vector<FrameStamp> stamps;
  const double dt = 0.002;
  for (int step = 0; step <= 5000; ++step) {  // 10 s of 2 ms steps
    const double t = step * dt;
    if (clock.Due(t)) stamps.push_back(clock.Take(t));
  }
  ASSERT_EQ(stamps.size(), 301u);  // t = 0, 1/30, ..., 10
  for (size_t k = 0; k < stamps.size(); ++k) {
    EXPECT_EQ(stamps[k].index, static_cast<std::int64_t>(k));
    EXPECT_NEAR(stamps[k].nominal_time_s, k / 30.0, 1e-12);
    EXPECT_GE(stamps[k].time_s, stamps[k].nominal_time_s - 1e-9);
    EXPECT_LT(stamps[k].time_s - stamps[k].nominal_time_s, dt);
  }
  EXPECT_EQ(clock.skipped(), 0);
  // A step over three frame times delivers one frame (the latest) and counts two skipped.
  FrameClock coarse(10.0);
  ASSERT_TRUE(coarse.Due(0.0));
  coarse.Take(0.0);
  EXPECT_FALSE(coarse.Due(0.05));
  const FrameStamp s = coarse.Take(0.31);
  EXPECT_EQ(s.index, 3);
  EXPECT_EQ(coarse.skipped(), 2);
  EXPECT_THROW(FrameClock(0.0), InputError);
}

TEST(CameraStream, SeededFramesRepeat) {
  TagScene s;
  s.Place(0.8, 10, 5);
  Renderer r(s.model.get(), RenderMode::kFast);
  Degradation deg;
  deg.noise_std = 3.0;
  CameraStream a(&r, 0, 20.0, deg, 9);
  CameraStream b(&r, 0, 20.0, deg, 9);
  for (double t : {0.0, 0.01, 0.05, 0.1}) {
    const auto fa = a.Poll(s.data.get(), t);
    const auto fb = b.Poll(s.data.get(), t);
    ASSERT_EQ(fa.has_value(), fb.has_value());
    if (!fa) continue;
    EXPECT_EQ(fa->rgb.data, fb->rgb.data);
    EXPECT_EQ(fa->gray.data, ToGray(fa->rgb).data);
    EXPECT_NEAR(fa->gray_noise_std, 3.0 * 0.6686, 1e-3);
  }
  EXPECT_EQ(a.clock().next_time_s(), 0.15);
}

// Clean frontal 640x480 frames (several in-plane rotations and distances): corners within
// 0.5 px RMS of the projected truth, covariances positive definite, pose with det(R) = +1.
TEST(Detection, CleanFrontalCornersMatchProjectedTruth) {
  TagScene s;
  for (RenderMode mode : {RenderMode::kFast, RenderMode::kQuality}) {
    Renderer r(s.model.get(), mode);
    DetectorSettings settings;
    settings.max_view_angle_deg = 75;
    TagDetector detector(settings);
    for (double rot : {0.0, 17.0, 45.0, 100.0}) {
      for (double distance : {0.4, 0.8}) {
        s.Place(distance, 0.0, rot, 0.01, -0.02);
        const DetectionResult res = detector.Detect(r.RenderRgb(s.data.get(), 0));
        ASSERT_EQ(res.detections.size(), 1u) << "rot " << rot << " d " << distance;
        const TagDetection& det = res.detections[0];
        EXPECT_EQ(det.id, 0);
        EXPECT_LT(CornerRmse(det, s.Truth()), 0.5);
        // acos(ratio) is steep near 0 deg: 0.1 px corner noise reads as a few degrees.
        EXPECT_LT(det.view_angle_deg, 10.0);
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 8, 8>> eig(det.corners_cov);
        EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0);
        EXPECT_GT(det.center_cov.determinant(), 0.0);
      }
    }
  }
}

// 78-85 deg views: libapriltag still decodes some of them, with corners off by pixels. With
// the view-angle gate they are reported missing (and counted), never as a detection.
TEST(Detection, GrazingViewsAreMissingNeverWrong) {
  TagScene s;
  Renderer r(s.model.get(), RenderMode::kFast);
  DetectorSettings gated;
  gated.max_view_angle_deg = 75;
  TagDetector detector(gated);
  TagDetector ungated(DetectorSettings{});
  int decoded_without_gate = 0;
  int dropped = 0;
  for (double view : {78.0, 80.0, 83.0, 85.0}) {
    for (double rot : {0.0, 30.0, 60.0}) {
      s.Place(0.5, view, rot);
      const Image frame = r.RenderRgb(s.data.get(), 0);
      const DetectionResult res = detector.Detect(frame);
      EXPECT_TRUE(res.detections.empty()) << "view " << view << " rot " << rot;
      dropped += res.dropped_grazing;
      decoded_without_gate += static_cast<int>(ungated.Detect(frame).detections.size());
    }
  }
  EXPECT_EQ(dropped, decoded_without_gate) << "every decode at a grazing angle is counted";
  EXPECT_GT(decoded_without_gate, 0) << "the gate is what keeps them out";
}

TEST(Detection, TinyTagsAreMissingOrDroppedBySize) {
  TagScene s;
  Renderer r(s.model.get(), RenderMode::kFast);
  DetectorSettings settings;
  settings.min_edge_px = 12;
  TagDetector detector(settings);
  // 4.5 m: about 10 px edges (decodes, dropped by the size gate); 8 m: about 6 px (no decode).
  s.Place(4.5, 0, 10);
  DetectionResult res = detector.Detect(r.RenderRgb(s.data.get(), 0));
  EXPECT_TRUE(res.detections.empty());
  EXPECT_EQ(res.dropped_small, 1);
  s.Place(8.0, 0, 10);
  res = detector.Detect(r.RenderRgb(s.data.get(), 0));
  EXPECT_TRUE(res.detections.empty());
}

TEST(Detection, TagCutByTheFrameBorderIsDroppedByTheVisibilityGate) {
  TagScene s;
  Renderer r(s.model.get(), RenderMode::kFast);
  DetectorSettings settings;
  settings.border_margin_px = 40;  // a wide margin, so the fully visible tag falls inside it
  TagDetector detector(settings);
  s.Place(0.8, 0, 0, 0.37, 0.0);  // the black square's right edge about 23 px from the border
  const DetectionResult res = detector.Detect(r.RenderRgb(s.data.get(), 0));
  EXPECT_TRUE(res.detections.empty());
  EXPECT_EQ(res.dropped_border, 1);
}

// Any rotation derived from a detection has det = +1 and matches the truth.
TEST(TagPose, RotationIsProperAndMatchesTruth) {
  TagScene s;
  Renderer r(s.model.get(), RenderMode::kFast);
  DetectorSettings settings;
  settings.max_view_angle_deg = 75;
  TagDetector detector(settings);
  std::mt19937_64 rng(3);
  int poses = 0;
  for (int i = 0; i < 24; ++i) {
    const double distance = 0.35 + 1.0 * Uniform01(rng);
    const double view = 70.0 * Uniform01(rng);
    const double rot = 360.0 * Uniform01(rng);
    s.Place(distance, view, rot, 0.1 * (Uniform01(rng) - 0.5), 0.1 * (Uniform01(rng) - 0.5));
    const DetectionResult res = detector.Detect(r.RenderRgb(s.data.get(), 0));
    if (res.detections.empty()) continue;
    const auto pose = EstimateTagPose(res.detections[0], s.cam, s.tags[0].size_m);
    ASSERT_TRUE(pose.has_value());
    ++poses;
    EXPECT_NEAR(pose->T_cam_tag.linear().determinant(), 1.0, 1e-9);
    // Truth: the rigid map of libapriltag's object corners onto the true corners.
    const auto object = TagObjectCorners(s.tags[0].size_m);
    const auto truth = s.CornersCam();
    Eigen::Matrix<double, 3, 4> src, dst;
    for (int k = 0; k < 4; ++k) {
      src.col(k) = object[k];
      dst.col(k) = truth[k];
    }
    const Eigen::Matrix4d T = Eigen::umeyama(src, dst, false);
    const Eigen::AngleAxisd dR(T.block<3, 3>(0, 0).transpose() * pose->T_cam_tag.linear());
    EXPECT_LT(std::abs(dR.angle()) * 180 / M_PI, 3.0) << "view " << view;
    EXPECT_LT((pose->T_cam_tag.translation() - T.block<3, 1>(0, 3)).norm(), 0.01 * distance);
  }
  EXPECT_GE(poses, 20);
  // A reflection (what libapriltag can return, apriltag#181) is projected back onto SO(3).
  const Eigen::Matrix3d reflection = Eigen::Vector3d(1, 1, -1).asDiagonal();
  EXPECT_NEAR(ProjectToRotation(reflection).determinant(), 1.0, 1e-12);
}

TEST(Overlay, ProjectedCovarianceMatchesFiniteDifferencesAndDrawingIsDeterministic) {
  PinholeCamera cam{500, 520, 320, 240, 640, 480};
  const Eigen::Vector3d p(0.1, -0.05, 1.2);
  Eigen::Matrix3d S;
  S << 4e-4, 1e-4, 0, 1e-4, 2e-4, 5e-5, 0, 5e-5, 9e-4;
  Eigen::Matrix<double, 2, 3> J;
  for (int i = 0; i < 3; ++i) {
    Eigen::Vector2d a, b;
    const Eigen::Vector3d h = 1e-6 * Eigen::Vector3d::Unit(i);
    cam.Project(p + h, &a);
    cam.Project(p - h, &b);
    J.col(i) = (a - b) / 2e-6;
  }
  EXPECT_TRUE(ProjectCovariance(cam, p, S).isApprox(J * S * J.transpose(), 1e-6));
  EXPECT_NEAR(EllipseScale(0.95), 2.447746830680816, 1e-12);

  const auto draw = [&] {
    Image img{640, 480, 3, std::vector<std::uint8_t>(640 * 480 * 3, 40)};
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation() = p;
    T.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
    EXPECT_TRUE(DrawFrameAxes(&img, cam, T, 0.1));
    EXPECT_TRUE(DrawPositionCovariance(&img, cam, p, S, 0.95, kYellow));
    DrawPolyline(&img, {{100, 100}, {200, 110}, {190, 220}}, true, kCyan);
    DrawMarker(&img, {300.5, 200.5}, kMagenta);
    DrawText(&img, "truth", {10, 20}, kWhite);
    return img;
  };
  const Image a = draw();
  const Image b = draw();
  EXPECT_EQ(a.data, b.data);
  EXPECT_FALSE(IsConstant(a));
  // A frame behind the camera draws nothing (and touches no image).
  EXPECT_FALSE(DrawFrameAxes(nullptr, cam, Eigen::Isometry3d(Eigen::Translation3d(0, 0, -1)), 0.1));
}

// ---- tag_detection_sweep bad input: one line on stderr, exit 2, no output folder ----

std::string SweepYaml(const std::string& model, const std::string& extra = "") {
  return "scenario: sweep_copy\nkind: tag_detection_sweep\nseed: 1\nmodel: " + model +
         "\ncamera: front\nboard_body: board\nrender: {mode: fast}\n"
         "sweep:\n  distances_m: [0.5, 4.0]\n  view_angles_deg: [0, 80]\n"
         "  rotations_deg: [0]\n" +
         extra;
}

std::string BoardXml() { return testing::ReadFile(testing::SourceDir() + "/models/tag_board.xml"); }

void ExpectSweepBadInput(const std::string& yaml, const std::string& xml,
                         const std::string& must_contain) {
  TempDir tmp;
  const fs::path model = tmp.path() / "m.xml";
  testing::WriteFile(model, xml);
  const fs::path path = tmp.path() / "s.yaml";
  testing::WriteFile(path, yaml.empty() ? SweepYaml(model.string()) : yaml);
  const fs::path out = tmp.path() / "out";
  const CommandResult r =
      RunCommand(testing::BinDir() + "/flexbench run " + path.string() + " --out " + out.string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(testing::CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find(must_contain), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

TEST(SweepBadInput, ModelWithoutCamera) {
  std::string xml = BoardXml();
  const size_t a = xml.find("<camera name=\"front\"");
  xml.erase(a, xml.find("/>", a) + 2 - a);
  ExpectSweepBadInput("", xml, "the model has no camera");
}

TEST(SweepBadInput, TagIdOutsideTheFamily) {
  std::string xml = BoardXml();
  for (size_t at; (at = xml.find("apriltag_tag36h11_0")) != std::string::npos;) {
    xml.replace(at, 19, "apriltag_tag36h11_900");
  }
  ExpectSweepBadInput("", xml, "tag id 900 is outside family tag36h11");
}

TEST(SweepBadInput, BoardThatIsNotMocap) {
  std::string xml = BoardXml();
  xml.replace(xml.find("mocap=\"true\""), 12, "");
  ExpectSweepBadInput("", xml, "must be a mocap body");
}

TEST(SweepBadInput, UnwritableOutputFolder) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  testing::WriteFile(path, SweepYaml(testing::SourceDir() + "/models/tag_board.xml"));
  const fs::path blocker = tmp.path() / "file";
  testing::WriteFile(blocker, "not a folder");
  const CommandResult r = RunCommand(testing::BinDir() + "/flexbench run " + path.string() +
                                     " --out " + (blocker / "out").string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(testing::CountLines(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("cannot create output folder"), std::string::npos) << r.err;
}

// A small sweep: same seed, same bytes (CSV, plot, frames); the CSV has one row per frame.
TEST(Sweep, SameSeedSameBytes) {
  TempDir tmp;
  const fs::path path = tmp.path() / "s.yaml";
  testing::WriteFile(path, SweepYaml(testing::SourceDir() + "/models/tag_board.xml",
                                     "degradation: {noise_std: 3.0}\nsaved_frames: 2\n"));
  for (const char* name : {"a", "b"}) {
    const CommandResult r = RunCommand(testing::BinDir() + "/flexbench run " + path.string() +
                                       " --out " + (tmp.path() / name).string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  for (const char* file :
       {"sweep.csv", "sweep.png", "frames/sweep_0000.png", "frames/sweep_0002.png"}) {
    const std::string a = testing::ReadFile(tmp.path() / "a" / file);
    EXPECT_FALSE(a.empty()) << file;
    EXPECT_EQ(a, testing::ReadFile(tmp.path() / "b" / file)) << file;
  }
  EXPECT_EQ(testing::CountLines(testing::ReadFile(tmp.path() / "a" / "sweep.csv")), 1 + 4);
  const auto summary = nlohmann::json::parse(testing::ReadFile(tmp.path() / "a" / "summary.json"));
  EXPECT_EQ(summary["metrics"]["frames"], 4);
  EXPECT_EQ(summary["metrics"]["wrong_detections"], 0);
}

}  // namespace
}  // namespace flexbench::render
