// The calibrated model holds what was fitted and goes where users need it: a declared file's
// identified effects are the model `identify` starts from (re-scoring an augmented model on its
// own calibration rows reproduces its "after" error); the fitted tracker pose and marker offsets
// travel in the augmented file. Rows come from MuJoCo's kinematics of a perturbed copy of the
// arm (other geometry, a joint offset), measured by a tracker at an unknown pose, never from the
// effect model under test.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "estimators/lie/se3.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench {
namespace {

namespace fs = std::filesystem;

// A 4-joint arm with masses; %s are the truth's perturbations (the fore link's position and
// the marker's place on the hand).
constexpr char kArmTemplate[] = R"(
<mujoco model="arm4">
  <compiler angle="radian" autolimits="true"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <joint name="j1" axis="0 0 1" range="-3 3"/>
      <geom type="cylinder" size="0.05 0.05" mass="2"/>
      <body name="upper" pos="0 0 0.1">
        <joint name="j2" axis="0 1 0" range="-2 2"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="3"/>
        <body name="fore" pos="%s" quat="0.99 0 0.1 0.05">
          <joint name="j3" axis="0 1 0" range="-2 2"/>
          <geom type="capsule" fromto="0 0 0 0.35 0 0" size="0.025" mass="2"/>
          <body name="hand" pos="0.35 0 0">
            <joint name="j4" axis="1 0 0" range="-3 3"/>
            <geom type="box" size="0.03 0.03 0.03" pos="0.03 0 0.01" mass="0.7"/>
            <site name="ee" pos="%s"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>)";

std::string Arm(const char* fore_pos, const char* ee_pos) {
  char xml[4096];
  std::snprintf(xml, sizeof(xml), kArmTemplate, fore_pos, ee_pos);
  return xml;
}

// The truth: the fore link 3 mm further out and 2 mm up, the marker 12 mm off the declared
// site, j2's link 0.6 deg past its reading.
const std::string kNominal = Arm("0.4 0 0", "0.08 0.01 0.02");
const std::string kTruth = Arm("0.403 0 0.002", "0.092 0.004 0.013");
constexpr double kJ2Offset = 0.6 * M_PI / 180.0;

// The tracker's pose in the arm's world (what the fit must find).
lie::SE3 TrackerPose() {
  const Eigen::Quaterniond q =
      Eigen::AngleAxisd(0.4, Vec3(0.2, -0.3, 1.0).normalized()) * Eigen::Quaterniond::Identity();
  return lie::SE3(q.toRotationMatrix(), Vec3(1.2, -0.4, 0.3));
}

// n rows: readings, the truth's marker by MuJoCo in the tracker's frame with Gaussian noise.
std::string TrackerRows(int n, std::mt19937_64& rng, double noise_m) {
  sim::MjModelPtr m = sim::LoadModelFromString(kTruth, "truth.xml");
  sim::MjDataPtr data = sim::MakeData(m.get());
  mjData* d = data.get();
  const int ee = mj_name2id(m.get(), mjOBJ_SITE, "ee");
  const lie::SE3 T_w_tracker = TrackerPose();
  std::uniform_real_distribution<double> u(-1.3, 1.3);
  std::normal_distribution<double> noise(0.0, noise_m);
  std::string csv = "j1,j2,j3,j4,x,y,z,frame\n";
  for (int i = 0; i < n; ++i) {
    double q[4];
    for (int j = 0; j < 4; ++j) {
      q[j] = u(rng);
      d->qpos[j] = q[j] + (j == 1 ? kJ2Offset : 0.0);
    }
    mj_kinematics(m.get(), d);
    const Vec3 p_w(d->site_xpos[3 * ee], d->site_xpos[3 * ee + 1], d->site_xpos[3 * ee + 2]);
    const Vec3 p = T_w_tracker.Inverse() * p_w;
    char row[256];
    std::snprintf(row, sizeof(row), "%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,tracker\n", q[0],
                  q[1], q[2], q[3], p.x() + noise(rng), p.y() + noise(rng), p.z() + noise(rng));
    csv += row;
  }
  return csv;
}

