// Pins every statement of estimators/conventions.h (docs/design.md, "Conventions").
#include "estimators/conventions.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <random>
#include <sstream>
#include <string>

#include "estimators/camera/pinhole.h"
#include "estimators/format.h"
#include "estimators/lie/sampling.h"
#include "estimators/lie/se3.h"

namespace flexbench {
namespace {

using lie::SE3;

// --- xi = [rho; theta], translation first [PPOE eq. 2] -------------------------------------------

TEST(Conventions, TangentBlockOffsets) {
  EXPECT_EQ(kTransIdx, 0);
  EXPECT_EQ(kRotIdx, 3);
}

TEST(Conventions, ExpOfPureRhoTranslatesByRho) {
  const Vec3 rho(0.4, -1.5, 2.0);
  Vec6 xi = Vec6::Zero();
  xi.segment<3>(kTransIdx) = rho;
  const SE3 X = SE3::Exp(xi);
  EXPECT_TRUE(X.rotation().isIdentity(0.0));
  EXPECT_TRUE(X.translation().isApprox(rho, 0.0));
  // hat(xi) puts rho in the last column [PPOE eq. 2].
  EXPECT_TRUE((lie::SE3Hat(xi).topRightCorner<3, 1>().isApprox(rho, 0.0)));
}

TEST(Conventions, ExpOfPureThetaRotatesAboutThetaRightHanded) {
  Vec6 xi = Vec6::Zero();
  xi.segment<3>(kRotIdx) = Vec3(0.0, 0.0, M_PI / 2);
  const SE3 X = SE3::Exp(xi);
  EXPECT_TRUE(X.translation().isZero(0.0));
  // +90 deg about z maps x to y.
  EXPECT_LT((X.rotation() * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-15);
  const Vec3 axis = Vec3(1.0, -2.0, 0.5).normalized();
  xi.segment<3>(kRotIdx) = 0.7 * axis;
  EXPECT_LT((SE3::Exp(xi).rotation() - Eigen::AngleAxisd(0.7, axis).toRotationMatrix())
                .cwiseAbs()
                .maxCoeff(),
            1e-15);
}

// --- Right (local) perturbations and the adjoint [PPOE eqs. 5-8, 10]
// ------------------------------

TEST(Conventions, PerturbationsAreRightMultipliedAndLocal) {
  // X rotated +90 deg about z; a local step along x moves the frame along global y.
  const SE3 X(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()).toRotationMatrix(), Vec3(1, 2, 3));
  Vec6 xi = Vec6::Zero();
  xi[kTransIdx + 0] = 0.5;
  const SE3 Y = X.Plus(xi);
  EXPECT_TRUE(Y.IsApprox(X * SE3::Exp(xi), 0.0));
  EXPECT_LT((Y.translation() - Vec3(1.0, 2.5, 3.0)).norm(), 1e-15);
  // Minus is the inverse of Plus in the same (local) tangent space: Log(X^-1 Y).
  EXPECT_LT((Y.Minus(X) - xi).norm(), 1e-15);
}

TEST(Conventions, AdjointMapsLocalToGlobal) {
  std::mt19937_64 rng(1);
  const SE3 X = lie::RandomSE3(rng, 2.0);
  Vec6 xi_local;
  xi_local << 0.1, -0.2, 0.3, 0.05, 0.2, -0.1;
  // [PPOE eqs. 5-6]: X Exp(X_xi) = Exp(Ad_X X_xi) X.
  const SE3 local = X * SE3::Exp(xi_local);
  const SE3 global = SE3::Exp(X.Adjoint() * xi_local) * X;
  EXPECT_LT((local.Matrix() - global.Matrix()).cwiseAbs().maxCoeff(), 1e-14);
  // [PPOE eq. 7] layout: translation row block carries [t]x R in the upper-right corner.
  EXPECT_TRUE((X.Adjoint().topRightCorner<3, 3>().isApprox(
      lie::Skew(X.translation()) * X.rotation(), 1e-15)));
  EXPECT_TRUE((X.Adjoint().bottomLeftCorner<3, 3>().isZero(0.0)));
}

TEST(Conventions, PoseNamingTabMapsPointsFromBToA) {
  // T_a_b is the pose of b in a: p_a = T_a_b * p_b.
  const SE3 T_a_b(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()).toRotationMatrix(), Vec3(1, 0, 0));
  const Vec3 p_b(1.0, 0.0, 0.0);
  EXPECT_LT((T_a_b * p_b - Vec3(1.0, 1.0, 0.0)).norm(), 1e-15);
}

// --- Quaternion helpers ----------------------------------------------------------------------

TEST(Conventions, WxyzRoundTripAndOrder) {
  // +90 deg about x: w = cos 45, x = sin 45.
  const double c = std::cos(M_PI / 4);
  const double wxyz[4] = {c, c, 0.0, 0.0};
  const Quat q = QuatFromWxyz(wxyz);
  EXPECT_DOUBLE_EQ(q.w(), c);
  EXPECT_DOUBLE_EQ(q.x(), c);
  // Eigen's coeffs() are (x, y, z, w).
  EXPECT_DOUBLE_EQ(q.coeffs()[0], c);
  EXPECT_DOUBLE_EQ(q.coeffs()[3], c);
  EXPECT_LT((q.toRotationMatrix() * Vec3::UnitY() - Vec3::UnitZ()).norm(), 1e-15);
  double back[4];
  QuatToWxyz(q, back);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(back[i], wxyz[i]);
}

TEST(Conventions, XyzwPositiveRoundTrip) {
  std::mt19937_64 rng(2);
  for (int i = 0; i < 100; ++i) {
    const Quat q = lie::RandomSE3(rng).quaternion();
    const Quat q_neg(-q.w(), -q.x(), -q.y(), -q.z());
    for (const Quat& in : {q, q_neg}) {
      const Vec4 xyzw = QuatToXyzwPositive(in);
      EXPECT_GE(xyzw[3], 0.0);
      EXPECT_TRUE(
          xyzw.head<3>().isApprox(Vec3(in.x(), in.y(), in.z()) * (in.w() < 0.0 ? -1.0 : 1.0), 0.0));
      const Quat back = QuatFromXyzw(xyzw);
      EXPECT_LT((back.toRotationMatrix() - in.toRotationMatrix()).cwiseAbs().maxCoeff(), 1e-15);
      EXPECT_GE(back.w(), 0.0);
    }
  }
}

TEST(Conventions, RowMajorRotationAndMakeTransform) {
  const double xmat[9] = {0, -1, 0, 1, 0, 0, 0, 0, 1};  // +90 deg about z, row-major
  const Mat3 R = RotFromRowMajor(xmat);
  EXPECT_EQ(R(0, 1), -1.0);
  EXPECT_EQ(R(1, 0), 1.0);
  const Mat4 T = MakeTransform(R, Vec3(1, 2, 3));
  EXPECT_TRUE((T.topLeftCorner<3, 3>().isApprox(R, 0.0)));
  EXPECT_EQ(T(0, 3), 1.0);
  EXPECT_EQ(T(2, 3), 3.0);
  EXPECT_TRUE(T.row(3).isApprox(Eigen::RowVector4d(0, 0, 0, 1), 0.0));
}

// Degrees: one constant for every layer.
TEST(Conventions, DegreesToRadians) {
  EXPECT_DOUBLE_EQ(180.0 * kDeg, M_PI);
  EXPECT_DOUBLE_EQ(M_PI / 2 / kDeg, 90.0);
}

// Numbers as text (estimators/format.h): six significant digits as an ostream writes them by
// default, 17 that read back as the same double, and printf output of any length.
TEST(Conventions, NumbersAsText) {
  for (double v : {0.0, -0.0, 1.0, 1.0 / 3.0, -2.5e-7, 123456789.0, 1e300, M_PI,
                   std::numeric_limits<double>::infinity(), std::nan("")}) {
    std::ostringstream os;
    os << v;
    EXPECT_EQ(ShortNum(v), os.str());
    if (std::isfinite(v)) EXPECT_EQ(std::strtod(ExactNum(v).c_str(), nullptr), v);
  }
  EXPECT_EQ(ShortNum(1.0 / 3.0), "0.333333");
  EXPECT_EQ(Fmt("%s=%.2f", "x", 1.005), "x=1.00");
  const std::string long_text(1000, 'a');
  EXPECT_EQ(Fmt("%s|%d", long_text.c_str(), 7), long_text + "|7");
}

// --- WrapAngle: [-pi, pi) ----------------------------------------------------------------------

void ExpectWrapped(double a) {
  const double w = WrapAngle(a);
  EXPECT_GE(w, -M_PI) << "a = " << a;
  EXPECT_LT(w, M_PI) << "a = " << a;
  // Same angle: the difference is a multiple of 2 pi (up to the rounding of a).
  const double k = (a - w) / (2.0 * M_PI);
  EXPECT_NEAR(k, std::round(k), 1e-9 * std::max(1.0, std::abs(k))) << "a = " << a;
}

// Pixel coordinates (estimators/camera/pinhole.h): the top-left pixel covers [0, 1]^2, so the
// optical axis through (cx, cy) = (w/2, h/2) lands on the image's middle, and the sensor spans
// [0, w] x [0, h]: a point a quarter pixel inside either edge is on it, a quarter pixel outside
// is not (the pixel-centre convention would take the first column's left quarter as outside and
// a quarter pixel beyond the last as inside).
TEST(Conventions, PixelCoordinatesCoverTheSensorFromZeroToItsSize) {
  PinholeCamera cam;
  cam.fx = cam.fy = 500.0;
  cam.width = 640;
  cam.height = 480;
  cam.cx = cam.width / 2.0;
  cam.cy = cam.height / 2.0;
  Eigen::Vector2d uv;
  ASSERT_TRUE(cam.Project(Eigen::Vector3d(0.0, 0.0, 2.0), &uv));
  EXPECT_EQ(uv, Eigen::Vector2d(320.0, 240.0));
  EXPECT_TRUE(cam.InImage(Eigen::Vector2d(0.25, 0.25)));
  EXPECT_TRUE(cam.InImage(Eigen::Vector2d(639.75, 479.75)));
  EXPECT_TRUE(cam.InImage(Eigen::Vector2d(640.0, 480.0)));
  EXPECT_FALSE(cam.InImage(Eigen::Vector2d(-0.25, 100.0)));
  EXPECT_FALSE(cam.InImage(Eigen::Vector2d(100.0, -0.25)));
  EXPECT_FALSE(cam.InImage(Eigen::Vector2d(640.25, 100.0)));
  EXPECT_FALSE(cam.InImage(Eigen::Vector2d(100.0, 480.25)));
  // Behind the camera: no pixel.
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(0.0, 0.0, -1.0), &uv));
}

