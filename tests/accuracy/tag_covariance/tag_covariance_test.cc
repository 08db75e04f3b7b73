// Validation of the corner and centre covariances of render/tag_covariance.h against the
// empirical error distribution of libapriltag on rendered frames.
//
// The model's constants were calibrated once (tag 0.8 m away, frontal, fast render; the floor
// on noise-free frames, kappa at noise 8 gray levels and gain 0.5). Every condition here differs
// from that one in distance, view angle, noise level or exposure. Per condition: N frames, each
// with a slightly different tag pose (random in-plane rotation, view-angle and position jitter)
// and a fresh noise realisation (seeded). For one corner per frame (cycling 0..3, so the samples
// are independent) and for the centre, d^2 = e^T S^-1 e with e = detected - projected truth
// must follow chi-square(2):
//  - the mean of d^2 lies within the two-sided 99% bounds of chi2(2N) / N, and
//  - Pearson's goodness-of-fit statistic over 10 equiprobable bins is below chi2_0.99(9).
#include "render/tag_covariance.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>

#include "estimators/conventions.h"
#include "render/degrade.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "sim/camera.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::render {
namespace {

constexpr int kFrames = 300;
// Deciles of chi-square(2): -2 ln(1 - p), p = 0.1 ... 0.9.
double Chi2Decile(int i) { return -2.0 * std::log(1.0 - 0.1 * i); }
constexpr int kConditions = 5;
constexpr int kChecks = kConditions * 2 * 2;  // conditions x {corner, centre} x {mean, Pearson}
// Standard-normal quantiles: two-sided at 0.01 / kChecks = 5e-4 (2.5e-4 a side), one-sided at
// 5e-4; and the plain 0.01 ones for the report.
constexpr double kZTwoSided = 3.4808;
constexpr double kZOneSided = 3.2905;
constexpr double kZTwoSided01 = 2.5758;
constexpr double kZOneSided01 = 2.3263;

// Wilson-Hilferty approximation of the chi-square quantile with k dof at standard-normal z.
double Chi2Quantile(double k, double z) {
  const double a = 2.0 / (9.0 * k);
  return k * std::pow(1.0 - a + z * std::sqrt(a), 3);
}

struct Condition {
  const char* name;
  double distance_m;
  double view_deg;
  double noise_std;  // gray levels, on the gray image the detector sees
  double gain;
  std::uint64_t seed;
};

struct Stats {
  int n = 0;
  double mean = 0.0;
  double pearson = 0.0;
};

Stats Evaluate(const std::vector<double>& d2) {
  Stats s;
  s.n = static_cast<int>(d2.size());
  int bins[10] = {0};
  for (double v : d2) {
    s.mean += v / s.n;
    int b = 0;
    while (b < 9 && v > Chi2Decile(b + 1)) ++b;
    ++bins[b];
  }
  const double expected = s.n / 10.0;
  for (int b : bins) s.pearson += (b - expected) * (b - expected) / expected;
  return s;
}

class TagCovariance : public ::testing::TestWithParam<Condition> {};

TEST_P(TagCovariance, MahalanobisDistancesFollowChiSquare2) {
  const Condition c = GetParam();
  sim::MjModelPtr m = sim::LoadModel(testing::SourceDir() + "/models/tag_board.xml");
  const std::vector<TagInModel> tags = ApplyTagTextures(m.get());
  sim::MjDataPtr d = sim::MakeData(m.get());
  Renderer renderer(m.get(), RenderMode::kFast);
  DetectorSettings settings;
  settings.pixel_noise_std = c.noise_std;
  TagDetector detector(settings);
  const PinholeCamera cam = sim::CameraIntrinsics(m.get(), 0);
  std::mt19937_64 rng(c.seed);
  Degradation deg;
  deg.noise_std = c.noise_std;
  deg.gain = c.gain;

  std::vector<double> corner_d2, center_d2;
  int missed = 0;
  Image gray;
  for (int i = 0; i < kFrames; ++i) {
    const double rot = 2 * M_PI * Uniform01(rng);
    const double view = (c.view_deg + 4 * (Uniform01(rng) - 0.5)) * M_PI / 180;
    const double tilt_axis = 2 * M_PI * Uniform01(rng);
    const Quat q(Eigen::AngleAxisd(tilt_axis, Eigen::Vector3d::UnitZ()) *
                 Eigen::AngleAxisd(view, Eigen::Vector3d::UnitY()) *
                 Eigen::AngleAxisd(rot - tilt_axis, Eigen::Vector3d::UnitZ()));
    d->mocap_pos[0] = 0.05 * (Uniform01(rng) - 0.5);
    d->mocap_pos[1] = 0.05 * (Uniform01(rng) - 0.5);
    d->mocap_pos[2] = -c.distance_m * (1 + 0.1 * (Uniform01(rng) - 0.5));
    QuatToWxyz(q, d->mocap_quat);
    mj_forward(m.get(), d.get());
    renderer.RenderGrayInto(d.get(), 0, &gray);
    ApplyDegradation(deg, rng, &gray);
    const DetectionResult res = detector.Detect(gray);
    if (res.detections.size() != 1) {
      ++missed;
      continue;
    }
    const TagDetection& det = res.detections[0];
    const Eigen::Isometry3d T_cam_w = sim::WorldFromOptical(d.get(), 0).inverse();
    const auto w = TagCornersWorld(d.get(), tags[0]);
    const int k = i % 4;
    Eigen::Vector2d corner, center;
    ASSERT_TRUE(cam.Project(T_cam_w * w[k], &corner));
    ASSERT_TRUE(cam.Project(T_cam_w * (0.25 * (w[0] + w[1] + w[2] + w[3])), &center));
    corner_d2.push_back(Mahalanobis2(det.corners[k] - corner, det.CornerCov(k)));
    center_d2.push_back(Mahalanobis2(det.center - center, det.center_cov));
  }
  EXPECT_LE(missed, kFrames / 100) << "detection should not fail in these conditions";
  for (const auto& [what, d2] :
       {std::make_pair("corner", &corner_d2), std::make_pair("centre", &center_d2)}) {
    const Stats s = Evaluate(*d2);
    const double lo = Chi2Quantile(2.0 * s.n, -kZTwoSided) / s.n;
    const double hi = Chi2Quantile(2.0 * s.n, kZTwoSided) / s.n;
    const double critical = Chi2Quantile(9.0, kZOneSided);
    const double lo01 = Chi2Quantile(2.0 * s.n, -kZTwoSided01) / s.n;
    const double hi01 = Chi2Quantile(2.0 * s.n, kZTwoSided01) / s.n;
    const double critical01 = Chi2Quantile(9.0, kZOneSided01);
    std::printf(
        "[ %-20s ] %s: n=%d mean d2=%.3f (bounds %.3f..%.3f; at 0.01 each %.3f..%.3f)"
        ", Pearson=%.1f (critical %.2f; at 0.01 each %.2f)\n",
        c.name, what, s.n, s.mean, lo, hi, lo01, hi01, s.pearson, critical, critical01);
    RecordProperty(std::string(what) + "_mean_d2", std::to_string(s.mean));
    RecordProperty(std::string(what) + "_pearson", std::to_string(s.pearson));
    EXPECT_GE(s.mean, lo) << what << ": covariance too large (conservative)";
    EXPECT_LE(s.mean, hi) << what << ": covariance too small (overconfident)";
    EXPECT_LT(s.pearson, critical) << what << ": d2 not chi-square(2)";
  }
}

static_assert(kConditions == 5, "kChecks counts the conditions below");
INSTANTIATE_TEST_SUITE_P(NotTheCalibrationCondition, TagCovariance,
                         ::testing::Values(Condition{"near_0.45m_noise10", 0.45, 0.0, 10.0, 0.5,
                                                     11},
                                           Condition{"far_1.5m_noise8", 1.5, 0.0, 8.0, 0.5, 12},
                                           Condition{"oblique_45deg", 0.8, 45.0, 8.0, 0.5, 13},
                                           Condition{"bright_noise16", 0.8, 0.0, 16.0, 1.0, 14},
                                           Condition{"dim_1.1m_30deg", 1.1, 30.0, 6.0, 0.4, 15}),
                         [](const ::testing::TestParamInfo<Condition>& info) {
                           std::string name = info.param.name;
                           for (char& ch : name) {
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           }
                           return name;
                         });

}  // namespace
}  // namespace flexbench::render
