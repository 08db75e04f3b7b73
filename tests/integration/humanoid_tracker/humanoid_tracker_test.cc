// Tracker rows simulated from the truth (runner/common/simulated_tracker.h) and
// the closed_loop_humanoid_tracker scenario's bad input.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "estimators/error.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "scenarios/identify/effect_model.h"
#include "scenarios/runner/common/simulated_tracker.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "tests/common/test_util.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

TrackerTruth HumanoidTracker() {
  const ConfigNode n = ConfigNode::LoadString(
      "tracker:\n  frame: tracker\n  T_base_tracker: [2.5, 0, 1.6, 0, 0, 0, 1]\n"
      "  pose_std_m: 0.05\n  pose_std_deg: 5\n  noise_std_m: 1.0e-12\n"
      "  markers: [right_marker, left_marker]\n"
      "  postures_deg: {default: [-30, 30], shoulder_pitch: [-110, 0], l_elbow: [-100, 0]}\n",
      "t.yaml");
  return ParseTrackerTruth(n.Child("tracker"));
}

// The humanoid's truth (with `effects`), its declared chain, and the tracker rows' set-up with
// both hands' markers.
struct HumanoidRig {
  explicit HumanoidRig(const sim::EffectList& effects = {}) {
    const std::string models = testing::SourceDir() + "/models/";
    truth = sim::Simulation::Load(models + "humanoid_upper.xml", effects);
    declared = sim::LoadDeclaredModel(models + "humanoid_upper.declared.yaml");
    chain = sim::BuildDeclaredChain(truth->nominal_model(), declared);
    setup.sim = truth.get();
    setup.chain = &chain;
    setup.base_body = declared.base;
    setup.marker_points = {1, 2};
  }
  std::unique_ptr<sim::Simulation> truth;
  sim::DeclaredModel declared;
  sim::DeclaredChain chain;
  TrackerRowsSetup setup;
};

// Without effects the truth is the declared chain: each row's marker, mapped back from the
// tracker frame with the true pose, is the declared forward kinematics of its readings (an
// oracle that shares neither MuJoCo's statics nor the row generator's frame bookkeeping).
TEST(SimulatedTracker, RigidTruthRowsAreTheDeclaredMarkersInTheTrackerFrame) {
  HumanoidRig rig;
  const sim::DeclaredChain& chain = rig.chain;
  const TrackerTruth t = HumanoidTracker();
  TrackerRowsSetup& s = rig.setup;
  s.T_base_tracker = DrawTrackerPose(t, 7);
  identify::DataSet d;
  SimulateTrackerRows(t, s, 12, 7, "test", "cal", &d);
  ASSERT_EQ(d.rows.size(), 24u);
  const kinematics::FrameId frames[2] = {chain.ObservedFrame("right_marker"),
                                         chain.ObservedFrame("left_marker")};
  kinematics::PpoeData pd(chain.model);
  for (const identify::Observation& o : d.rows) {
    kinematics::ForwardKinematics(chain.model, pd, o.q);
    const Vec3 p_fk = pd.T_base_frame[frames[o.point - 1]].translation();
    EXPECT_LT((s.T_base_tracker * o.p_frame - p_fk).norm(), 1e-9) << o.where;
    EXPECT_EQ(o.frame, 0);
  }
  // Same seed, same rows; the tracker's pose is drawn about its nominal one.
  identify::DataSet again;
  SimulateTrackerRows(t, s, 12, 7, "test", "cal", &again);
  EXPECT_EQ(again.rows[5].p_frame, d.rows[5].p_frame);
  EXPECT_EQ(again.rows[5].q, d.rows[5].q);
  EXPECT_LT((s.T_base_tracker.translation() - t.T_nominal.translation()).norm(), 0.5);
}

