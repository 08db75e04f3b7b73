// Covariance of libapriltag's corner and centre estimates, derived from how libapriltag 3.3
// localises them (apriltag.c, refine_edges and quad_decode_task):
//
//  1. Each of the four edges of a quad of length L is re-fit from N = max(16, floor(L / 8))
//     sample points at arc-length fractions alpha_j = (j + 1) / (N + 1). At each, the edge's
//     normal offset is the mean of the offsets n in [-(decimate+1), decimate+1] (step 0.25),
//     weighted by the squared gray-level difference of the two pixels one pixel either side,
//     with both pixel coordinates truncated to integers.
//  2. The line is the total-least-squares fit through the N points; corner k is the
//     intersection of the lines of the edges (k-1, k) and (k, k+1).
//  3. det->c is H * (0, 0) for the homography through the four corners: the intersection of
//     the quad's diagonals.
//
// Error model of one sample's normal offset e_j (pixels), three independent parts:
//
//    e_j = sum_{m=1,2} sum_{axis=x,y} |n_axis| (a cos(2 pi m |t_axis| s_j) + b sin(...))
//          + eps_j + eta_j
//
//    a, b ~ N(0, sigma_lock_m^2)   sub-pixel phase error ("pixel locking") of harmonic m
//    eps_j ~ N(0, sigma_sample^2)  per-sample discretisation error
//    eta_j ~ N(0, kappa var_n / c^2)  pixel noise
//
//  - The integer truncation of the sample coordinates makes a sample's offset error a periodic
//    function of where the edge crosses the pixel grid (period 1 px on each axis). Along an
//    edge with unit direction t and normal n, the x phase advances by |t_x| cycles per pixel of
//    arc and moves the normal offset by |n_x| (same for y). The samples of an axis-aligned edge
//    therefore share their phase and their errors do not average out (measured: 2-4x the
//    corner error of a slanted edge), and a sample spacing that is a multiple of a period
//    aliases in the same way; a random-phase Fourier series truncated after the second
//    harmonic captures both.
//  - eta: to first order the weighted-mean offset moves by (noise / contrast) times a factor
//    kappa set by the gradient stencil. c is the edge's contrast measured in the image; var_n
//    is the pixel-noise variance after 8-bit clipping at the measured gray levels on either
//    side (a black border at level 0 keeps half of its noise).
//
// Each line's offset and angle errors follow from the least-squares fit (offset = mean of e_j,
// angle = sum s_j e_j / sum s_j^2, s_j centred), the four corners' 8x8 covariance from the
// first-order change of the intersection of two lines (adjacent corners share a line, so they
// are correlated), and the centre's from the Jacobian of the diagonals' intersection.
//
// Constants (CornerNoiseModel::Calibrated, by maximum likelihood of the corner errors):
// sigma_lock = 0.10 px, sigma_lock2 = 0.04 px and sigma_sample = 0.06 px once, on 600
// noise-free fast-mode frames of a near-frontal tag 0.8 m from the 640x480, 45 deg camera of
// models/tag_board.xml (about 58 px edges, random in-plane rotation); kappa = 2.4 once, at the
// same geometry with noise 8 gray levels and exposure gain 0.5. Validated at other distances,
// view angles, noise levels and exposures in tests/accuracy/tag_covariance/.
//
// Domain: fast render mode (the quality mode's multisample resolve erodes the black border by
// about 0.1 px, a bias this zero-mean model does not describe), tags with at least ~4 px per
// cell and views up to ~55 deg. Smaller or steeper tags have larger errors than predicted
// (tag_detection_sweep: corner NEES about 8x its expected value below 3 px per cell), and the
// centre's covariance is about 10-15% conservative.
#pragma once

#include <Eigen/Core>
#include <array>

#include "render/image.h"
#include "render/tag_detector.h"

namespace flexbench::render {

struct CornerNoiseModel {
  double sigma_lock_px = 0.0;    // sub-pixel phase error, first harmonic (std of a and b)
  double sigma_lock2_px = 0.0;   // second harmonic
  double sigma_sample_px = 0.0;  // independent per-sample discretisation error
  double kappa = 0.0;            // noise gain of the weighted-mean edge sampler

  // The calibrated constants (see the file comment).
  static CornerNoiseModel Calibrated();
};

// What the model used for one edge (edge k runs from corner k to corner k+1).
struct EdgeUncertainty {
  double length_px = 0.0;
  int samples = 0;             // N
  double contrast = 0.0;       // gray levels, outside minus inside (white minus black)
  double sample_std_px = 0.0;  // sqrt(sigma_sample^2 + kappa sigma_n^2 / c^2)
  double offset_std_px = 0.0;  // of the fitted line at its centroid
  double angle_std_rad = 0.0;
};

struct TagCovariance {
  // Corners in TagDetection order, stacked (u0, v0, u1, v1, u2, v2, u3, v3), pixels^2.
  Eigen::Matrix<double, 8, 8> corners = Eigen::Matrix<double, 8, 8>::Zero();
  Eigen::Matrix2d center = Eigen::Matrix2d::Zero();
  std::array<EdgeUncertainty, 4> edges;

  Eigen::Matrix2d Corner(int k) const { return corners.block<2, 2>(2 * k, 2 * k); }
};

// The covariance of `det`'s corners and centre. `gray` is the image the detector saw (gray),
// `pixel_noise_std` the standard deviation of its pixel noise in gray levels (0 for a clean
// render). Contrast is measured in `gray` along each edge.
TagCovariance EstimateTagCovariance(const Image& gray, const TagDetection& det,
                                    double pixel_noise_std,
                                    const CornerNoiseModel& model = CornerNoiseModel::Calibrated());

// The intersection of the quad's diagonals (libapriltag's det->c as a function of the corners)
// and its Jacobian with respect to the stacked corners.
Eigen::Vector2d DiagonalIntersection(const std::array<Eigen::Vector2d, 4>& corners,
                                     Eigen::Matrix<double, 2, 8>* jacobian = nullptr);

// Squared Mahalanobis distance e^T S^-1 e (S symmetric positive definite).
double Mahalanobis2(const Eigen::Vector2d& error, const Eigen::Matrix2d& covariance);

}  // namespace flexbench::render
