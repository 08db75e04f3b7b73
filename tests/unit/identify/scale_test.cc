// Identification at scale keeps its results: independent steps run side by side (selection's
// screens, refits and removals, the folds, the alternatives) and the selection's memo give the
// same bits as one thread; loads without their cached nominal poses predict the same bits; a
// row's loads hold one link-middle entry per link that can bend, not one per frame.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <random>
#include <stdexcept>

#include "scenarios/identify/effect_model.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/parallel.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/identify_test_util.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

using Rig = testing::ModelRig;
const auto MakeRig = testing::LoadModelRig;

// Point rows of rover_arm in 4 sets with a gear compliance at j2 and an encoder offset at j3
// (predicted by the identification model: this test compares identification with itself).
DataSet RoverRows(const EffectModel& em, int rows) {
  const std::vector<int> truth = {em.FindCandidate("joint_compliance@j2"),
                                  em.FindCandidate("joint_offset@j3")};
  const double theta[2] = {-1.2e-3, 0.005};
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  std::normal_distribution<double> n(0.0, 1e-4);
  EffectModel::Workspace ws = em.MakeWorkspace();
  DataSet d;
  d.sets = {"s0", "s1", "s2", "s3"};
  for (int r = 0; r < rows; ++r) {
    Observation o;
    o.q = Eigen::VectorXd(em.chain().nq());
    for (int k = 0; k < o.q.size(); ++k) o.q[k] = u(rng);
    o.p_base = em.Predict(o.q, em.Loads(o.q), truth, theta, ws) + Vec3(n(rng), n(rng), n(rng));
    o.set = r % 4;
    d.rows.push_back(o);
  }
  return d;
}

