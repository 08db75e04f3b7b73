// The analytic derivatives of the augmented kinematics (identification's Jacobians
// were central differences, each column re-predicting every row twice) equal central differences
// of PredictPose, for every candidate they cover, at random configurations and random sets of
// active effects of realistic size; and the identification problem's Jacobian and candidate
// columns equal their all-numeric forms on rows of every kind (points, groups with distances,
// poses, pixels), one candidate at a time or all in one pass.
//
// Tolerance 1e-7 relative (plus 1e-7 absolute, in the units of the derivative): central
// differences err by h^2 |f'''| / 6 + eps |f| / h. With the candidates' steps (h = 1e-6 for
// angles and lengths on a chain of ~1 m, 1e-7 rad/(N m) for compliances under loads of ~50 N m)
// that is at most ~2e-9 relative, 50 times below the tolerance; a missing Lie Jacobian factor at
// the test's angles (~0.01 rad) errs by ~5e-3, a wrong lever or sign by ~1. The problem's
// columns are whitened: its residuals reach M ~ 3e3 (3 m at 1e-3 m, 1000 px at 0.5 px), whose
// rounding eps M, differenced over 2 h, allows an absolute 10 eps M / h on top (7e-5 at the
// compliances' h = 1e-7, against columns of ~1e3; the small cubic-spring column needs it).
#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "estimators/lie/so3.h"
#include "scenarios/identify/effect_model.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/problem.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/identify_test_util.h"
#include "tests/common/test_util.h"