// The torso-enabled declared model: its coupled torso_pitch_3 is neither commanded nor read, the
// truth's linkage moves it and each row takes it from its drivers' readings; the markers sit
// where marker_offsets_mm puts them, in their sites' frames; the truth's own error of a row is
// the tracker's noise alone. The oracle is the declared chain's forward kinematics.
TEST(SimulatedTracker, CoupledTorsoAndMarkersOffTheirSites) {
  const std::string models = testing::SourceDir() + "/models/";
  auto truth = sim::Simulation::Load(models + "humanoid_upper.xml");
  const sim::DeclaredModel declared =
      sim::LoadDeclaredModel(models + "humanoid_upper_torso.declared.yaml");
  const sim::DeclaredChain chain =
      sim::BuildDeclaredChain(truth->nominal_model(), declared, /*with_couplings=*/true);
  const ConfigNode n = ConfigNode::LoadString(
      "tracker:\n  frame: tracker\n  T_base_tracker: [2.5, 0, 1.6, 0, 0, 0, 1]\n"
      "  pose_std_m: 0.05\n  pose_std_deg: 5\n  noise_std_m: 2.0e-4\n"
      "  markers: [right_marker, left_marker]\n"
      "  marker_offsets_mm: {left_marker: [-0.9, -3.5, -0.4], right_marker: [0.7, -4.2, 1.9]}\n"
      "  postures_deg: {default: [-30, 30], torso_pitch_1: [-15, 30]}\n",
      "t.yaml");
  const TrackerTruth t = ParseTrackerTruth(n.Child("tracker"));
  TrackerRowsSetup s;
  s.sim = truth.get();
  s.chain = &chain;
  s.base_body = declared.base;
  s.marker_points = {0, 1};
  s.T_base_tracker = DrawTrackerPose(t, 5);
  identify::DataSet d;
  std::vector<double> truth_errors;
  SimulateTrackerRows(t, s, 40, 5, "test", "cal", &d, &truth_errors);
  ASSERT_EQ(truth_errors.size(), d.rows.size());
  const int k1 = chain.QIndex("torso_pitch_1"), k2 = chain.QIndex("torso_pitch_2");
  const int k3 =
      static_cast<int>(std::find(chain.q_joints.begin(), chain.q_joints.end(), "torso_pitch_3") -
                       chain.q_joints.begin());
  ASSERT_TRUE(chain.IsCoupled(k3));
  kinematics::PpoeData pd(chain.model);
  double worst = 0.0, mean_truth = 0.0, mean_on_site = 0.0;
  for (size_t r = 0; r < d.rows.size(); ++r) {
    const identify::Observation& o = d.rows[r];
    EXPECT_EQ(o.q[k3], -(o.q[k1] + o.q[k2])) << o.where;
    kinematics::ForwardKinematics(chain.model, pd, o.q);
    const kinematics::FrameId f =
        chain.ObservedFrame(o.point == 0 ? "right_marker" : "left_marker");
    const Vec3 p_model = pd.T_base_frame[f] * t.marker_offsets[o.point];
    const double e = (s.T_base_tracker * o.p_frame - p_model).norm();
    EXPECT_NEAR(e, truth_errors[r], 1e-9) << o.where;  // the truth is the declared chain here
    worst = std::max(worst, e);
    mean_truth += truth_errors[r] / d.rows.size();
    mean_on_site +=
        (s.T_base_tracker * o.p_frame - pd.T_base_frame[f].translation()).norm() / d.rows.size();
  }
  // 3-D Gaussian noise of 0.2 mm per axis: mean distance sqrt(8 / pi) 0.2 mm = 0.32 mm.
  EXPECT_NEAR(mean_truth, std::sqrt(8.0 / M_PI) * 2e-4, 0.5e-4);
  EXPECT_LT(worst, 1.2e-3);
  // Read in mm; taken for sites without their offsets, the rows miss by millimetres.
  EXPECT_NEAR(t.marker_offsets[1].norm(), 3.6359e-3, 1e-7);
  EXPECT_GT(mean_on_site, 3e-3);
}

TEST(SimulatedTracker, ACoupledJointTakesNoPostureRange) {
  const std::string models = testing::SourceDir() + "/models/";
  auto truth = sim::Simulation::Load(models + "humanoid_upper.xml");
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(
      truth->nominal_model(), sim::LoadDeclaredModel(models + "humanoid_upper_torso.declared.yaml"),
      true);
  const ConfigNode n = ConfigNode::LoadString(
      "tracker:\n  frame: tracker\n  T_base_tracker: [2.5, 0, 1.6, 0, 0, 0, 1]\n"
      "  pose_std_m: 0\n  pose_std_deg: 0\n  noise_std_m: 1.0e-4\n  markers: [right_marker]\n"
      "  postures_deg: {default: [-30, 30], torso_pitch_3: [-15, 30]}\n",
      "t.yaml");
  try {
    ResolvePostures(ParseTrackerTruth(n.Child("tracker")), *truth, chain);
    ADD_FAILURE() << "a range for a coupled joint accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("'torso_pitch_3' is coupled"), std::string::npos)
        << e.what();
  }
}

