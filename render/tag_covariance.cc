#include "render/tag_covariance.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace flexbench::render {
namespace {

// Gray level at (x, y) in the pixel convention of estimators/camera/pinhole.h (pixel (i, j)
// covers [i, i+1] x [j, j+1]), bilinear, clamped at the border.
double Sample(const Image& gray, double x, double y) {
  const double fx = std::clamp(x - 0.5, 0.0, gray.width - 1.0);
  const double fy = std::clamp(y - 0.5, 0.0, gray.height - 1.0);
  const int x0 = static_cast<int>(fx);
  const int y0 = static_cast<int>(fy);
  const int x1 = std::min(x0 + 1, gray.width - 1);
  const int y1 = std::min(y0 + 1, gray.height - 1);
  const double ax = fx - x0;
  const double ay = fy - y0;
  const auto at = [&](int xx, int yy) { return static_cast<double>(gray.Row(yy)[xx]); };
  return (1 - ay) * ((1 - ax) * at(x0, y0) + ax * at(x1, y0)) +
         ay * ((1 - ax) * at(x0, y1) + ax * at(x1, y1));
}

// Variance of clamp(mu + sigma z, 0, 255), z ~ N(0, 1): the noise that survives 8-bit clipping
// at a gray level mu. Midpoint quadrature over z in [-6, 6] (error far below 1e-6 relative).
double ClippedNoiseVariance(double mu, double sigma) {
  if (sigma <= 0.0) return 0.0;
  constexpr int kSteps = 240;
  constexpr double kLo = -6.0;
  constexpr double kDz = 12.0 / kSteps;
  double w_sum = 0.0;
  double m1 = 0.0;
  double m2 = 0.0;
  for (int i = 0; i < kSteps; ++i) {
    const double z = kLo + (i + 0.5) * kDz;
    const double w = std::exp(-0.5 * z * z);
    const double v = std::clamp(mu + sigma * z, 0.0, 255.0);
    w_sum += w;
    m1 += w * v;
    m2 += w * v * v;
  }
  m1 /= w_sum;
  m2 /= w_sum;
  return std::max(0.0, m2 - m1 * m1);
}

}  // namespace

CornerNoiseModel CornerNoiseModel::Calibrated() {
  CornerNoiseModel m;
  m.sigma_lock_px = 0.10;
  m.sigma_lock2_px = 0.04;
  m.sigma_sample_px = 0.06;
  m.kappa = 2.4;
  return m;
}

Eigen::Vector2d DiagonalIntersection(const std::array<Eigen::Vector2d, 4>& p,
                                     Eigen::Matrix<double, 2, 8>* jacobian) {
  const auto intersect = [](const std::array<Eigen::Vector2d, 4>& q) {
    const Eigen::Vector2d d1 = q[2] - q[0];
    const Eigen::Vector2d d2 = q[3] - q[1];
    const Eigen::Vector2d r = q[1] - q[0];
    const double cross = d1.x() * d2.y() - d1.y() * d2.x();
    const double t = (r.x() * d2.y() - r.y() * d2.x()) / cross;
    return Eigen::Vector2d(q[0] + t * d1);
  };
  const Eigen::Vector2d c = intersect(p);
  if (jacobian) {
    // Central differences: the map is a smooth rational function of the corners; a step of
    // 1e-5 px leaves a relative error near 1e-10.
    constexpr double kStep = 1e-5;
    for (int i = 0; i < 8; ++i) {
      std::array<Eigen::Vector2d, 4> plus = p;
      std::array<Eigen::Vector2d, 4> minus = p;
      plus[i / 2][i % 2] += kStep;
      minus[i / 2][i % 2] -= kStep;
      jacobian->col(i) = (intersect(plus) - intersect(minus)) / (2 * kStep);
    }
  }
  return c;
}

double Mahalanobis2(const Eigen::Vector2d& error, const Eigen::Matrix2d& covariance) {
  return error.dot(covariance.ldlt().solve(error));
}

