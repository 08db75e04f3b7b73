#include "estimators/stats/shared_nees.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>

namespace flexbench::stats {

template <int N>
SharedNeesStep MakeSharedNeesStep(const Eigen::Matrix<double, N, Eigen::Dynamic>& G_in,
                                  const Eigen::Matrix<double, N, N>& cov) {
  using MatN = Eigen::Matrix<double, N, N>;
  const MatN P = 0.5 * (cov + cov.transpose());
  Eigen::SelfAdjointEigenSolver<MatN> eig(P);
  const double tol = 1e-12 * std::max(eig.eigenvalues().maxCoeff(), 1e-300);
  MatN P_pinv = MatN::Zero();
  SharedNeesStep step;
  for (int i = 0; i < N; ++i) {
    const double l = eig.eigenvalues()[i];
    if (l <= tol) continue;
    P_pinv += eig.eigenvectors().col(i) * eig.eigenvectors().col(i).transpose() / l;
    ++step.dof;
  }
  step.t1 = step.t2 = step.dof;  // P^+ P is the projector on P's range
  if (G_in.cols() == 0) return step;
  Eigen::Matrix<double, N, Eigen::Dynamic> G = G_in;
  const double largest = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(G.transpose() * P_pinv * G)
                             .eigenvalues()
                             .maxCoeff();
  if (largest > 1.0) G /= std::sqrt(largest);
  const MatN A = P_pinv * (P - G * G.transpose());  // P^+ W
  step.t1 = A.trace();
  step.t2 = (A * A).trace();
  step.X = G.transpose() * A * P_pinv * G;
  step.Y = G.transpose() * P_pinv * G;
  return step;
}
template SharedNeesStep MakeSharedNeesStep<6>(const Eigen::Matrix<double, 6, Eigen::Dynamic>&,
                                              const Eigen::Matrix<double, 6, 6>&);
template SharedNeesStep MakeSharedNeesStep<3>(const Eigen::Matrix<double, 3, Eigen::Dynamic>&,
                                              const Eigen::Matrix<double, 3, 3>&);

namespace {
// z^T A z without a temporary (0 for an empty A).
double QuadraticForm(const Eigen::MatrixXd& A, const Eigen::VectorXd& z) {
  double sum = 0.0;
  for (Eigen::Index j = 0; j < A.cols(); ++j) {
    double col = 0.0;
    for (Eigen::Index i = 0; i < A.rows(); ++i) col += A(i, j) * z[i];
    sum += col * z[j];
  }
  return sum;
}
}  // namespace

SharedNeesDistribution::SharedNeesDistribution(const std::vector<SharedNeesStep>& steps,
                                               int draws) {
  double t1 = 0.0, t2 = 0.0;
  Eigen::MatrixXd X, Y;
  for (const SharedNeesStep& s : steps) {
    t1 += s.t1;
    t2 += s.t2;
    if (!s.shared()) continue;
    X = X.size() == 0 ? s.X : Eigen::MatrixXd(X + s.X);
    Y = Y.size() == 0 ? s.Y : Eigen::MatrixXd(Y + s.Y);
  }
  const double n = static_cast<double>(steps.size());
  if (Y.size() == 0) draws = 1;
  std::mt19937_64 rng(20261126);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXd z(Y.rows());
  double sum = 0.0, sum2 = 0.0;
  for (int d = 0; d < draws; ++d) {
    for (int i = 0; i < z.size(); ++i) z[i] = normal(rng);
    const double mean = (t1 + QuadraticForm(Y, z)) / n;
    const double var = (2.0 * t2 + 4.0 * QuadraticForm(X, z)) / (n * n);
    if (!(mean > 0.0) || !(var > 0.0)) continue;
    given_z_.push_back({mean * mean / var, var / mean});
    sum += mean;
    sum2 += var + mean * mean;
  }
  // The mixture's mean plus 12 of its standard deviations: above any quantile asked for here.
  const double m = sum / std::max<size_t>(1, given_z_.size());
  const double v = sum2 / std::max<size_t>(1, given_z_.size()) - m * m;
  hi_ = m + 12.0 * std::sqrt(std::max(v, 0.0));
  shape_ = v > 0.0 ? m * m / v : 1.0;
  scale_ = v > 0.0 ? v / m : m;
}

// With a shared term each gamma's CDF is Wilson and Hilferty's cube-root normal form (shapes here
// are the steps' dof summed, 15 and more, where it is within about 1e-4; and 20x cheaper than
// the incomplete gamma function); a single gamma (nothing shared) is evaluated exactly.
double SharedNeesDistribution::Cdf(double x) const {
  if (given_z_.empty()) return 1.0;
  if (given_z_.size() == 1) {
    return RegularizedGammaP(given_z_[0].shape, x / given_z_[0].scale);
  }
  double sum = 0.0;
  for (const Gamma& g : given_z_) {
    const double v = 1.0 / (9.0 * g.shape);
    const double t = (std::cbrt(x / (g.shape * g.scale)) - (1.0 - v)) / std::sqrt(v);
    sum += 0.5 * std::erfc(-t / std::sqrt(2.0));
  }
  return sum / given_z_.size();
}

// The Illinois variant of regula falsi on [0, hi] (the CDF rises monotonically from 0 to 1
// there), until the probability is within 1e-7 of p or the bracket within 1e-9 of hi.
double SharedNeesDistribution::Quantile(double p) const {
  if (given_z_.size() == 1) {  // nothing shared: a chi-square of the steps' summed dof, exactly
    return ChiSquareQuantile(p, 2.0 * given_z_[0].shape) * 0.5 * given_z_[0].scale;
  }
  // Bracket from the gamma with the mixture's mean and variance, widened until it holds.
  const double x0 = std::max(1e-300, ChiSquareQuantile(p, 2.0 * shape_) * 0.5 * scale_);
  double a = x0 / 1.1, b = std::min(x0 * 1.1, hi_);
  double fa = Cdf(a) - p, fb = Cdf(b) - p;
  while (fa > 0.0 && a > 1e-12 * hi_) a /= 1.5, fa = Cdf(a) - p;
  while (fb < 0.0 && b < hi_) b = std::min(b * 1.5, hi_), fb = Cdf(b) - p;
  int side = 0;
  for (int it = 0; it < 100 && b - a > 1e-9 * hi_; ++it) {
    const double c = (a * fb - b * fa) / (fb - fa);
    const double fc = Cdf(c) - p;
    if (std::abs(fc) < 1e-7) return c;
    if ((fc < 0.0) == (fa < 0.0)) {
      a = c, fa = fc;
      if (side == -1) fb *= 0.5;
      side = -1;
    } else {
      b = c, fb = fc;
      if (side == 1) fa *= 0.5;
      side = 1;
    }
  }
  return 0.5 * (a + b);
}

ChiSquareBounds SharedNeesBounds(const std::vector<SharedNeesStep>& steps, double alpha) {
  const SharedNeesDistribution dist(steps);
  return {dist.Quantile(0.5 * alpha), dist.Quantile(1.0 - 0.5 * alpha)};
}

}  // namespace flexbench::stats
