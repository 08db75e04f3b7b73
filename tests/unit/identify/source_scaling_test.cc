// Which directions of the declared PPOE sources rows constrain (identify/source_scaling.h), on
// the rover's declared model with the rows' points from MuJoCo's own kinematics: a source no row
// sees keeps its declared size to the bit, a seen one is scaled.
#include "scenarios/identify/source_scaling.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

struct Rover {
  sim::DeclaredModel d;
  sim::MjModelPtr m;
  sim::DeclaredChain chain;
  std::vector<SourceDirection> dirs;
};

Rover LoadRover() {
  Rover r;
  r.d = sim::LoadDeclaredModel(testing::SourceDir() + "/models/rover_arm.declared.yaml");
  r.m = sim::LoadModel(r.d.model_path);
  r.chain = sim::BuildDeclaredChain(r.m.get(), r.d);
  r.dirs = SourceDirections(r.m.get(), r.d, r.chain.model);
  return r;
}

// Rows at random arm postures measuring the end effector where MuJoCo puts it, in the base
// frame (frame -1) or in one measurement frame whose pose the fit re-estimates (frame 0).
DataSet EndEffectorRows(const Rover& r, int frame, std::vector<Vec3>* p) {
  DataSet d;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> angle(-0.6, 0.6);
  sim::MjDataPtr data = sim::MakeData(r.m.get());
  const int ee = mj_name2id(r.m.get(), mjOBJ_SITE, "ee");
  for (int i = 0; i < 40; ++i) {
    Eigen::VectorXd q = Eigen::VectorXd::Zero(r.chain.model.nq());
    for (int k = 0; k < 6; ++k) q[k] = angle(rng);  // j1..j6; the mast stays
    q[2] -= 1.6;                                    // the elbow bent, as the rover works
    std::copy(r.m->qpos0, r.m->qpos0 + r.m->nq, data->qpos);
    r.chain.WriteQpos(q, data->qpos);
    mj_kinematics(r.m.get(), data.get());
    Observation o;
    o.q = q;
    o.type = ObservationType::kPoint;
    o.frame = frame;
    o.p_base = Eigen::Map<const Vec3>(data->site_xpos + 3 * ee);
    d.rows.push_back(o);
    p->push_back(o.p_base);
  }
  return d;
}

std::vector<double> Snr(const Rover& r, int frame, double noise_std_m) {
  std::vector<Vec3> p;
  const DataSet d = EndEffectorRows(r, frame, &p);
  const std::vector<Mat3> noise(d.rows.size(), noise_std_m * noise_std_m * Mat3::Identity());
  return SourceSignalToNoise(r.chain.model, d, {r.chain.end_effector}, p, noise, r.dirs);
}

int Find(const Rover& r, const std::string& name) {
  for (size_t i = 0; i < r.dirs.size(); ++i) {
    if (r.dirs[i].name == name) return static_cast<int>(i);
  }
  ADD_FAILURE() << name << " not among the source directions";
  return 0;
}

std::vector<bool> Constrained(const std::vector<double>& snr) {
  std::vector<bool> c;
  for (double s : snr) c.push_back(s >= kConstrainedSignalToNoise);
  return c;
}

TEST(SourceScaling, DirectionsAreTheDeclaredAxes) {
  const Rover r = LoadRover();
  // base_plate: std_rot_deg [5, 5, 1]; j1..j6, mast_pan, mast_tilt: about_axis_deg 0.5.
  ASSERT_EQ(r.dirs.size(), 11u);
  const SourceDirection& rot_y = r.dirs[Find(r, "base_plate:rot_y")];
  EXPECT_EQ(rot_y.v, Vec6::Unit(4));
  EXPECT_EQ(rot_y.variance, r.d.sources[0].cov(4, 4));
  const SourceDirection& j3 = r.dirs[Find(r, "j3:about_axis")];
  EXPECT_TRUE(j3.about_axis);
  EXPECT_NEAR(std::sqrt(j3.variance), 0.5 * M_PI / 180.0, 1e-15);
}