bool SameBits(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

TEST(IdentifyScale, LoadsComputedInAPassGiveTheBitsOfKeptOnes) {
  // Beyond kLoadsCacheBytes a pass computes a row's loads on its thread's own MuJoCo data:
  // identification and the augmented model's predictions are the bits of kept loads.
  const std::unique_ptr<Rig> rig = MakeRig("rover_arm");
  const EffectModel& em = *rig->em;
  const DataSet d = RoverRows(em, 160);
  const RowLoads kept = ComputeLoads(em, d);
  ASSERT_EQ(kept.num_kept(), d.rows.size());
  const RowLoads none(em, d, {}, Eigen::VectorXd(), 0.0);
  const RowLoads half(em, d, {}, Eigen::VectorXd(),
                      80.5 * static_cast<double>(LoadsBytes(kept.kept(0))));
  EXPECT_EQ(none.num_kept(), 0u);
  EXPECT_EQ(half.num_kept(), 80u);
  std::vector<int> candidates;
  for (size_t c = 0; c < em.candidates().size() && candidates.size() < 30; ++c) {
    candidates.push_back(static_cast<int>(c));
  }
  IdentifyOptions opt;
  opt.threads = 2;
  const IdentifyResult a = Identify(em, d, kept, candidates, opt);
  ASSERT_FALSE(a.effects.empty());
  for (const RowLoads* loads : {&none, &half}) {
    const IdentifyResult b = Identify(em, d, *loads, candidates, opt);
    EXPECT_EQ(a.after.active, b.after.active);
    EXPECT_TRUE(SameBits(a.after.theta, b.after.theta));
    EXPECT_EQ(a.after.rss, b.after.rss);
    EXPECT_EQ(a.cv_after, b.cv_after);
    EXPECT_EQ(a.steps, b.steps);
  }
  // The loads where the fit's own corrections put the arm (EffectModel::LoadsShift).
  ASSERT_TRUE(em.LoadsShift(a.after.active));
  const RowLoads shifted = ComputeLoads(em, d, a.after.active, a.after.theta);
  const RowLoads shifted_none(em, d, a.after.active, a.after.theta, 0.0);
  const auto p = PredictAll(em, d, shifted, a.after.active, a.after.theta);
  const auto q = PredictAll(em, d, shifted_none, a.after.active, a.after.theta);
  const auto at_readings = PredictAll(em, d, kept, a.after.active, a.after.theta);
  bool moved = false;
  for (size_t r = 0; r < p.size(); ++r) {
    EXPECT_EQ(p[r], q[r]) << "row " << r;
    moved = moved || p[r] != at_readings[r];
  }
  EXPECT_TRUE(moved) << "the shifted loads differ from the loads at the readings";
}

TEST(IdentifyScale, TasksSideBySideGiveTheSameBitsAsOneThread) {
  const std::unique_ptr<Rig> rig = MakeRig("rover_arm");
  const EffectModel& em = *rig->em;
  const DataSet d = RoverRows(em, 160);
  const RowLoads loads = ComputeLoads(em, d);
  std::vector<int> candidates;
  for (size_t c = 0; c < em.candidates().size() && candidates.size() < 30; ++c) {
    candidates.push_back(static_cast<int>(c));
  }
  IdentifyOptions one;
  one.threads = 1;
  IdentifyOptions two = one;
  two.threads = 2;
  const IdentifyResult a = Identify(em, d, loads, candidates, one);
  const IdentifyResult b = Identify(em, d, loads, candidates, two);
  // Not vacuous: both planted effects chosen, each with its alternative.
  ASSERT_EQ(a.after.active.size(), 2u);
  ASSERT_EQ(a.alternatives.size(), 2u);
  EXPECT_EQ(a.after.active, b.after.active);
  EXPECT_TRUE(SameBits(a.after.theta, b.after.theta));
  EXPECT_EQ(std::memcmp(&a.cv_after, &b.cv_after, sizeof(double)), 0);
  EXPECT_EQ(a.steps, b.steps);
  for (size_t k = 0; k < a.alternatives.size(); ++k) {
    EXPECT_EQ(a.alternatives[k].effects, b.alternatives[k].effects);
    EXPECT_EQ(std::memcmp(&a.alternatives[k].cv, &b.alternatives[k].cv, sizeof(double)), 0);
  }
  EXPECT_TRUE(a.theta_cov == b.theta_cov);
}

TEST(IdentifyScale, LoadsWithoutNominalPosesPredictTheSameBits) {
  const std::unique_ptr<Rig> rig = MakeRig("rover_arm");
  const EffectModel& em = *rig->em;
  const DataSet d = RoverRows(em, 20);
  const std::vector<int> active = {em.FindCandidate("joint_compliance@j2"),
                                   em.FindCandidate("link_offset@j5")};
  ASSERT_GE(active[0], 0);
  ASSERT_GE(active[1], 0);
  const double theta[4] = {-1e-3, 1e-3, -2e-3, 5e-4};
  EffectModel::Workspace ws = em.MakeWorkspace();
  int cached = 0;
  for (const Observation& o : d.rows) {
    const ConfigLoads with = em.Loads(o.q);
    ConfigLoads without = with;
    without.T_nominal.clear();
    without.q_nominal.resize(0);
    cached += !with.T_nominal.empty();
    for (const std::vector<int>& act : {std::vector<int>{}, active}) {
      const lie::SE3 a = em.PredictPose(o.q, with, act, theta, ws);
      const lie::SE3 b = em.PredictPose(o.q, without, act, theta, ws);
      EXPECT_TRUE(a.rotation() == b.rotation() && a.translation() == b.translation());
    }
  }
  EXPECT_EQ(cached, 20);  // the loads did cache them: the comparison is not vacuous
}

TEST(IdentifyScale, LoadsHoldOneLinkMiddlePerLinkThatCanBend) {
  const std::unique_ptr<Rig> rig = MakeRig("rover_arm");
  const EffectModel& em = *rig->em;
  int bends = 0;
  for (const Candidate& c : em.candidates()) bends += c.type == EffectType::kLinkBending;
  ASSERT_GT(bends, 0);
  ASSERT_LT(bends, em.chain().num_frames());
  const ConfigLoads L = em.Loads(Eigen::VectorXd::Constant(em.chain().nq(), 0.3));
  EXPECT_EQ(static_cast<int>(L.M_mid.size()), bends);
  EXPECT_EQ(static_cast<int>(L.M_mid_unit.size()), bends);
  EXPECT_EQ(static_cast<int>(L.R_mid_T.size()), bends);
}

TEST(ForEachTask, EveryTaskOnceAndTheLowestTasksErrorRethrown) {
  for (const int threads : {1, 2, 3}) {
    std::vector<std::atomic<int>> runs(17);
    ForEachTask(17, threads, [&](int i) { ++runs[i]; });
    for (const std::atomic<int>& r : runs) EXPECT_EQ(r.load(), 1) << threads << " threads";
    try {
      ForEachTask(9, threads, [](int i) {
        if (i == 4 || i == 7) throw std::runtime_error("task " + std::to_string(i));
      });
      ADD_FAILURE() << "no exception with " << threads << " threads";
    } catch (const std::runtime_error& e) {
      EXPECT_STREQ(e.what(), "task 4");
    }
  }
}

}  // namespace
}  // namespace flexbench::identify
