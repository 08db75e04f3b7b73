#include "estimators/lie/compound.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/sampling.h"
#include "tests/unit/lie/lie_test_util.h"

namespace flexbench::lie {
namespace {

using Mat12 = Eigen::Matrix<double, 12, 12>;
using Vec12 = Eigen::Matrix<double, 12, 1>;

Mat6 RandomMatrix(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Mat6 A;
  for (int i = 0; i < 36; ++i) A(i) = n(rng);
  return A;
}

// A PSD covariance with per-axis standard deviations `sd` and random correlations.
Mat6 RandomCovariance(std::mt19937_64& rng, const Vec6& sd) {
  const Mat6 A = RandomMatrix(rng);
  Mat6 C = A * A.transpose() + 3.0 * Mat6::Identity();
  const Vec6 d = C.diagonal().cwiseSqrt().cwiseInverse();
  C = d.asDiagonal() * C * d.asDiagonal();  // correlation matrix
  return sd.asDiagonal() * C * sd.asDiagonal();
}

Vec6 Sd(double trans, double rot) {
  Vec6 sd;
  sd << trans, trans, trans, rot, rot, rot;
  return sd;
}

// A matrix difference in units of the reference's standard deviations, so metres and radians
// weigh alike: || D^-1/2 (S - S_ref) D^-1/2 ||_F with D = diag(S_ref).
double NormalizedError(const Mat6& S, const Mat6& S_ref) {
  const Vec6 d = S_ref.diagonal().cwiseSqrt().cwiseInverse();
  return (d.asDiagonal() * (S - S_ref) * d.asDiagonal()).norm();
}

// Puts a number into the test's XML report (--gtest_output=xml) for later inspection.
void Record(const std::string& key, double value) {
  ::testing::Test::RecordProperty(key, std::to_string(value));
}

// ---------------------------------------------------------------------------------------------
// Building blocks against brute-force sums over the basis (G_k = ad(e_k)).

Mat6 Generator(int k) { return CurlyWedge(Vec6::Unit(k)); }

TEST(CompoundBlocks, CurlyCongruenceExpectationMatchesBasisSum) {
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 5; ++trial) {
    const Mat6 A = RandomMatrix(rng);  // deliberately non-symmetric
    const Mat6 M = RandomMatrix(rng);
    Mat6 expected = Mat6::Zero();
    for (int k = 0; k < 6; ++k) {
      for (int l = 0; l < 6; ++l) expected += A(k, l) * Generator(k) * M * Generator(l).transpose();
    }
    EXPECT_LT((CurlyCongruenceExpectation(A, M) - expected).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(CompoundBlocks, CurlySquareExpectationMatchesBasisSum) {
  std::mt19937_64 rng(2);
  const Mat6 A = RandomMatrix(rng);
  Mat6 expected = Mat6::Zero();
  for (int k = 0; k < 6; ++k) {
    for (int l = 0; l < 6; ++l) expected += A(k, l) * Generator(k) * Generator(l);
  }
  EXPECT_LT((CurlySquareExpectation(A) - expected).cwiseAbs().maxCoeff(), 1e-13);
}

TEST(CompoundBlocks, BchMeanMatchesBasisSum) {
  std::mt19937_64 rng(3);
  const Mat6 C = RandomMatrix(rng);
  Vec6 expected = Vec6::Zero();
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) expected += 0.5 * C(i, j) * Generator(i) * Vec6::Unit(j);
  }
  EXPECT_LT((BchMean(C) - expected).cwiseAbs().maxCoeff(), 1e-14);
}

// An independent evaluation of the truncated moment series: write (a, b) = (La w, Lb w) with w
// standard normal in R^12 and apply E[w_p w_q w_r w_s] = d_pq d_rs + d_pr d_qs + d_ps d_qr
// directly to the BCH terms of [PPOE eq. 12].
Mat6 BruteForceFourthOrder(const Mat12& P) {
  GaussianSampler<12> factor(P);
  const Eigen::Matrix<double, 6, 12> La = factor.factor().topRows<6>();
  const Eigen::Matrix<double, 6, 12> Lb = factor.factor().bottomRows<6>();
  const Eigen::Matrix<double, 6, 12> Lc = La + Lb;
  Mat6 out = Lc * Lc.transpose();
  // 1/4 E[(ad_a b)(ad_a b)^T], h_pq = ad(La_p) Lb_q.
  Vec6 trace_h = Vec6::Zero();
  Mat6 sum_pq = Mat6::Zero();
  for (int p = 0; p < 12; ++p) {
    trace_h += CurlyWedge(La.col(p)) * Lb.col(p);
    for (int q = 0; q < 12; ++q) {
      const Vec6 h_pq = CurlyWedge(La.col(p)) * Lb.col(q);
      const Vec6 h_qp = CurlyWedge(La.col(q)) * Lb.col(p);
      sum_pq += h_pq * h_pq.transpose() + h_pq * h_qp.transpose();
    }
  }
  out += 0.25 * (trace_h * trace_h.transpose() + sum_pq);
  // 1/12 E[(ad_a^2 b + ad_b^2 a) c^T] + transpose, c = a + b.
  Mat6 M = Mat6::Zero();
  for (int p = 0; p < 12; ++p) {
    for (int q = 0; q < 12; ++q) {
      const Mat6 Ap = CurlyWedge(La.col(p));
      const Mat6 Aq = CurlyWedge(La.col(q));
      const Mat6 Bp = CurlyWedge(Lb.col(p));
      const Mat6 Bq = CurlyWedge(Lb.col(q));
      // E[X_p X_q y_r z_s] summed: (p=q, r=s) + (p=r, q=s) + (p=s, q=r).
      M += Ap * Ap * Lb.col(q) * Lc.col(q).transpose() +
           Ap * Aq * Lb.col(p) * Lc.col(q).transpose() +
           Ap * Aq * Lb.col(q) * Lc.col(p).transpose();
      M += Bp * Bp * La.col(q) * Lc.col(q).transpose() +
           Bp * Bq * La.col(p) * Lc.col(q).transpose() +
           Bp * Bq * La.col(q) * Lc.col(p).transpose();
    }
  }
  out += (M + M.transpose()) / 12.0;
  return out;
}

Mat12 JointCovariance(const Mat6& Sa, const Mat6& Sb, const Mat6& Cab) {
  Mat12 P;
  P << Sa, Cab, Cab.transpose(), Sb;
  return P;
}

TEST(CompoundBlocks, FourthOrderIndependentMatchesBruteForce) {
  std::mt19937_64 rng(4);
  const Mat6 Sa = RandomCovariance(rng, Sd(0.3, 0.2));
  const Mat6 Sb = RandomCovariance(rng, Sd(0.1, 0.25));
  const Mat6 expected = BruteForceFourthOrder(JointCovariance(Sa, Sb, Mat6::Zero()));
  const Mat6 got = BchSecondMoment(Sa, Sb, CompoundOrder::kFourth);
  EXPECT_LT((got - expected).cwiseAbs().maxCoeff(), 1e-12 * expected.cwiseAbs().maxCoeff());
  // The 4th-order terms are not negligible here: the check has teeth.
  EXPECT_GT((got - (Sa + Sb)).cwiseAbs().maxCoeff(), 1e-3 * expected.cwiseAbs().maxCoeff());
  // Symmetric in (a, b) for independent inputs, as the mirrored Barfoot form relies on.
  EXPECT_LT((BchSecondMoment(Sb, Sa, CompoundOrder::kFourth) - got).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(CompoundBlocks, FourthOrderCorrelatedMatchesBruteForce) {
  std::mt19937_64 rng(5);
  // A random 12x12 PSD joint covariance with strong cross terms.
  Eigen::Matrix<double, 12, 12> A;
  std::normal_distribution<double> n(0.0, 0.15);
  for (int i = 0; i < 144; ++i) A(i) = n(rng);
  const Mat12 P = A * A.transpose();
  const Mat6 Sa = P.topLeftCorner<6, 6>();
  const Mat6 Sb = P.bottomRightCorner<6, 6>();
  const Mat6 Cab = P.topRightCorner<6, 6>();
  const Mat6 expected = BruteForceFourthOrder(P);
  const Mat6 got = BchSecondMoment(Sa, Sb, Cab, CompoundOrder::kFourth);
  EXPECT_LT((got - expected).cwiseAbs().maxCoeff(), 1e-12 * expected.cwiseAbs().maxCoeff());
  // With C = 0 the correlated form reduces to the independent one.
  EXPECT_LT((BchSecondMoment(Sa, Sb, Mat6::Zero(), CompoundOrder::kFourth) -
             BchSecondMoment(Sa, Sb, CompoundOrder::kFourth))
                .cwiseAbs()
                .maxCoeff(),
            1e-15);
}

// ---------------------------------------------------------------------------------------------
// Monte Carlo: X1 Exp(xi1) X2 Exp(xi2) = X1 X2 Exp(xi12); E[xi12 xi12^T] from samples vs the
// 2nd- and 4th-order predictions.

struct MonteCarloResult {
  Mat6 second_moment = Mat6::Zero();
  Vec6 mean = Vec6::Zero();
};

// Compounds a chain of uncertain poses with independent perturbations.
MonteCarloResult SampleChain(const std::vector<UncertainPose>& chain, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<GaussianSampler<6>> samplers;
  SE3 mean;
  for (const UncertainPose& p : chain) {
    samplers.emplace_back(p.cov);
    mean = mean * p.mean;
  }
  const SE3 mean_inv = mean.Inverse();
  MonteCarloResult r;
  for (int i = 0; i < n; ++i) {
    SE3 X;
    for (size_t k = 0; k < chain.size(); ++k) {
      X = X * chain[k].mean * SE3::Exp(samplers[k].Sample(rng));
    }
    const Vec6 xi = (mean_inv * X).Log();
    r.second_moment += xi * xi.transpose();
    r.mean += xi;
  }
  r.second_moment /= n;
  r.mean /= n;
  return r;
}

UncertainPose CompoundChain(const std::vector<UncertainPose>& chain, CompoundOrder order) {
  UncertainPose acc = chain.front();
  for (size_t k = 1; k < chain.size(); ++k) acc = Compound(acc, chain[k], order);
  return acc;
}

std::vector<UncertainPose> RandomChain(std::mt19937_64& rng, int n, const Vec6& sd) {
  std::vector<UncertainPose> chain;
  for (int k = 0; k < n; ++k) chain.push_back({RandomSE3(rng, 0.5), RandomCovariance(rng, sd)});
  return chain;
}

TEST(CompoundMonteCarlo, SmallPerturbationsAllAgree) {
  std::mt19937_64 rng(10);
  const auto chain = RandomChain(rng, 3, Sd(1e-3, 0.1 * kDeg));
  const MonteCarloResult mc = SampleChain(chain, 100000, 11);
  const Mat6 S2 = CompoundChain(chain, CompoundOrder::kSecond).cov;
  const Mat6 S4 = CompoundChain(chain, CompoundOrder::kFourth).cov;
  // Sampling error of a normalised second moment ~ sqrt(2 / n) per entry -> ~0.03 in Frobenius.
  Record("err2", NormalizedError(S2, mc.second_moment));
  Record("err4", NormalizedError(S4, mc.second_moment));
  EXPECT_LT(NormalizedError(S2, mc.second_moment), 0.05);
  EXPECT_LT(NormalizedError(S4, mc.second_moment), 0.05);
  // The two orders differ by O(sigma^2) ~ 1e-6 relative.
  EXPECT_LT(NormalizedError(S4, S2), 1e-4);
}

TEST(CompoundMonteCarlo, SingleSourceIsCarriedExactlyByTheAdjoint) {
  // xi2 = 0: xi12 = Ad_{X2^-1} xi1 exactly, so both orders equal the transported covariance and
  // match Monte Carlo even at 10 deg.
  std::mt19937_64 rng(12);
  const UncertainPose p1{RandomSE3(rng, 0.5), RandomCovariance(rng, Sd(0.05, 10 * kDeg))};
  const UncertainPose p2{RandomSE3(rng, 0.8), Mat6::Zero()};
  const Mat6 S2 = Compound(p1, p2, CompoundOrder::kSecond).cov;
  const Mat6 S4 = Compound(p1, p2, CompoundOrder::kFourth).cov;
  EXPECT_LT((S4 - S2).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LT((S2 - TransportCovariance(p2.mean, p1.cov)).cwiseAbs().maxCoeff(), 1e-15);
  const MonteCarloResult mc = SampleChain({p1, p2}, 200000, 13);
  Record("err", NormalizedError(S2, mc.second_moment));
  EXPECT_LT(NormalizedError(S2, mc.second_moment), 0.03);
}

TEST(CompoundMonteCarlo, FourthOrderIsCloserAtTenDegreesWithSeveralSources) {
  std::mt19937_64 rng(14);
  const auto chain = RandomChain(rng, 6, Sd(0.02, 10 * kDeg));
  const MonteCarloResult mc = SampleChain(chain, 600000, 15);
  const double err2 =
      NormalizedError(CompoundChain(chain, CompoundOrder::kSecond).cov, mc.second_moment);
  const double err4 =
      NormalizedError(CompoundChain(chain, CompoundOrder::kFourth).cov, mc.second_moment);
  Record("err2", err2);
  Record("err4", err4);
  EXPECT_LT(err4, 0.5 * err2) << "2nd: " << err2 << " 4th: " << err4;
  EXPECT_LT(err4, 0.05);
}

TEST(CompoundMonteCarlo, TwoSourcesLargeRotation) {
  // Two poses with 10 deg rotation and 10 cm translation noise (Barfoot & Furgale's setting).
  std::mt19937_64 rng(16);
  const auto chain = RandomChain(rng, 2, Sd(0.1, 10 * kDeg));
  const MonteCarloResult mc = SampleChain(chain, 400000, 17);
  const double err2 =
      NormalizedError(CompoundChain(chain, CompoundOrder::kSecond).cov, mc.second_moment);
  const double err4 =
      NormalizedError(CompoundChain(chain, CompoundOrder::kFourth).cov, mc.second_moment);
  Record("err2", err2);
  Record("err4", err4);
  EXPECT_LT(err4, err2) << "2nd: " << err2 << " 4th: " << err4;
}

// Correlated inputs: sample (xi1, xi2) jointly.
MonteCarloResult SampleCorrelatedPair(const SE3& X1, const SE3& X2, const Mat12& P, int n,
                                      std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  GaussianSampler<12> sampler(P);
  const SE3 mean_inv = (X1 * X2).Inverse();
  MonteCarloResult r;
  for (int i = 0; i < n; ++i) {
    const Vec12 z = sampler.Sample(rng);
    const SE3 X = X1 * SE3::Exp(z.head<6>()) * X2 * SE3::Exp(z.tail<6>());
    const Vec6 xi = (mean_inv * X).Log();
    r.second_moment += xi * xi.transpose();
    r.mean += xi;
  }
  r.second_moment /= n;
  r.mean /= n;
  return r;
}

Mat12 CorrelatedJointCovariance(std::mt19937_64& rng, const Vec6& sd, double rho) {
  // xi2 = rho * M xi1 + sqrt(1 - rho^2) * independent part: strong, non-trivial correlation.
  const Mat6 S1 = RandomCovariance(rng, sd);
  const Mat6 M = Eigen::Matrix<double, 6, 6>::Identity() + 0.3 * RandomMatrix(rng);
  const Mat6 Sind = RandomCovariance(rng, sd);
  Mat12 P;
  P.topLeftCorner<6, 6>() = S1;
  P.topRightCorner<6, 6>() = rho * S1 * M.transpose();
  P.bottomLeftCorner<6, 6>() = rho * M * S1;
  P.bottomRightCorner<6, 6>() = rho * rho * M * S1 * M.transpose() + (1 - rho * rho) * Sind;
  return P;
}

TEST(CompoundMonteCarlo, CorrelatedSmallPerturbations) {
  std::mt19937_64 rng(18);
  const SE3 X1 = RandomSE3(rng, 0.5);
  const SE3 X2 = RandomSE3(rng, 0.5);
  const Mat12 P = CorrelatedJointCovariance(rng, Sd(1e-3, 0.1 * kDeg), 0.8);
  const Mat6 S1 = P.topLeftCorner<6, 6>();
  const Mat6 S2 = P.bottomRightCorner<6, 6>();
  const Mat6 C12 = P.topRightCorner<6, 6>();
  const MonteCarloResult mc = SampleCorrelatedPair(X1, X2, P, 100000, 19);
  const Mat6 cov2 = CompoundCovariance(X2, S1, S2, C12, CompoundOrder::kSecond);
  const Mat6 cov4 = CompoundCovariance(X2, S1, S2, C12, CompoundOrder::kFourth);
  Record("err2", NormalizedError(cov2, mc.second_moment));
  Record("err4", NormalizedError(cov4, mc.second_moment));
  EXPECT_LT(NormalizedError(cov2, mc.second_moment), 0.05);
  EXPECT_LT(NormalizedError(cov4, mc.second_moment), 0.05);
  // Ignoring the correlation is clearly wrong: the check has teeth.
  EXPECT_GT(
      NormalizedError(CompoundCovariance(X2, S1, S2, CompoundOrder::kSecond), mc.second_moment),
      0.5);
}

TEST(CompoundMonteCarlo, CorrelatedTenDegreesFourthOrderIsCloser) {
  std::mt19937_64 rng(20);
  const SE3 X1 = RandomSE3(rng, 0.5);
  const SE3 X2 = RandomSE3(rng, 0.5);
  const Mat12 P = CorrelatedJointCovariance(rng, Sd(0.05, 10 * kDeg), 0.7);
  const Mat6 S1 = P.topLeftCorner<6, 6>();
  const Mat6 S2 = P.bottomRightCorner<6, 6>();
  const Mat6 C12 = P.topRightCorner<6, 6>();
  const MonteCarloResult mc = SampleCorrelatedPair(X1, X2, P, 400000, 21);
  const double err2 = NormalizedError(CompoundCovariance(X2, S1, S2, C12, CompoundOrder::kSecond),
                                      mc.second_moment);
  const double err4 = NormalizedError(CompoundCovariance(X2, S1, S2, C12, CompoundOrder::kFourth),
                                      mc.second_moment);
  Record("err2", err2);
  Record("err4", err4);
  EXPECT_LT(err4, err2) << "2nd: " << err2 << " 4th: " << err4;
  // The BCH mean of the correlated case: 1/2 E[ad(xi1') xi2], checked against the sample mean.
  const Mat6 Cab = X2.Inverse().Adjoint() * C12;
  const Vec6 mean = BchMean(Cab);
  const Vec6 sd = mc.second_moment.diagonal().cwiseSqrt();
  EXPECT_LT(((mc.mean - mean).cwiseQuotient(sd)).cwiseAbs().maxCoeff(), 0.03)
      << "MC mean " << mc.mean.transpose() << "\npredicted " << mean.transpose();
}

TEST(Compound, MeanIsTheProductOfMeans) {
  std::mt19937_64 rng(22);
  const UncertainPose p1{RandomSE3(rng), Mat6::Identity() * 1e-4};
  const UncertainPose p2{RandomSE3(rng), Mat6::Identity() * 2e-4};
  const UncertainPose p12 = Compound(p1, p2, CompoundOrder::kFourth);
  EXPECT_TRUE(p12.mean.IsApprox(p1.mean * p2.mean, 1e-15));
  // [PPOE eq. 15] literally.
  const Mat6 Ad = p2.mean.Inverse().Adjoint();
  EXPECT_LT((Compound(p1, p2, CompoundOrder::kSecond).cov - (Ad * p1.cov * Ad.transpose() + p2.cov))
                .cwiseAbs()
                .maxCoeff(),
            1e-15);
}

}  // namespace
}  // namespace flexbench::lie
