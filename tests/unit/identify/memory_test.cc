// Identification's memory per row: a point row carries no pose row's matrices;
// cross-validation reads its folds' rows in place (the same bits as fitting copies of them)
// instead of copying every row and its loads once per fold; loads beyond a budget are not kept;
// with many rows the normal equations, observable bases and screening steps come from row
// blocks and products of columns, not from whole Jacobians copied (the same results to
// rounding).
#include <gtest/gtest.h>

#include <Eigen/SVD>
#include <array>
#include <cstring>
#include <fstream>
#include <random>

#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/cross_validation.h"
#include "scenarios/identify/equivalence.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/problem.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/common/planar_rows.h"
#include "tests/common/test_util.h"
#include "tests/unit/identify/counting_heap.h"  // test_identify's malloc counts its bytes

namespace flexbench::identify {
namespace {

// planar3 with point rows made by MuJoCo's kinematics (a 0.3 deg offset at joint2), read from
// a CSV as the CLI reads them.
struct Planar {
  sim::MjModelPtr m;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
  DataSet data;
  RowLoads loads;
};

std::unique_ptr<Planar> MakePlanar(int rows,
                                   const std::array<double, 3>& offsets = {0.0, 0.005, 0.0}) {
  auto p = std::make_unique<Planar>();
  const sim::DeclaredModel d =
      sim::LoadDeclaredModel(testing::SourceDir() + "/models/planar3.declared.yaml");
  p->m = sim::LoadModel(d.model_path);
  p->chain = sim::BuildDeclaredChain(p->m.get(), d);
  p->em = std::make_unique<EffectModel>(p->m.get(), p->chain, p->chain.end_effector);
  testing::TempDir dir;
  const std::string path = (dir.path() / "points.csv").string();
  std::mt19937_64 rng(7);
  std::ofstream(path) << testing::kPlanarHeader << testing::PlanarRows(rows, rng, 1e-4, offsets);
  ReadCalibrationCsv(path, p->chain.q_joints, &p->data);
  p->loads = ComputeLoads(*p->em, p->data);
  return p;
}

TEST(IdentifyMemory, APointRowHoldsNoRotationMatrix) {
  // Two 3x3 matrices (144 B) made a row 304 B; pose rows keep theirs behind a pointer.
  EXPECT_LE(sizeof(Observation), 192u);
  Observation point;
  EXPECT_EQ(point.R_base.get(), Mat3::Identity());
  Observation pose;
  pose.R_base = Mat3(Eigen::AngleAxisd(0.3, Vec3::UnitZ()).toRotationMatrix());
  const Observation copy = pose;  // a deep copy: the copy's matrix is its own
  pose.R_base.setIdentity();
  EXPECT_NEAR(copy.R_base.get()(0, 1), -std::sin(0.3), 1e-15);
  EXPECT_EQ(pose.R_base.get(), Mat3::Identity());
}

TEST(IdentifyMemory, AFoldReadInPlaceFitsTheSameBitsAsItsCopy) {
  const auto p = MakePlanar(600);
  const std::vector<int> active = {p->em->FindCandidate("joint_offset@joint2"),
                                   p->em->FindCandidate("joint_compliance@joint2")};
  IdentifyOptions opt;
  opt.threads = 1;
  const Folds folds = MakeFolds(p->data);
  ASSERT_GE(folds.test_rows.size(), 2u);
  std::vector<int> train;
  for (size_t r = 0; r < p->data.rows.size(); ++r) {
    if (!std::binary_search(folds.test_rows[0].begin(), folds.test_rows[0].end(),
                            static_cast<int>(r))) {
      train.push_back(static_cast<int>(r));
    }
  }
  const DataSet train_data = Subset(p->data, train);
  const RowLoads train_loads = p->loads.Subset(train_data, train);
  const Fit copied =
      FitEffects(*p->em, train_data, train_loads, active, {}, Eigen::VectorXd(), opt);
  const Fit in_place =
      FitEffects(*p->em, p->data, p->loads, active, {}, Eigen::VectorXd(), opt, &train);
  ASSERT_EQ(copied.theta.size(), in_place.theta.size());
  for (int k = 0; k < copied.theta.size(); ++k) EXPECT_EQ(copied.theta[k], in_place.theta[k]);
  EXPECT_EQ(copied.rss, in_place.rss);
  EXPECT_EQ(copied.num_residuals, in_place.num_residuals);
  EXPECT_GT(in_place.theta[0], 0.004);  // the planted 0.005 rad, seen through the noise
}

TEST(IdentifyMemory, CrossValidationCopiesNoRow) {
  // Copies of the rows and their loads took about 1.5 KB a row per fold on planar3; what is
  // left is the fold fit's own residuals and Jacobian (a few doubles a row per parameter).
  const int rows = 4000;
  const auto p = MakePlanar(rows);
  const std::vector<int> active = {p->em->FindCandidate("joint_offset@joint2")};
  IdentifyOptions opt;
  opt.threads = 1;
  const Fit fit = FitEffects(*p->em, p->data, p->loads, active, Eigen::VectorXd(), opt);
  const Folds folds = MakeFolds(p->data);
  double cv = 0.0;
  const testing::PeakMemory peak;
  cv = CrossValidate(*p->em, p->data, p->loads, folds, fit, opt);
  const double per_row = peak.HeapBytes() / rows;
  EXPECT_GT(cv, 0.0);
  EXPECT_LT(per_row, 200.0) << "cross-validation's peak heap per row";
  RecordProperty("cross_validation_peak_heap_B_per_row", std::to_string(per_row));
  std::printf("cross-validation peak heap: %.0f B a row\n", per_row);
}

TEST(IdentifyMemory, AJacobianInBlocksOfRowsHasTheBitsOfOneProduct) {
  // From two blocks of rows on, the columns of an effect with a reduced basis are multiplied by
  // it a block of rows at a time; each half of the rows on its own is one product.
  const int rows = 4000;
  const auto p = MakePlanar(rows);
  const std::vector<int> active = {p->em->FindCandidate("joint_offset@joint1"),
                                   p->em->FindCandidate("joint_origin@joint2")};
  Eigen::MatrixXd B(6, 3);
  B << 1, 0, 0.5, 0, 1, -0.25, 0.3, 0, 0, 0, 0.7, 0, -0.2, 0, 1, 0, 0.1, 0.4;
  const std::vector<Eigen::MatrixXd> basis = {Eigen::MatrixXd(), B};
  IdentifyOptions opt;
  opt.threads = 2;
  opt.row_block = 1500;
  const Problem all(*p->em, p->data, p->loads, active, basis, opt);
  Eigen::VectorXd x(all.num_params());
  x << 0.004, 1e-3, -2e-3, 5e-4;
  const Eigen::MatrixXd J = all.Jacobian(x);
  std::vector<int> first, second;
  for (int r = 0; r < rows; ++r) (r < rows / 2 ? first : second).push_back(r);
  int at = 0;
  for (const std::vector<int>* half : {&first, &second}) {
    const Problem pr(*p->em, p->data, p->loads, active, basis, opt, half);
    const Eigen::MatrixXd Jh = pr.Jacobian(x);
    ASSERT_EQ(Jh.cols(), J.cols());
    for (Eigen::Index c = 0; c < J.cols(); ++c) {
      EXPECT_EQ(std::memcmp(Jh.col(c).data(), J.col(c).data() + at, sizeof(double) * Jh.rows()), 0)
          << "column " << c << " of rows from " << at / 3;
    }
    at += static_cast<int>(Jh.rows());
  }
  EXPECT_GT(J.col(1).norm(), 0.0);
}

TEST(IdentifyMemory, UnkeptLoadsTakeNoMemoryPerRow) {
  const auto p = MakePlanar(4000);
  const testing::PeakMemory peak;
  const RowLoads none(*p->em, p->data, {}, Eigen::VectorXd(), 0.0);
  EXPECT_LT(peak.HeapBytes(), 64.0 * 1024) << "loads kept for none of 4000 rows";
  const RowLoads all = ComputeLoads(*p->em, p->data);
  EXPECT_GT(peak.HeapBytes() / 4000, 400.0) << "planar3's kept loads (the measure is live)";
}

TEST(IdentifyMemory, RowBlocksGiveTheNormalEquationsAndBasesOfWholeJacobians) {
  // From two blocks of rows on, the Levenberg-Marquardt normal equations are summed over blocks
  // and a candidate's observable basis comes from the triangular factor of [J_fit J_c]: the
  // whole Jacobians' results to rounding, without holding either for every row.
  IdentifyOptions opt;
  opt.threads = 2;
  opt.row_block = 1000;
  const int rows = 2 * opt.row_block + 700;
  const auto p = MakePlanar(rows);
  const std::vector<int> active = {p->em->FindCandidate("joint_offset@joint2")};
  const Fit fit = FitEffects(*p->em, p->data, p->loads, active, Eigen::VectorXd(), opt);
  EXPECT_NEAR(fit.theta[0], 0.005, 1e-4);  // the planted offset, fitted on the blocks
  const Problem pr(*p->em, p->data, p->loads, fit.active, fit.basis, opt);
  const Eigen::VectorXd x = StateOf(pr, fit);
  const Eigen::VectorXd r = pr.Residuals(x);
  const Eigen::MatrixXd J = pr.Jacobian(x);
  Eigen::MatrixXd A;
  Eigen::VectorXd g;
  NormalEquations(pr, x, &r, &A, &g);
  const Eigen::MatrixXd A_whole = J.transpose() * J;
  const Eigen::VectorXd g_whole = J.transpose() * r;
  EXPECT_LT((A - A_whole).norm(), 1e-12 * A_whole.norm());
  EXPECT_LT((g - g_whole).norm(), 1e-9 * g_whole.norm() + 1e-12 * J.norm() * r.norm());
  int checked = 0;
  for (const char* name : {"joint_origin@joint2", "joint_origin@joint3", "joint_offset@joint1"}) {
    const int c = p->em->FindCandidate(name);
    ASSERT_GE(c, 0) << name;
    ++checked;
    double rel = 0.0, rel_whole = 0.0;
    const Eigen::MatrixXd B = CandidateBasis(*p->em, p->data, p->loads, fit, c, opt, &rel);
    const Eigen::MatrixXd B_whole =
        ObservableBasis(CandidateJacobian(*p->em, p->data, p->loads, fit, c, opt), Projector(J),
                        opt.rank_tol, &rel_whole);
    ASSERT_EQ(B.cols(), B_whole.cols()) << name;
    EXPECT_NEAR(rel, rel_whole, 1e-9) << name;
    // Both against the SVD of the whole projected columns (ObservableBasis on few rows).
    const Eigen::MatrixXd Jc = CandidateJacobian(*p->em, p->data, p->loads, fit, c, opt);
    Eigen::VectorXd scale(Jc.cols());
    for (Eigen::Index k = 0; k < Jc.cols(); ++k) scale[k] = 1.0 / Jc.col(k).norm();
    const Eigen::MatrixXd Js = Jc * scale.asDiagonal();
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(Projector(J).Apply(Js), Eigen::ComputeThinV);
    double rel_svd = 0.0;
    for (Eigen::Index i = 0; i < svd.singularValues().size(); ++i) {
      rel_svd = std::max(rel_svd, svd.singularValues()[i] / (Js * svd.matrixV().col(i)).norm());
    }
    EXPECT_NEAR(rel_whole, rel_svd, 1e-9) << name;
    // The same directions (each up to its sign).
    for (Eigen::Index k = 0; k < B.cols(); ++k) {
      EXPECT_NEAR(std::abs(B.col(k).dot(B_whole.col(k))), 1.0, 1e-6) << name << " " << k;
    }
    EXPECT_GT(B.cols(), 0) << name;
  }
  EXPECT_EQ(checked, 3);
  // Screening's Gauss-Newton step from the columns' products lands where the full fit does.
  const Fit wrong =
      FitEffects(*p->em, p->data, p->loads, {p->em->FindCandidate("joint_offset@joint1")},
                 Eigen::VectorXd(), opt);
  const int c = p->em->FindCandidate("joint_offset@joint2");
  const Eigen::MatrixXd B = Eigen::MatrixXd::Identity(1, 1);
  const Fit screened = ScreenWith(*p->em, p->data, p->loads, wrong, c, B,
                                  FitJacobian(*p->em, p->data, p->loads, wrong, opt),
                                  CandidateJacobian(*p->em, p->data, p->loads, wrong, c, opt),
                                  FitResiduals(*p->em, p->data, p->loads, wrong, opt), opt);
  const Fit full = FitWith(*p->em, p->data, p->loads, wrong, c, B, opt);
  ASSERT_EQ(screened.theta.size(), 2);
  EXPECT_NEAR(screened.theta[1], 0.005, 1e-4);
  EXPECT_NEAR(screened.theta[0], full.theta[0], 1e-6);
  EXPECT_NEAR(screened.theta[1], full.theta[1], 1e-6);
  EXPECT_LT(screened.rss, wrong.rss);
}

TEST(IdentifyMemory, RowBlocksIdentifyWhatTheWholeRowsDo) {
  // Every stage in blocks of rows (screening, equivalences, unidentifiable and simpler
  // candidates, covariances, overlap: each from the triangular factor of its columns) against
  // the same stages on the rows whole: the same findings, and the same numbers to rounding.
  const auto p = MakePlanar(1200, {0.004, 0.005, -0.003});
  std::vector<int> all(p->em->candidates().size());
  for (size_t c = 0; c < all.size(); ++c) all[c] = static_cast<int>(c);
  IdentifyOptions opt;
  opt.threads = 2;
  const IdentifyResult whole = Identify(*p->em, p->data, p->loads, all, opt);
  opt.row_block = 100;  // twelve blocks
  EXPECT_TRUE(Problem(*p->em, p->data, p->loads, {}, {}, opt).InRowBlocks());
  const IdentifyResult blocks = Identify(*p->em, p->data, p->loads, all, opt);
  const auto names = [&](const Fit& f) {
    std::vector<std::string> out;
    for (int c : f.active) out.push_back(p->em->candidates()[c].Name());
    return out;
  };
  ASSERT_EQ(names(blocks.after), names(whole.after));
  ASSERT_FALSE(whole.after.active.empty());
  EXPECT_LT((blocks.after.theta - whole.after.theta).norm(), 1e-8 * whole.after.theta.norm());
  ASSERT_EQ(blocks.equivalence.size(), whole.equivalence.size());
  for (size_t e = 0; e < whole.equivalence.size(); ++e) {
    EXPECT_EQ(blocks.equivalence[e].name, whole.equivalence[e].name);
    EXPECT_NEAR(blocks.equivalence[e].correction_rms, whole.equivalence[e].correction_rms,
                1e-8 * whole.equivalence[e].correction_rms);
    ASSERT_EQ(blocks.equivalence[e].members[0].value.size(),
              whole.equivalence[e].members[0].value.size());
    for (size_t k = 0; k < whole.equivalence[e].members[0].value.size(); ++k) {
      EXPECT_NEAR(blocks.equivalence[e].members[0].value[k],
                  whole.equivalence[e].members[0].value[k], 1e-8);
    }
  }
  EXPECT_EQ(blocks.unidentifiable, whole.unidentifiable);
  EXPECT_EQ(blocks.simpler, whole.simpler);
  EXPECT_EQ(blocks.stopped_by, whole.stopped_by);
  EXPECT_NEAR(blocks.overlap, whole.overlap, 1e-9);
  EXPECT_NEAR(blocks.condition_number, whole.condition_number, 1e-6 * whole.condition_number);
  EXPECT_LT((blocks.theta_cov - whole.theta_cov).norm(), 1e-6 * whole.theta_cov.norm());
  EXPECT_NEAR(blocks.cv_after, whole.cv_after, 1e-9 * whole.cv_after);
  // What the stages found, so that the comparison has something to compare.
  std::printf("chosen %zu, unidentifiable %zu, simpler %zu, overlap %.4f\n",
              whole.after.active.size(), whole.unidentifiable.size(), whole.simpler.size(),
              whole.overlap);
  for (const EquivalenceSet& s : whole.equivalence) std::printf("  %s\n", s.name.c_str());
}

}  // namespace
}  // namespace flexbench::identify