namespace {

// One edge's least-squares line (offset at its centroid, angle) and what sized its covariance.
struct EdgeLine {
  Eigen::Vector2d normal;
  double length = 0.0;
  Eigen::Matrix2d cov;
  EdgeUncertainty uncertainty;
};

// Local contrast: mean absolute difference across the edge a -> b at the sample points, read
// about a third of a border cell (L / 8 for an 8-cell border; clamped) either side, where the
// profile has reached its plateaus but the data bits have not started; and the noise variance
// the sampler sees on the two sides after 8-bit clipping (a black border at gray level 0 keeps
// only half of its noise). s gets the samples' arc positions about the edge's middle.
void EdgeProfile(const Image& gray, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                 const Eigen::Vector2d& n, double L, int N, double pixel_noise_std,
                 Eigen::VectorXd* s, double* contrast, double* noise_var) {
  const double reach = std::clamp(L / 24.0, 1.0, 3.0);
  double inside_sum = 0.0;
  double outside_sum = 0.0;
  for (int j = 0; j < N; ++j) {
    const double alpha = (1.0 + j) / (N + 1.0);
    (*s)[j] = (alpha - 0.5) * L;
    const Eigen::Vector2d x = a + alpha * (b - a);
    outside_sum += Sample(gray, x.x() + reach * n.x(), x.y() + reach * n.y());
    inside_sum += Sample(gray, x.x() - reach * n.x(), x.y() - reach * n.y());
  }
  const double level_out = outside_sum / N;
  const double level_in = inside_sum / N;
  *contrast = std::max(std::abs(level_out - level_in), 1.0);
  *noise_var = 0.5 * (ClippedNoiseVariance(level_in, pixel_noise_std) +
                      ClippedNoiseVariance(level_out, pixel_noise_std));
}

// Sub-pixel phase error: a 2-D periodic function of where the sample crosses the pixel grid,
// expanded in harmonics m = 1, 2 of each axis. Along the edge the x phase advances by m |t_x|
// cycles per pixel of arc and the y phase by m |t_y|; a truncation error along an axis moves
// the normal offset by the normal's component on that axis, |n_x| or |n_y|. An axis-aligned
// edge thus has a locked (constant) phase on the axis across it, and a sample spacing that is a
// multiple of a period aliases in the same way. A maps the samples' errors to the line.
Eigen::Matrix2d PhaseLockCovariance(const Eigen::Vector2d& t, const Eigen::Vector2d& n,
                                    const Eigen::VectorXd& s,
                                    const Eigen::Matrix<double, 2, Eigen::Dynamic>& A,
                                    const CornerNoiseModel& model) {
  const double lock_std[2] = {model.sigma_lock_px, model.sigma_lock2_px};
  Eigen::Matrix2d lock_cov = Eigen::Matrix2d::Zero();
  for (int harmonic = 1; harmonic <= 2; ++harmonic) {
    for (int axis = 0; axis < 2; ++axis) {
      const double rate = harmonic * std::abs(t[axis]);
      const double weight = std::abs(n[axis]) * lock_std[harmonic - 1];
      const Eigen::VectorXd arg = 2 * M_PI * rate * s;
      const Eigen::Vector2d Ac = A * Eigen::VectorXd(arg.array().cos());
      const Eigen::Vector2d As = A * Eigen::VectorXd(arg.array().sin());
      lock_cov += weight * weight * (Ac * Ac.transpose() + As * As.transpose());
    }
  }
  return lock_cov;
}

// Edge a -> b: libapriltag's samples along it, their noise and phase lock, the fitted line's
// covariance.
EdgeLine FitEdge(const Image& gray, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                 double pixel_noise_std, const CornerNoiseModel& model) {
  EdgeLine out;
  const double L = (b - a).norm();
  const Eigen::Vector2d t = (b - a) / L;
  const Eigen::Vector2d n(-t.y(), t.x());
  out.normal = n;
  out.length = L;
  // apriltag.c: nsamples = imax(16, mag / 8) (the double is truncated to int).
  const int N = std::max(16, static_cast<int>(L / 8.0));
  Eigen::VectorXd s(N);
  double contrast = 0.0, noise_var = 0.0;
  EdgeProfile(gray, a, b, n, L, N, pixel_noise_std, &s, &contrast, &noise_var);
  Eigen::Matrix<double, 2, Eigen::Dynamic> A(2, N);
  A.row(0).setConstant(1.0 / N);
  A.row(1) = s.transpose() / s.squaredNorm();
  const Eigen::Matrix2d lock_cov = PhaseLockCovariance(t, n, s, A, model);
  const double var_sample = model.sigma_sample_px * model.sigma_sample_px +
                            model.kappa * noise_var / (contrast * contrast);
  // Least-squares line through the samples: offset = mean(e), angle = s.e / s.s.
  out.cov = lock_cov + var_sample * A * A.transpose();
  EdgeUncertainty& e = out.uncertainty;
  e.length_px = L;
  e.samples = N;
  e.contrast = contrast;
  e.sample_std_px = std::sqrt(var_sample);
  e.offset_std_px = std::sqrt(out.cov(0, 0));
  e.angle_std_rad = std::sqrt(out.cov(1, 1));
  return out;
}

// Corner k is the intersection of line k-1 (it is that line's end, s = +L/2) and line k (its
// start, s = -L/2). Moving line i by h_i along its normal moves the corner by dp with
// n_{k-1} . dp = h_{k-1}, n_k . dp = h_k; h_i(s) = d_i + s theta_i.
Eigen::Matrix<double, 8, 8> CornerCovariance(const std::array<EdgeLine, 4>& edges) {
  Eigen::Matrix<double, 8, 8> J = Eigen::Matrix<double, 8, 8>::Zero();  // d corners / d xi
  for (int k = 0; k < 4; ++k) {
    const int prev = (k + 3) % 4;
    Eigen::Matrix2d M;
    M.row(0) = edges[prev].normal.transpose();
    M.row(1) = edges[k].normal.transpose();
    const Eigen::Matrix2d Minv = M.inverse();
    // h_prev = [1, +L_prev/2] xi_prev; h_k = [1, -L_k/2] xi_k.
    J.block<2, 1>(2 * k, 2 * prev) = Minv.col(0);
    J.block<2, 1>(2 * k, 2 * prev + 1) = Minv.col(0) * (0.5 * edges[prev].length);
    J.block<2, 1>(2 * k, 2 * k) = Minv.col(1);
    J.block<2, 1>(2 * k, 2 * k + 1) = Minv.col(1) * (-0.5 * edges[k].length);
  }
  Eigen::Matrix<double, 8, 8> xi_cov = Eigen::Matrix<double, 8, 8>::Zero();
  for (int k = 0; k < 4; ++k) xi_cov.block<2, 2>(2 * k, 2 * k) = edges[k].cov;
  Eigen::Matrix<double, 8, 8> corners = J * xi_cov * J.transpose();
  corners = 0.5 * (corners + corners.transpose()).eval();
  return corners;
}

}  // namespace

TagCovariance EstimateTagCovariance(const Image& gray, const TagDetection& det,
                                    double pixel_noise_std, const CornerNoiseModel& model) {
  TagCovariance out;
  const auto& p = det.corners;
  // Per edge k (corner k -> corner k+1).
  std::array<EdgeLine, 4> edges;
  for (int k = 0; k < 4; ++k) {
    edges[k] = FitEdge(gray, p[k], p[(k + 1) % 4], pixel_noise_std, model);
    out.edges[k] = edges[k].uncertainty;
  }
  out.corners = CornerCovariance(edges);
  Eigen::Matrix<double, 2, 8> Jc;
  DiagonalIntersection(p, &Jc);
  out.center = Jc * out.corners * Jc.transpose();
  out.center = 0.5 * (out.center + out.center.transpose()).eval();
  return out;
}

}  // namespace flexbench::render