TEST(Conventions, WrapAngleRange) {
  EXPECT_EQ(WrapAngle(0.0), 0.0);
  EXPECT_EQ(WrapAngle(M_PI), -M_PI);   // pi itself is excluded
  EXPECT_EQ(WrapAngle(-M_PI), -M_PI);  // -pi is included
  EXPECT_NEAR(WrapAngle(3 * M_PI), -M_PI, 1e-15);
  EXPECT_NEAR(WrapAngle(-3 * M_PI), -M_PI, 1e-15);
  EXPECT_NEAR(WrapAngle(2 * M_PI), 0.0, 1e-15);
  EXPECT_NEAR(WrapAngle(-2 * M_PI), 0.0, 1e-15);
  EXPECT_NEAR(WrapAngle(0.5), 0.5, 1e-15);
  EXPECT_NEAR(WrapAngle(-0.5), -0.5, 1e-15);
  EXPECT_NEAR(WrapAngle(M_PI + 0.25), -M_PI + 0.25, 1e-15);
  EXPECT_NEAR(WrapAngle(-M_PI - 0.25), M_PI - 0.25, 1e-15);
  for (double a : {std::nextafter(M_PI, 0.0), std::nextafter(M_PI, 10.0), 1e10, -1e10, 7 * M_PI,
                   -1e-300, 1e-300, 123.456, -123.456}) {
    ExpectWrapped(a);
  }
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  for (int i = 0; i < 10000; ++i) ExpectWrapped(u(rng));
}

// For the double just below -pi, fmod(a + pi, 2 pi) = -ulp(pi), and -ulp + 2 pi rounds up to
// 2 pi: without its last line WrapAngle returns +pi, outside [-pi, pi).
TEST(Conventions, WrapAngleJustBelowMinusPi) { ExpectWrapped(std::nextafter(-M_PI, -10.0)); }

}  // namespace
}  // namespace flexbench