// With the shoulders' gears elastic (1000 N m/rad), the hands sit below where their readings put
// them, by millimetres (not centimetres: the sag stays well under 5 deg).
TEST(SimulatedTracker, ElasticShouldersLowerTheHandsByMillimetres) {
  sim::EffectList effects;
  effects.push_back(
      sim::MakeEffect("joint_compliance",
                      "{stiffness_Nm_per_rad: {shoulder_pitch: 1000, l_shoulder_pitch: 1000}}"));
  HumanoidRig rig(effects);
  const sim::DeclaredChain& chain = rig.chain;
  const TrackerTruth t = HumanoidTracker();
  TrackerRowsSetup& s = rig.setup;
  identify::DataSet d;
  SimulateTrackerRows(t, s, 20, 3, "test", "cal", &d);
  kinematics::PpoeData pd(chain.model);
  double largest = 0.0, mean_z = 0.0;
  for (const identify::Observation& o : d.rows) {
    kinematics::ForwardKinematics(chain.model, pd, o.q);
    const kinematics::FrameId f =
        chain.ObservedFrame(o.point == 1 ? "right_marker" : "left_marker");
    const Vec3 sag = s.T_base_tracker * o.p_frame - pd.T_base_frame[f].translation();
    mean_z += sag.z() / d.rows.size();
    largest = std::max(largest, sag.norm());
  }
  EXPECT_LT(mean_z, -5e-4);  // the weight pulls the hands down (one may rise: a bent elbow)
  EXPECT_GT(largest, 2e-3);
  EXPECT_LT(largest, 2e-2);
  // The largest load: the arm stretched out forward. The gear gives a little over half a degree.
  rig.truth->SetCommand("shoulder_pitch", -M_PI / 2);
  rig.truth->Settle();
  const int j = mj_name2id(rig.truth->model(), mjOBJ_JOINT, "shoulder_pitch");
  const double sag_deg =
      std::abs(rig.truth->JointPosition(j) - rig.truth->MotorPosition(j)) * 180.0 / M_PI;
  std::printf(
      "hand off its readings by up to %.2f mm over 20 postures; %.2f deg of sag with the "
      "arm stretched out\n",
      largest * 1e3, sag_deg);
  EXPECT_GT(sag_deg, 0.3);
  EXPECT_LT(sag_deg, 1.0);
}

// A compliant mount carries every measured point: one hand's shoulder is no mount of the other
// hand (with both measured, the humanoid's fixed torso leaves no mount candidate at all), while
// one arm alone keeps its first joint's anchor as before.
TEST(SimulatedTracker, TheMountOfSeveralMarkersIsAboveThemAll) {
  HumanoidRig rig;
  const sim::DeclaredChain& chain = rig.chain;
  const mjModel* m = rig.truth->nominal_model();
  const identify::EffectModel one(m, chain, chain.end_effector);
  EXPECT_GE(one.FindCandidate("base_compliance@shoulder_pitch"), 0);
  const identify::EffectModel both(
      m, chain, chain.end_effector, "",
      {chain.ObservedFrame("right_marker"), chain.ObservedFrame("left_marker")});
  for (const identify::Candidate& c : both.candidates()) {
    EXPECT_NE(c.type, identify::EffectType::kBaseCompliance) << c.Name();
  }
  EXPECT_GE(both.FindCandidate("joint_compliance@l_shoulder_pitch"), 0);
  EXPECT_TRUE(both.has_masses());
}

// Bad input in the scenario's tracker block: exit 2, one line naming the file or option and key.
TEST(SimulatedTracker, BadTrackerBlockIsOneLineAndExit2) {
  const std::string scenario =
      testing::SourceDir() + "/scenarios/closed_loop_humanoid_tracker.yaml";
  const fs::path out = fs::temp_directory_path() / ("flexbench_ht_" + std::to_string(::getpid()));
  const struct {
    const char* set;
    const char* expect;
  } cases[] = {
      {"truth.tracker.frame=laser", "truth.tracker.frame': 'laser' is not declared"},
      {"truth.tracker.noise_std_m=0", "noise_std_m"},
      {"truth.tracker.markers=[index_tip, l_foot]", "'l_foot' is neither the end effector"},
      {"truth.tracker.postures_deg.l_elbow=[10, -10]", "postures_deg.l_elbow"},
      {"truth.tracker.postures_deg.l_knee=[0, 10]", "'l_knee' is not an actuated joint"},
      {"truth.tracker.marker_offsets_mm={l_foot: [1, 2, 3]}", "'l_foot' is not one of"},
      {"truth.tracker.marker_offsets_mm={left_marker: [1, 2]}", "expected [x, y, z] in mm"},
      {"calibration.simulate.postures=2", "postures"},
      {"calibration.simulate.placements=3", "placements"},
  };
  for (const auto& c : cases) {
    const testing::CommandResult r =
        testing::RunCommand(testing::BinDir() + "/flexbench run " + scenario + " --out " +
                            out.string() + " --quiet --set '" + c.set + "'");
    EXPECT_EQ(r.exit_code, 2) << c.set << ": " << r.err;
    EXPECT_EQ(testing::CountLines(r.err), 1) << c.set << ": " << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << c.set << ": " << r.err;
  }
  fs::remove_all(out);
}

}  // namespace
}  // namespace flexbench::scenarios
