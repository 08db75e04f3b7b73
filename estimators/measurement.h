// Typed, timestamped measurements: everything an estimator ever sees of the world besides its
// declared model. Frames are ids of the declared PPOE model (resolved once at set-up, so no
// strings travel per measurement); positions are in the model's base frame; pixels follow
// estimators/camera/pinhole.h. Fixed-capacity vectors keep measurements heap-free.
#pragma once

#include <Eigen/Core>
#include <array>
#include <variant>

#include "estimators/conventions.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/se3.h"

namespace flexbench::estimators {

using kinematics::FrameId;
using Vec2 = Eigen::Vector2d;
using Mat2 = Eigen::Matrix2d;

// Joint vectors up to kMaxJoints entries without heap allocation.
inline constexpr int kMaxJoints = 32;
using JointVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxJoints, 1>;

// Encoder readings of the declared actuated joints, in the declared model's q order.
struct JointReading {
  double t = 0.0;
  JointVector q;
  JointVector std;  // per-joint noise std (rad or m)
};

// A 6-axis IMU (no magnetometer) on declared frame setup.imus[imu].
struct ImuReading {
  double t = 0.0;
  int imu = 0;
  Vec3 gyro = Vec3::Zero();   // rad/s, sensor frame
  Vec3 accel = Vec3::Zero();  // m/s^2, specific force in the sensor frame (+g up at rest)
};

// An orientation of a declared frame in the base frame, e.g. from an IMU orientation filter.
struct OrientationReading {
  double t = 0.0;
  FrameId frame = -1;
  Quat q_base_frame = Quat::Identity();
};

// Pixel position of a point fixed to a frame, seen by camera setup.cameras[camera]
// [PPOE eq. 25].
struct PixelPoint {
  double t = 0.0;
  int camera = 0;
  FrameId frame = -1;
  Vec3 p_frame = Vec3::Zero();
  Vec2 uv = Vec2::Zero();
  Mat2 cov = Mat2::Identity();
};

// The four corners of an AprilTag fixed to a frame (libapriltag's corner order), with the
// 8x8 covariance of [u0 v0 u1 v1 u2 v2 u3 v3].
struct TagCorners {
  double t = 0.0;
  int camera = 0;
  int tag_id = -1;
  FrameId frame = -1;
  std::array<Vec3, 4> p_frame;
  std::array<Vec2, 4> uv;
  Eigen::Matrix<double, 8, 8> cov = Eigen::Matrix<double, 8, 8>::Identity();
};

// Contact of a point on a frame with a plane whose pose is uncertain (PPOE paper sec. V-B):
// the plane is T_base_plane * Exp(v), v ~ N(0, plane_cov), its normal is the plane's z axis,
// and the measured signed distance of the point along the normal is `distance` (0 in contact).
struct PlaneContact {
  double t = 0.0;
  FrameId frame = -1;
  Vec3 p_frame = Vec3::Zero();
  lie::SE3 T_base_plane;
  Mat6 plane_cov = Mat6::Zero();
  double distance = 0.0;
  double std = 1e-3;  // the distance sensor's own noise
};

// 3-D position of a point on a frame, in the base frame.
struct PositionReading {
  double t = 0.0;
  FrameId frame = -1;
  Vec3 p_frame = Vec3::Zero();
  Vec3 p_base = Vec3::Zero();
  Mat3 cov = Mat3::Identity();
};

// Full pose of a frame in the base frame, covariance in its local tangent space.
struct PoseReading {
  double t = 0.0;
  FrameId frame = -1;
  lie::SE3 T_base_frame;
  Mat6 cov = Mat6::Identity();
};

using Measurement = std::variant<JointReading, ImuReading, OrientationReading, PixelPoint,
                                 TagCorners, PlaneContact, PositionReading, PoseReading>;

}  // namespace flexbench::estimators