class CalibratedModel : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("flexbench_calibrated_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    testing::WriteFile(dir_ / "arm4.xml", kNominal);
    testing::WriteFile(dir_ / "arm4.declared.yaml",
                       "model: arm4.xml\nactuated_joints: [j1, j2, j3, j4]\nend_effector: ee\n");
    std::mt19937_64 rng(34);
    testing::WriteFile(dir_ / "cal.csv", TrackerRows(80, rng, 5e-5));
    testing::WriteFile(dir_ / "val.csv", TrackerRows(50, rng, 5e-5));
  }
  void TearDown() override {
    if (!getenv("KEEP")) fs::remove_all(dir_);
  }

  testing::CommandResult Identify(const fs::path& declared, const std::string& out,
                                  const std::string& extra) const {
    return testing::RunCommand(
        testing::Flexbench() + " identify --declared " + declared.string() + " --calibration " +
        (dir_ / "cal.csv").string() + " --validation " + (dir_ / "val.csv").string() +
        " --frame tracker --point-std 5e-5 --quiet --out " + (dir_ / out).string() + extra);
  }
  nlohmann::json Metrics(const std::string& out) const {
    return nlohmann::json::parse(testing::ReadFile(dir_ / out / "summary.json"))["metrics"];
  }

  fs::path dir_;
};

// Re-scoring the augmented model with no effect allowed gives the first run's "after" errors:
// the identified effects are applied (not the nominal model's error reported again), the marker
// moved by its fitted offset, the tracker's fit started from its stored pose.
TEST_F(CalibratedModel, RescoringTheAugmentedModelReproducesItsAfterError) {
  const testing::CommandResult first =
      Identify(dir_ / "arm4.declared.yaml", "first", " --set 'unknown_marker_offsets=[ee]'");
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const nlohmann::json a = Metrics("first");
  ASSERT_FALSE(a["effects_found"].empty());
  // The effects matter: well above the noise before, at it after.
  ASSERT_GT(a["cal_err_before_m"].get<double>(), 1e-3);
  ASSERT_LT(a["cal_err_after_m"].get<double>(), 2e-4);
  const fs::path aug = dir_ / "first" / "declared_augmented.yaml";
  ASSERT_TRUE(fs::exists(aug));
  // The file carries what was fitted besides the effects: the tracker's pose and the marker's
  // offset (the truth's 12 mm), each with a covariance that covers its error.
  const sim::DeclaredModel d = sim::LoadDeclaredModel(aug.string());
  ASSERT_EQ(d.frames.size(), 1u);
  EXPECT_EQ(d.frames[0].name, "tracker");
  const Vec6 xi = (TrackerPose().Inverse() * d.frames[0].T_base_frame).Log();
  for (int k = 0; k < 6; ++k) {
    EXPECT_GT(d.frames[0].cov(k, k), 0.0);
    EXPECT_LT(std::abs(xi[k]), 5.0 * std::sqrt(d.frames[0].cov(k, k)) + 1e-6) << k;
  }
  ASSERT_EQ(d.marker_offsets.size(), 1u);
  EXPECT_EQ(d.marker_offsets[0].frame, "ee");
  const Vec3 truth_offset(0.012, -0.006, -0.007);
  EXPECT_LT((d.marker_offsets[0].offset_m - truth_offset).norm(), 1e-3)
      << d.marker_offsets[0].offset_m.transpose();
  EXPECT_GT(d.marker_offsets[0].cov.trace(), 0.0);
  const testing::CommandResult again = Identify(aug, "again", " --max-effects 0");
  ASSERT_EQ(again.exit_code, 0) << again.err;
  const nlohmann::json b = Metrics("again");
  EXPECT_TRUE(b["effects_found"].empty());
  for (const char* set : {"cal", "val"}) {
    const std::string after = std::string(set) + "_err_after_m";
    const std::string before = std::string(set) + "_err_before_m";
    EXPECT_NEAR(b[before].get<double>(), a[after].get<double>(), 1e-9) << set;
    EXPECT_NEAR(b[after].get<double>(), a[after].get<double>(), 1e-9) << set;
  }
}

