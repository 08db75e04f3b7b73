#include "render/overlay.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace flexbench::render {
namespace {

// Sub-pixel drawing: OpenCV takes fixed-point coordinates with kShift fractional bits.
constexpr int kShift = 4;
constexpr double kScale = 1 << kShift;

cv::Mat Wrap(Image* image) {
  return cv::Mat(image->height, image->width, image->channels == 1 ? CV_8UC1 : CV_8UC3,
                 image->data.data());
}

cv::Scalar ToScalar(const Image& image, Color c) {
  if (image.channels == 1) return cv::Scalar(0.299 * c.r + 0.587 * c.g + 0.114 * c.b);
  return cv::Scalar(c.r, c.g, c.b);  // Image is RGB
}

// pinhole.h pixel (top-left pixel covers [0,1]^2) -> OpenCV (pixel centres at integers).
cv::Point FixedPoint(const Eigen::Vector2d& p) {
  const auto clampi = [](double v) {
    return static_cast<int>(std::lround(std::clamp(v, -1e6, 1e6)));
  };
  return cv::Point(clampi((p.x() - 0.5) * kScale), clampi((p.y() - 0.5) * kScale));
}

void Line(Image* image, const Eigen::Vector2d& a, const Eigen::Vector2d& b, Color c, int t) {
  cv::Mat m = Wrap(image);
  cv::line(m, FixedPoint(a), FixedPoint(b), ToScalar(*image, c), t, cv::LINE_AA, kShift);
}

}  // namespace

bool DrawFrameAxes(Image* image, const PinholeCamera& camera, const Eigen::Isometry3d& T_cam_frame,
                   double length_m, int thickness) {
  Eigen::Vector2d origin;
  if (!camera.Project(T_cam_frame.translation(), &origin)) return false;
  const Color colors[3] = {kRed, kGreen, kBlue};
  // Draw z first so x and y stay visible where they overlap it.
  for (int axis : {2, 1, 0}) {
    Eigen::Vector2d end;
    const Eigen::Vector3d tip = T_cam_frame * (length_m * Eigen::Vector3d::Unit(axis));
    if (!camera.Project(tip, &end)) continue;
    Line(image, origin, end, colors[axis], thickness);
  }
  return true;
}

Eigen::Matrix2d ProjectCovariance(const PinholeCamera& camera, const Eigen::Vector3d& p,
                                  const Eigen::Matrix3d& cov) {
  const double z = p.z();
  Eigen::Matrix<double, 2, 3> J;
  J << camera.fx / z, 0.0, -camera.fx * p.x() / (z * z), 0.0, camera.fy / z,
      -camera.fy * p.y() / (z * z);
  return J * cov * J.transpose();
}

double EllipseScale(double confidence) {
  const double p = std::clamp(confidence, 0.0, 1.0 - 1e-12);
  return std::sqrt(-2.0 * std::log(1.0 - p));
}

void DrawCovarianceEllipse(Image* image, const Eigen::Vector2d& center_px,
                           const Eigen::Matrix2d& cov_px, double confidence, Color color,
                           int thickness) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(0.5 * (cov_px + cov_px.transpose()));
  const Eigen::Vector2d values = eig.eigenvalues().cwiseMax(0.0);
  const Eigen::Matrix2d vectors = eig.eigenvectors();
  const double k = EllipseScale(confidence);
  // A polyline of 72 points: sub-pixel exact, and the same on every OpenCV version.
  std::vector<Eigen::Vector2d> points;
  constexpr int kPoints = 72;
  for (int i = 0; i < kPoints; ++i) {
    const double a = 2.0 * M_PI * i / kPoints;
    points.push_back(center_px + k * (vectors.col(0) * std::sqrt(values[0]) * std::cos(a) +
                                      vectors.col(1) * std::sqrt(values[1]) * std::sin(a)));
  }
  DrawPolyline(image, points, true, color, thickness);
}

bool DrawPositionCovariance(Image* image, const PinholeCamera& camera, const Eigen::Vector3d& p_cam,
                            const Eigen::Matrix3d& cov_cam, double confidence, Color color,
                            int thickness) {
  Eigen::Vector2d uv;
  if (!camera.Project(p_cam, &uv)) return false;
  DrawCovarianceEllipse(image, uv, ProjectCovariance(camera, p_cam, cov_cam), confidence, color,
                        thickness);
  return true;
}

void DrawPolyline(Image* image, const std::vector<Eigen::Vector2d>& points, bool closed,
                  Color color, int thickness) {
  if (points.size() < 2) return;
  std::vector<cv::Point> pts;
  pts.reserve(points.size());
  for (const auto& p : points) pts.push_back(FixedPoint(p));
  cv::Mat m = Wrap(image);
  cv::polylines(m, pts, closed, ToScalar(*image, color), thickness, cv::LINE_AA, kShift);
}

void DrawMarker(Image* image, const Eigen::Vector2d& p, Color color, int size_px, int thickness) {
  Line(image, p - Eigen::Vector2d(size_px, 0), p + Eigen::Vector2d(size_px, 0), color, thickness);
  Line(image, p - Eigen::Vector2d(0, size_px), p + Eigen::Vector2d(0, size_px), color, thickness);
}

void DrawText(Image* image, const std::string& text, const Eigen::Vector2d& origin, Color color,
              double scale) {
  cv::Mat m = Wrap(image);
  const cv::Point o(static_cast<int>(std::lround(origin.x() - 0.5)),
                    static_cast<int>(std::lround(origin.y() - 0.5)));
  cv::putText(m, text, o, cv::FONT_HERSHEY_SIMPLEX, scale, ToScalar(*image, Color{0, 0, 0}), 3,
              cv::LINE_AA);
  cv::putText(m, text, o, cv::FONT_HERSHEY_SIMPLEX, scale, ToScalar(*image, color), 1, cv::LINE_AA);
}

}  // namespace flexbench::render