TEST(SourceScaling, SourcesNoRowSeesKeepTheirDeclaredSize) {
  const Rover r = LoadRover();
  const std::vector<double> snr = Snr(r, -1, 1e-4);
  // The mast's joints move the camera, not the hand the rows measure; the hand's point lies on
  // the wrist's roll axis.
  EXPECT_EQ(snr[Find(r, "mast_pan:about_axis")], 0.0);
  EXPECT_EQ(snr[Find(r, "mast_tilt:about_axis")], 0.0);
  EXPECT_LT(snr[Find(r, "j6:about_axis")], 1e-6);
  // In the base frame a 5 deg plate tilt and 0.5 deg at the elbow move the hand by millimetres.
  EXPECT_GT(snr[Find(r, "base_plate:rot_x")], 100.0);
  EXPECT_GT(snr[Find(r, "j3:about_axis")], 100.0);

  std::vector<sim::DeclaredSource> scaled = r.d.sources;
  ScaleSourceDirections(r.dirs, Constrained(snr), 1e-6, &scaled);
  for (size_t s = 0; s < scaled.size(); ++s) {
    const std::string& at = r.d.sources[s].at;
    if (at == "mast_pan" || at == "mast_tilt" || at == "j6") {
      EXPECT_EQ(scaled[s].about_axis_rad, r.d.sources[s].about_axis_rad) << at;  // to the bit
      EXPECT_EQ(scaled[s].cov, r.d.sources[s].cov) << at;
    } else if (at == "base_plate") {
      EXPECT_EQ(scaled[s].cov, (1e-6 * r.d.sources[s].cov).eval());
    } else {
      EXPECT_EQ(scaled[s].about_axis_rad, std::sqrt(1e-6) * r.d.sources[s].about_axis_rad) << at;
    }
  }
}

TEST(SourceScaling, RigidMotionsAFittedFrameAbsorbsAreNotConstrained) {
  const Rover r = LoadRover();
  // Measured in a tracker frame whose pose is fitted: the plate's tilt and j1's turn move every
  // measured point rigidly, which the frame's pose takes up whatever their size.
  const std::vector<double> snr = Snr(r, 0, 1e-4);
  for (const char* rigid :
       {"base_plate:rot_x", "base_plate:rot_y", "base_plate:rot_z", "j1:about_axis"}) {
    EXPECT_LT(snr[Find(r, rigid)], 1e-6) << rigid;
  }
  EXPECT_GT(snr[Find(r, "j3:about_axis")], 100.0);  // the elbow bends the arm: not rigid

  std::vector<sim::DeclaredSource> scaled = r.d.sources;
  ScaleSourceDirections(r.dirs, Constrained(snr), 1e-6, &scaled);
  for (size_t s = 0; s < scaled.size(); ++s) {
    const std::string& at = r.d.sources[s].at;
    const bool kept =
        at == "base_plate" || at == "j1" || at == "j6" || at == "mast_pan" || at == "mast_tilt";
    if (kept) {
      EXPECT_EQ(scaled[s].cov, r.d.sources[s].cov) << at;
      EXPECT_EQ(scaled[s].about_axis_rad, r.d.sources[s].about_axis_rad) << at;
    } else {
      EXPECT_LT(scaled[s].about_axis_rad, 1e-2 * r.d.sources[s].about_axis_rad) << at;
    }
  }
}

TEST(SourceScaling, NoiseAboveEverySourceConstrainsNothing) {
  const Rover r = LoadRover();
  for (double s : Snr(r, -1, 1.0)) EXPECT_LT(s, kConstrainedSignalToNoise);
}

TEST(SourceScaling, PartlyConstrainedSourceScalesOnlyThoseDirections) {
  const Rover r = LoadRover();
  std::vector<bool> constrained(r.dirs.size(), false);
  constrained[Find(r, "base_plate:rot_z")] = true;
  std::vector<sim::DeclaredSource> scaled = r.d.sources;
  ScaleSourceDirections(r.dirs, constrained, 0.25, &scaled);
  Mat6 expected = r.d.sources[0].cov;
  expected(5, 5) *= 0.25;
  EXPECT_NEAR((scaled[0].cov - expected).cwiseAbs().maxCoeff(), 0.0, 1e-18);
  EXPECT_EQ(scaled[0].cov(3, 3), r.d.sources[0].cov(3, 3));
  EXPECT_EQ(scaled[0].cov(4, 4), r.d.sources[0].cov(4, 4));
  // The fit's chain carries the chosen directions alone.
  const kinematics::PpoeModel only = WithSourceDirections(r.chain.model, r.dirs, constrained);
  const kinematics::FrameId plate = r.dirs[Find(r, "base_plate:rot_z")].frame;
  Mat6 rot_z = Mat6::Zero();
  rot_z(5, 5) = r.d.sources[0].cov(5, 5);
  EXPECT_EQ(only.frame(plate).source_cov, rot_z);
  EXPECT_FALSE(only.frame(r.dirs[Find(r, "j3:about_axis")].frame).has_source);
}

}  // namespace
}  // namespace flexbench::identify