// An augmented file that does not fit its model, or whose fitted frames are malformed: exit 2,
// one line naming the file, the line and the entry.
TEST_F(CalibratedModel, ABadAugmentedFileIsOneLineNamingFileLineAndEntry) {
  const std::string head =
      "model: arm4.xml\nactuated_joints: [j1, j2, j3, j4]\nend_effector: ee\n"
      "observed_frames: [hand]\n";
  const auto run = [&](const std::string& name, const std::string& body) {
    testing::WriteFile(dir_ / name, head + body);
    const testing::CommandResult r = Identify(dir_ / name, "out_" + name, "");
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(testing::CountLines(r.err), 1) << r.err;
    return r.err;
  };
  std::string e = run("joint.yaml",
                      "identified_effects:\n  - {effect: joint_offset@j2, value: [0.01]}\n"
                      "  - {effect: joint_offset@elbow9, value: [0.01]}\n");
  EXPECT_NE(e.find("joint.yaml:7"), std::string::npos) << e;
  EXPECT_NE(e.find("joint_offset@elbow9"), std::string::npos) << e;
  EXPECT_NE(e.find("elbow9"), std::string::npos) << e;
  e = run("frame.yaml", "identified_effects:\n  - {effect: link_offset@wrist, value: [0, 0, 0]}\n");
  EXPECT_NE(e.find("frame.yaml:6"), std::string::npos) << e;
  EXPECT_NE(e.find("link_offset@wrist"), std::string::npos) << e;
  e = run("marker.yaml", "marker_offsets:\n  thumb: {offset_m: [0.01, 0, 0]}\n");
  EXPECT_NE(e.find("marker.yaml:6"), std::string::npos) << e;
  EXPECT_NE(e.find("thumb"), std::string::npos) << e;
  e = run("pd.yaml",
          "marker_offsets:\n  ee: {offset_m: [0.01, 0, 0], covariance: [1, 0, 0, 0, -1, 0, 0, 0, "
          "1]}\n");
  EXPECT_NE(e.find("pd.yaml:6"), std::string::npos) << e;
  EXPECT_NE(e.find("positive definite"), std::string::npos) << e;
  e = run("nan.yaml", "marker_offsets:\n  hand: {offset_m: [.nan, 0, 0]}\n");
  EXPECT_NE(e.find("nan.yaml:6"), std::string::npos) << e;
  EXPECT_NE(e.find("finite"), std::string::npos) << e;
  e = run("quat.yaml", "frames:\n  tracker: {T_base_frame: [0, 0, 0, 1, 1, 0, 0]}\n");
  EXPECT_NE(e.find("quat.yaml:6"), std::string::npos) << e;
  EXPECT_NE(e.find("unit length"), std::string::npos) << e;
  e = run("base.yaml", "frames:\n  base: {T_base_frame: [0, 0, 0, 1, 0, 0, 0]}\n");
  EXPECT_NE(e.find("base.yaml:6"), std::string::npos) << e;
  // A frame pose and a moved body are read, and used (the run gets past the model).
  testing::WriteFile(
      dir_ / "good.yaml",
      head +
          "frames:\n  tracker: {T_base_frame: [1.2, -0.4, 0.3, 1, 0, 0, 0], "
          "covariance: [1e-6, 0, 0, 0, 0, 0, 0, 1e-6, 0, 0, 0, 0, 0, 0, 1e-6, 0, 0, 0, "
          "0, 0, 0, 1e-6, 0, 0, 0, 0, 0, 0, 1e-6, 0, 0, 0, 0, 0, 0, 1e-6]}\n"
          "marker_offsets:\n  hand: {offset_m: [0.01, 0, 0]}\n");
  const testing::CommandResult ok = Identify(dir_ / "good.yaml", "good", " --max-effects 0");
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
}

}  // namespace
}  // namespace flexbench
