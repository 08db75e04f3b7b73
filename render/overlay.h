// Evaluation overlays drawn on a frame: projected frame axes, projected 3-D position
// covariances as ellipses, polylines (e.g. tag corners), text labels. Inputs are plain Eigen
// and PinholeCamera values (no estimator or simulator types), so any scenario can draw its
// ground truth, forward kinematics and estimates. Drawing is OpenCV's, anti-aliased, with
// sub-pixel coordinates, deterministic: the same inputs give the same bytes.
//
// Pixel coordinates follow estimators/camera/pinhole.h (the top-left pixel covers [0, 1]^2);
// the conversion to OpenCV's integer pixel centres happens here.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "estimators/camera/pinhole.h"
#include "render/image.h"

namespace flexbench::render {

struct Color {
  std::uint8_t r = 0;
  std::uint8_t g = 0;
  std::uint8_t b = 0;
};

inline constexpr Color kRed{230, 40, 40};
inline constexpr Color kGreen{40, 200, 60};
inline constexpr Color kBlue{50, 90, 240};
inline constexpr Color kWhite{255, 255, 255};
inline constexpr Color kYellow{250, 210, 40};
inline constexpr Color kMagenta{220, 60, 220};
inline constexpr Color kCyan{40, 210, 220};

// Draws the x (red), y (green) and z (blue) axes of frame T_cam_frame (a pose in the camera's
// optical frame), each `length_m` long. Axes whose end points are behind the camera are
// skipped. Returns false when the origin is behind the camera (nothing drawn).
bool DrawFrameAxes(Image* image, const PinholeCamera& camera, const Eigen::Isometry3d& T_cam_frame,
                   double length_m, int thickness = 2);

// The 2-D covariance of the projection of a point p_cam with 3-D covariance cov_cam (both in
// the optical frame), to first order: J cov J^T with J = d(pinhole)/dp [PPOE eq. 25]:
//   J = [fx / z, 0, -fx x / z^2; 0, fy / z, -fy y / z^2].
Eigen::Matrix2d ProjectCovariance(const PinholeCamera& camera, const Eigen::Vector3d& p_cam,
                                  const Eigen::Matrix3d& cov_cam);

// Scale of the 2-D confidence ellipse that holds `confidence` of a Gaussian's mass:
// sqrt(chi2_2^-1(confidence)) = sqrt(-2 ln(1 - confidence)).
double EllipseScale(double confidence);

// Draws the `confidence` ellipse (e.g. 0.95) of a 2-D covariance centred at `center_px`.
void DrawCovarianceEllipse(Image* image, const Eigen::Vector2d& center_px,
                           const Eigen::Matrix2d& cov_px, double confidence, Color color,
                           int thickness = 1);

// Projects p_cam and cov_cam and draws the ellipse; false when p_cam is behind the camera.
bool DrawPositionCovariance(Image* image, const PinholeCamera& camera, const Eigen::Vector3d& p_cam,
                            const Eigen::Matrix3d& cov_cam, double confidence, Color color,
                            int thickness = 1);

void DrawPolyline(Image* image, const std::vector<Eigen::Vector2d>& points_px, bool closed,
                  Color color, int thickness = 1);

// A small cross ("+") of half-size `size_px`.
void DrawMarker(Image* image, const Eigen::Vector2d& p_px, Color color, int size_px = 4,
                int thickness = 1);

// Text with its baseline's left end at `origin_px`, drawn over a dark outline so it reads on
// any background.
void DrawText(Image* image, const std::string& text, const Eigen::Vector2d& origin_px, Color color,
              double scale = 0.45);

}  // namespace flexbench::render
