// Seeded sampling in tangent spaces: Monte-Carlo oracles in tests and particle methods.
// Every stream is a caller-owned std::mt19937_64 (docs/design.md: same seed, same bytes out).
#pragma once

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <random>

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"

namespace flexbench::lie {

// Draws x ~ N(0, cov) for a symmetric positive *semi*-definite cov (singular allowed: the
// factor comes from the eigendecomposition, not Cholesky; negative round-off eigenvalues are
// clamped to zero). Fixed size, no heap after construction.
template <int N>
class GaussianSampler {
 public:
  using Vector = Eigen::Matrix<double, N, 1>;
  using Matrix = Eigen::Matrix<double, N, N>;

  explicit GaussianSampler(const Matrix& cov) {
    Eigen::SelfAdjointEigenSolver<Matrix> eig(0.5 * (cov + cov.transpose()));
    const Vector sqrt_lambda = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
    L_ = eig.eigenvectors() * sqrt_lambda.asDiagonal();
  }

  template <class Rng>
  Vector Sample(Rng& rng) {
    Vector z;
    for (int i = 0; i < N; ++i) z[i] = normal_(rng);
    return L_ * z;
  }

  // cov = L L^T.
  const Matrix& factor() const { return L_; }

 private:
  Matrix L_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

// A random pose: rotation uniform on SO(3) (normalised Gaussian quaternion), translation with
// entries uniform in [-translation_scale, translation_scale].
template <class Rng>
SE3 RandomSE3(Rng& rng, double translation_scale = 1.0) {
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-translation_scale, translation_scale);
  // Draw in a fixed order: function-argument evaluation order is unspecified.
  Vec4 wxyz;
  for (int i = 0; i < 4; ++i) wxyz[i] = normal(rng);
  Quat q(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
  q.normalize();
  Vec3 t;
  for (int i = 0; i < 3; ++i) t[i] = uniform(rng);
  return SE3(q.toRotationMatrix(), t);
}

}  // namespace flexbench::lie