namespace flexbench::identify {
namespace {

constexpr double kTol = 1e-7;

using Rig = testing::ModelRig;
const auto MakeRig = testing::LoadModelRig;

// A value of realistic size for parameter k of c (angles ~0.01 rad, so Lie Jacobians matter).
double Value(const Candidate& c, int k, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  switch (c.type) {
    case EffectType::kLinkLength:
    case EffectType::kLinkOffset:
      return 0.005 * n(rng);
    case EffectType::kJointCompliance:
    case EffectType::kLinkBending:
    case EffectType::kBaseCompliance:
    case EffectType::kStiffeningSpring:
    case EffectType::kLateralCompliance:
      return 2e-3 * std::abs(n(rng));
    case EffectType::kThermalExpansion:
      return 4e-4 * n(rng);
    case EffectType::kPayload:
      return k == 0 ? 1.5 : 0.05 * n(rng);
    case EffectType::kJointOrigin:
      return (k < 3 ? 0.004 : 0.02) * n(rng);
    default:
      return 0.02 * n(rng);
  }
}

// A random set of active effects (each candidate with probability 1/3) and its theta.
void RandomActive(const EffectModel& em, std::mt19937_64& rng, std::vector<int>* active,
                  Eigen::VectorXd* theta) {
  std::bernoulli_distribution pick(1.0 / 3.0);
  std::vector<double> t;
  active->clear();
  for (size_t c = 0; c < em.candidates().size(); ++c) {
    if (!pick(rng)) continue;
    active->push_back(static_cast<int>(c));
    for (int k = 0; k < em.candidates()[c].num_params; ++k) {
      t.push_back(Value(em.candidates()[c], k, rng));
    }
  }
  *theta = Eigen::Map<const Eigen::VectorXd>(t.data(), t.size());
}

// Whether `cand` moves a translation or origin at a frame whose own link bending is active
// (the bend's pivot moves with it).
bool BentAt(const EffectModel& em, const std::vector<int>& active, const Candidate& cand) {
  if (cand.type != EffectType::kLinkLength && cand.type != EffectType::kLinkOffset &&
      cand.type != EffectType::kJointOrigin) {
    return false;
  }
  for (int a : active) {
    const Candidate& b = em.candidates()[a];
    if (b.type == EffectType::kLinkBending && b.frame == cand.frame) return true;
  }
  return false;
}

bool Near(const Vec3& a, const Vec3& b) { return (a - b).norm() <= kTol * (1.0 + b.norm()); }

class TangentTest : public ::testing::TestWithParam<std::string> {};

TEST_P(TangentTest, PoseTangentsEqualCentralDifferences) {
  const std::unique_ptr<Rig> rig = MakeRig(GetParam());
  const EffectModel& em = *rig->em;
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  EffectModel::Workspace ws = em.MakeWorkspace();
  int covered = 0, queried = 0, bent = 0;
  for (int trial = 0; trial < 12; ++trial) {
    Eigen::VectorXd q(em.chain().nq());
    for (int k = 0; k < q.size(); ++k) q[k] = u(rng);
    const ConfigLoads L = em.Loads(q);
    std::vector<int> active;
    Eigen::VectorXd theta;
    RandomActive(em, rng, &active, &theta);
    for (size_t c = 0; c < em.candidates().size(); ++c) {
      ++queried;
      if (!em.HasTangent(static_cast<int>(c), active)) continue;
      ++covered;
      const Candidate& cand = em.candidates()[c];
      if (BentAt(em, active, cand)) ++bent;
      std::vector<EffectModel::Tangent> tangent(cand.num_params);
      const lie::SE3 T =
          em.PoseTangents(q, L, active, theta.data(), {static_cast<int>(c)}, ws, tangent.data());
      // The pose is PredictPose's, bit for bit.
      const lie::SE3 T_ref = em.PredictPose(q, L, active, theta.data(), ws);
      EXPECT_TRUE(T.rotation() == T_ref.rotation() && T.translation() == T_ref.translation());
      // c added to the active ones (at zero, so it adds to an active copy of itself).
      std::vector<int> act = active;
      act.push_back(static_cast<int>(c));
      Eigen::VectorXd th(theta.size() + cand.num_params);
      th << theta, Eigen::VectorXd::Zero(cand.num_params);
      for (int k = 0; k < cand.num_params; ++k) {
        Eigen::VectorXd tp = th, tm = th;
        tp[theta.size() + k] += cand.step;
        tm[theta.size() + k] -= cand.step;
        const lie::SE3 Tp = em.PredictPose(q, L, act, tp.data(), ws);
        const lie::SE3 Tm = em.PredictPose(q, L, act, tm.data(), ws);
        const Vec3 dp = (Tp.translation() - Tm.translation()) / (2 * cand.step);
        const Vec3 w = lie::SO3Log(Tp.rotation() * Tm.rotation().transpose()) / (2 * cand.step);
        const Vec3& dp_analytic = tangent[k].dp;
        EXPECT_TRUE(Near(dp_analytic, dp))
            << cand.Name() << "[" << k << "] trial " << trial << ": d p " << dp_analytic.transpose()
            << " vs " << dp.transpose();
        EXPECT_TRUE(Near(tangent[k].w, w))
            << cand.Name() << "[" << k << "] trial " << trial << ": w " << tangent[k].w.transpose()
            << " vs " << w.transpose();
      }
    }
  }
  // Not vacuous: most queries are analytic (thermal and payload not), bent links' translations
  // and origins among them.
  EXPECT_GT(covered, queried * 3 / 4) << covered << " of " << queried;
  EXPECT_GT(bent, 0);
}

// Rows of every kind (points, groups, poses, pixels, gravity), at random configurations, observed
// with a camera in front of the arm.
DataSet MixedRows(const EffectModel& em, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  std::normal_distribution<double> n(0.0, 1e-3);
  DataSet d;
  d.sets = {"s"};
  d.groups = {"g0", "g1"};
  d.distances = {{0, 1, 0.05}};
  d.camera.present = true;
  d.camera.intrinsics.fx = d.camera.intrinsics.fy = 600.0;
  d.camera.intrinsics.cx = 320.0;
  d.camera.intrinsics.cy = 240.0;
  Mat3 R;
  R.col(0) = Vec3(0, 1, 0);
  R.col(1) = Vec3(0, 0, -1);
  R.col(2) = Vec3(-1, 0, 0);
  d.camera.T_base_cam = lie::SE3(R, Vec3(3.0, 0.0, 0.3));
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (int r = 0; r < 24; ++r) {
    Observation o;
    o.q = Eigen::VectorXd(em.chain().nq());
    for (int k = 0; k < o.q.size(); ++k) o.q[k] = u(rng);
    const lie::SE3 T = em.PredictPose(o.q, em.Loads(o.q), {}, nullptr, ws);
    o.type = static_cast<ObservationType>(r % 5);
    o.p_base = T.translation() + Vec3(n(rng), n(rng), n(rng));
    o.R_base = T.rotation() * lie::SO3Exp(Vec3(n(rng), n(rng), n(rng)));
    o.group = r % 2;
    o.uv = Eigen::Vector2d(320.0, 240.0);
    o.up() = lie::SO3Exp(Vec3(n(rng), n(rng), n(rng))) * T.rotation().transpose() *
             GravityUp(em, {}, nullptr);
    d.rows.push_back(o);
  }
  return d;
}

TEST_P(TangentTest, ProblemJacobianEqualsCentralDifferences) {
  const std::unique_ptr<Rig> rig = MakeRig(GetParam());
  const EffectModel& em = *rig->em;
  std::mt19937_64 rng(7);
  const DataSet d = MixedRows(em, rng);
  const RowLoads loads = ComputeLoads(em, d);
  IdentifyOptions opt;
  opt.point_std_m = 1e-3;
  opt.rotation_std_rad = 1e-3;
  int zero_columns = 0;
  for (int trial = 0; trial < 4; ++trial) {
    std::vector<int> active;
    Eigen::VectorXd theta;
    RandomActive(em, rng, &active, &theta);
    // A reduced basis for the first effect with more than one parameter (as selection keeps).
    std::vector<Eigen::MatrixXd> basis(active.size());
    for (size_t e = 0; e < active.size(); ++e) {
      const int np = em.candidates()[active[e]].num_params;
      if (np > 1) {
        basis[e] = Eigen::MatrixXd::Random(np, np - 1);
        break;
      }
    }
    const Problem pr(em, d, loads, active, basis, opt);
    const auto floor = [](double step) { return 10.0 * 2.2e-16 * 3e3 / step; };
    Eigen::VectorXd x(pr.num_params());
    x.head(pr.num_alpha()) = pr.Alpha(theta);
    x.tail(6) << 0.3, 0.1, 0.4, 0.33, 0.12, 0.41;
    const Eigen::MatrixXd J = pr.Jacobian(x);
    const Eigen::MatrixXd Jn = pr.NumericJacobian(x);
    ASSERT_EQ(J.rows(), Jn.rows());
    ASSERT_EQ(J.cols(), Jn.cols());
    for (size_t e = 0, k = 0; e < active.size(); ++e) {
      const double step = em.candidates()[active[e]].step;
      for (Eigen::Index j = 0; j < pr.basis(e).cols(); ++j, ++k) {
        EXPECT_LE((J.col(k) - Jn.col(k)).lpNorm<Eigen::Infinity>(),
                  kTol * Jn.col(k).lpNorm<Eigen::Infinity>() + floor(step))
            << "trial " << trial << " " << em.candidates()[active[e]].Name() << " column " << j;
      }
    }
    // The group points' and distances' columns are exact in both.
    EXPECT_TRUE(J.rightCols(6) == Jn.rightCols(6));
    // All candidates in one pass give each one's columns, bit for bit.
    std::vector<int> all(em.candidates().size());
    for (size_t c = 0; c < all.size(); ++c) all[c] = static_cast<int>(c);
    const std::vector<Eigen::MatrixXd> batch = pr.CandidateColumns(x, all);
    ASSERT_EQ(batch.size(), all.size());
    for (size_t c = 0; c < em.candidates().size(); ++c) {
      const Eigen::MatrixXd Cc = pr.CandidateColumns(x, static_cast<int>(c));
      EXPECT_TRUE(batch[c] == Cc) << em.candidates()[c].Name();
      const Eigen::MatrixXd Cn = pr.NumericCandidateColumns(x, static_cast<int>(c));
      for (Eigen::Index k = 0; k < Cc.cols(); ++k) {
        EXPECT_LE((Cc.col(k) - Cn.col(k)).lpNorm<Eigen::Infinity>(),
                  kTol * Cn.col(k).lpNorm<Eigen::Infinity>() + floor(em.candidates()[c].step))
            << "trial " << trial << " " << em.candidates()[c].Name() << "[" << k << "]";
        // Selection tells an unobservable candidate (a point on a joint's axis) by its zero
        // column: where the differences are exactly zero, so are the analytic columns.
        if (Cn.col(k).isZero(0.0)) {
          EXPECT_TRUE(Cc.col(k).isZero(0.0)) << em.candidates()[c].Name() << "[" << k << "]";
          ++zero_columns;
        }
      }
    }
  }
  std::printf("%s: %d exactly zero candidate columns\n", GetParam().c_str(), zero_columns);
}

INSTANTIATE_TEST_SUITE_P(Models, TangentTest, ::testing::Values("rover_arm", "planar3", "jsk_arm"));

}  // namespace
}  // namespace flexbench::identify
