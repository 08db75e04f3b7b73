// A recorded robot log: a folder with one file per sensor stream and a log.yaml that says what
// they are (docs/logs.md). As in the EuRoC / ASL layout, one CSV per
// stream with its time first; unlike it, one folder, times in seconds, and several IMUs in one
// file told apart by a `sensor` column.
//
//   log.yaml    robot: jsk_arm                         # a label
//               declared: ../models/jsk_arm.declared.yaml   # relative to the folder
//               joints: {file: joints.csv, clock_offset_s: 0,
//                        std_rad: 0}   # the readings' noise, each joint (m for a slide)
//               commands: {file: commands.csv, clock_offset_s: 0,  # optional
//                          type: position}   # or torque
//               imu: {file: imu.csv, clock_offset_s: 0,     # optional
//                     gyro_std_rad_s: 0, accel_std_m_s2: 0,   # the readings' noise (0: unknown)
//                     sensors: {imu2: {frame: imu_link2, initial_wxyz: [1, 0, 0, 0],
//                                      filter_beta: 0.05}}}   # Madgwick's gain, rad/s
//               truth: {file: truth.tum, frame: grasp_point}  # optional
//               estimate_in: head_camera  # optional: an observed frame the estimators work
//                                        # in; truth.tum and the planes are in it too
//               static_postures: false   # true: each joint row is a posture of its own,
//                                        # estimated afresh (a data set, not a motion)
//               postures: {file: postures.csv}   # optional: when postures of several rows begin
//               cameras:                                        # with tags
//                 cam0: {frame: external_camera, fx: 600, fy: 600, cx: 320, cy: 240,
//                        width: 640, height: 480}
//               tags: {file: tags.csv, clock_offset_s: 0, pixel_std_px: 1,
//                      measurement: corners,   # or centre: the estimators fuse the centre
//                      ids: {20: {frame: tag_gripper, corners_m: [[x, y, z], x 4]}}}
//               images: {dir: images, clock_offset_s: 0}    # instead of tags.file
//               orientations: {file: orientations.csv, clock_offset_s: 0}  # optional
//               positions: {file: positions.csv, clock_offset_s: 0}        # optional
//               contacts: {file: contacts.csv, clock_offset_s: 0,           # optional
//                 planes: {table: {T_base_plane: [x, y, z, qw, qx, qy, qz],
//                                  std_m: 0.001, std_deg: 0.5}},  # or std: [6] (m, rad)
//                 points: {tip: {frame: grasp_point, p_frame_m: [0, 0, 0]}}}
//   joints.csv  t_s, then one column per joint: <joint>_rad (<joint>_m for a slide)
//   commands.csv  t_s, then one column per actuated joint: <joint>_rad (_m): the position
//               servos' targets as sent; type torque: <joint>_Nm (_N), the motors' torques
//   imu.csv     t_s, sensor, gx_rad_s, gy_rad_s, gz_rad_s, ax_m_s2, ay_m_s2, az_m_s2 (sensor
//               frame; specific force, +g up at rest)
//   truth.tum   TUM lines "t x y z qx qy qz qw": the frame's pose in the base frame (m, s)
//   tags.csv    t_s, camera, tag_id, u0_px, v0_px, ..., u3_px, v3_px: a tag's corners as
//               libapriltag reports them (its order; pixel centres at +0.5: estimators/camera/
//               pinhole.h); optionally then uc_px, vc_px: the detector's centre (else the
//               corners' diagonals' crossing is the centre)
//   contacts.csv  t_s, point, plane, distance_m, std_m: the signed distance of a point on the
//               arm from a plane along its normal (the plane's z axis; 0 in contact) and the
//               sensor's standard deviation; the plane's pose is known within std_m / std_deg
//               (a 6x6 covariance of its tangent [rho; theta], diagonal: PPOE paper sec. V-B)
//   orientations.csv  t_s, frame, qw, qx, qy, qz: an observed frame's orientation in the base
//               frame as a sensor reads it (an orientation filter's output, a motion-capture
//               body), which the estimators fuse
//   positions.csv  t_s, frame, x_m, y_m, z_m, std_m: an observed frame's origin in the base
//               frame as a tracker reads it, with its noise per axis, fused by the estimators
//               (truth.tum, by contrast, only scores them)
//   postures.csv  t_s: the times at which a posture begins (the arm resting while several
//               readings come in); the estimators start afresh at the first step at or after
//               each
//   images/<camera>/<t_ns>.png   a camera's frames, named by their time in nanoseconds: the
//               scenario layer detects their tags (scenarios/runner/common/log_images.h)
//
// A camera's frame is an observed frame of the declared model that is its optical frame (x
// right, y down, z forward); its intrinsics are estimators/camera/pinhole.h's. A tag's
// corners_m are its four corners in its frame's coordinates, in libapriltag's order (the
// printed tag's (-1, +1), (+1, +1), (+1, -1), (-1, -1) with x right and y down); `size_m: s`
// instead says the frame is the tag's own, centred, x right and y down on the printed tag.
//
// A stream's clock_offset_s is added to its times. Within a stream (an IMU sensor's rows) times
// never go backwards; equal times are kept and counted as duplicates, steps longer than twice
// the median step as gaps. Bad input is one InputError naming the file, the line and the column.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <utility>
#include <vector>

#include "estimators/camera/pinhole.h"
#include "estimators/conventions.h"
#include "estimators/estimator.h"
#include "estimators/lie/se3.h"
#include "estimators/measurement.h"

namespace flexbench::sim {

// The largest stream file read.
constexpr std::uintmax_t kMaxLogStreamBytes = 512u << 20;

struct StreamStats {
  std::string file;  // empty: the stream is absent
  int rows = 0;
  int duplicates = 0;  // rows at the time of the row before (of the same sensor)
  int gaps = 0;        // steps longer than twice the median step
  double t_first = 0.0, t_last = 0.0, median_dt_s = 0.0;  // on the log's clock
  double clock_offset_s = 0.0;
};

struct LogImu {
  std::string name;   // imu.csv's `sensor`
  std::string frame;  // an observed frame of the declared model
  bool has_initial = false;
  Quat q_base_frame_initial = Quat::Identity();             // at its first reading, when known
  double filter_beta = estimators::ImuSetup{}.filter_beta;  // its Madgwick filter's gain
};

struct LogCamera {
  std::string name;   // tags.csv's `camera`
  std::string frame;  // its optical frame: an observed frame of the declared model
  PinholeCamera intrinsics;
};

struct LogTag {
  int id = -1;                    // tags.csv's `tag_id`
  std::string frame;              // the observed frame it is fixed to
  std::array<Vec3, 4> corners_m;  // in that frame, libapriltag's corner order
};

// One camera frame of images/: its time (with the stream's clock offset), camera and file.
struct LogImage {
  double t = 0.0;
  int camera = 0;
  std::string path;
};

// One tag seen by one camera: indices into RecordedLog::cameras and ::tags.
struct LogTagRow {
  double t = 0.0;
  int camera = 0;
  int tag = 0;
  std::array<Eigen::Vector2d, 4> uv;
  // The detector's (tags.csv's uc_px, vc_px; a detected image's), or the diagonals' crossing;
  // NaN when they do not cross.
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
};

// Where the diagonals of a tag's four corners cross (the centre of a planar square's image);
// false when they do not (degenerate corners).
bool DiagonalsCross(const std::array<Eigen::Vector2d, 4>& uv, Eigen::Vector2d* centre);

// A tag's centre in its frame: the mean of its four corners (a parallelogram's centre).
inline Vec3 TagCentre(const std::array<Vec3, 4>& c) { return 0.25 * (c[0] + c[1] + c[2] + c[3]); }

struct LogPlane {
  std::string name;                      // contacts.csv's `plane`
  Quat q_base_plane = Quat::Identity();  // as stated (written back as it is)
  lie::SE3 T_base_plane;                 // PlanePose of it and the stated position
  Vec6 std = Vec6::Zero();               // of its tangent [rho; theta] as stated (m, rad)
  Mat6 cov = Mat6::Zero();               // diag(std^2)
};

struct LogContactPoint {
  std::string name;   // contacts.csv's `point`
  std::string frame;  // an observed frame of the declared model
  Vec3 p_frame = Vec3::Zero();
};

// An orientation or a position reading of RecordedLog::sensed_frames[frame].
struct LogOrientationRow {
  double t = 0.0;
  int frame = 0;
  Quat q_base_frame = Quat::Identity();
};
struct LogPositionRow {
  double t = 0.0;
  int frame = 0;
  Vec3 p_base = Vec3::Zero();
  double std_m = 0.0;
};

// One contact reading: indices into RecordedLog::contact_points and ::planes.
struct LogContactRow {
  double t = 0.0;
  int point = 0;
  int plane = 0;
  double distance_m = 0.0;
  double std_m = 0.0;
};

struct RecordedLog {
  std::string dir;
  std::string robot;
  std::string declared_path;     // resolved against the folder
  std::string estimate_in;       // the frame estimates, truth and planes are in ("": the base)
  bool static_postures = false;  // each joint row a posture of its own (log.yaml's key)
  std::vector<double> posture_starts;  // postures.csv: when each posture begins, in time order
  // joints.csv: the joints in its column order, whether each is a slide (_m), its rows.
  std::vector<std::string> joints;
  std::vector<char> joint_is_slide;
  std::vector<double> joint_t;
  std::vector<double> joint_q;  // row-major, joints.size() a row
  double joint_std = 0.0;       // each reading's noise (joints.std_rad), rad or m
  // commands.csv (optional): the position servos' targets, one column per actuated joint (its
  // name and unit as in joints.csv), what a controller sent: dynamic identification drives its
  // rollouts with them.
  std::vector<std::string> command_joints;
  std::vector<char> command_is_slide;
  std::vector<double> command_t;
  std::vector<double> command_q;  // row-major, command_joints.size() a row
  // type: torque: the motors' torques at the joints (N m; N on a slide), each in force from its
  // time to the next row's, instead of position targets.
  bool command_torque = false;
  // imu.csv: the sensors of log.yaml and every reading (`imu` indexes imus), in file order.
  std::vector<LogImu> imus;
  std::vector<estimators::ImuReading> imu;
  double gyro_std = 0.0;   // each gyro reading's noise, rad/s (imu.gyro_std_rad_s; 0: unknown)
  double accel_std = 0.0;  // each accelerometer reading's, m/s^2 (imu.accel_std_m_s2)
  // truth.tum (optional).
  std::string truth_frame;
  std::vector<double> truth_t;
  std::vector<lie::SE3> truth;
  // cameras, tags and tags.csv (optional; every row's camera and tag are declared).
  std::vector<LogCamera> cameras;
  std::vector<LogTag> tags;
  double pixel_std_px = 1.0;      // each corner's, in u and in v
  bool pixel_std_stated = false;  // the log gives it (else the 1 px above is the format's default)
  bool tag_centres = false;       // tags.measurement: centre (the estimators fuse the centre pixel)
  bool has_centre_columns = false;  // tags.csv holds the detector's centres (uc_px, vc_px)
  std::vector<LogTagRow> tag_rows;
  // images/ (optional, instead of tags.csv): the frames in time order (cameras in their order at
  // equal times), undetected.
  std::vector<LogImage> images;
  // contacts.csv (optional).
  std::vector<LogPlane> planes;
  std::vector<LogContactPoint> contact_points;
  std::vector<LogContactRow> contacts;
  // orientations.csv and positions.csv (optional): the frames they read, in first-seen order.
  std::vector<std::string> sensed_frames;
  std::vector<LogOrientationRow> orientations;
  std::vector<LogPositionRow> positions;
  StreamStats joint_stats, command_stats, imu_stats, truth_stats, tag_stats, image_stats,
      contact_stats, orientation_stats, position_stats;

  const double* q(size_t row) const { return joint_q.data() + row * joints.size(); }
  const double* command(size_t row) const { return command_q.data() + row * command_joints.size(); }
};

// The pose a log's plane [x, y, z, qw, qx, qy, qz] stands for: the quaternion normalised, as
// the reader takes it (a kind that exports a plane builds its pose so, for the same bits).
inline lie::SE3 PlanePose(const Quat& q, const Vec3& p) {
  return lie::SE3(q.normalized().toRotationMatrix(), p);
}

// Index of the tag `id` in log.tags, -1 when the log has no such tag.
int TagIndex(const RecordedLog& log, int id);

// Reads DIR/log.yaml and the streams it names (InputError on bad input).
RecordedLog ReadRecordedLog(const std::string& dir);

// Writes `log` into the folder `dir` (which must not exist yet: InputError naming it) in the
// format ReadRecordedLog reads back into the same numbers (17 significant digits; clock offsets
// 0, the times as they are; the truth's rotation goes through its quaternion, so to the last
// digit): log.yaml with `declared:` as log.declared_path is written, then
// joints.csv, imu.csv when it has IMUs, truth.tum when it has truth, tags.csv when it has tag
// rows, orientations.csv, positions.csv and postures.csv when it has such rows. `files`: further
// files to
// write there first (name relative to the folder, bytes), e.g.
// the declared model or images/<camera>/<t_ns>.png (log.yaml then names `images:` when the log
// has `images` and no tag rows). The folder appears whole or not at all.
void WriteRecordedLog(const RecordedLog& log, const std::string& dir,
                      const std::vector<std::pair<std::string, std::string>>& files = {});

// The joints.csv column of each declared joint variable (`q_joints`; `slide[k]`: joint k is a
// slide, read in metres); every column must be one of them. InputError naming joints.csv's
// header, the column and `declared_file` otherwise.
std::vector<int> JointColumns(const RecordedLog& log, const std::vector<std::string>& q_joints,
                              const std::vector<char>& slide, const std::string& declared_file);

// The joint readings at time t in declared order (`column`: JointColumns), linear between the
// rows around it (a duplicated time: its last row). False (q untouched) outside the joints' span.
bool JointsAt(const RecordedLog& log, const std::vector<int>& column, double t, Eigen::VectorXd* q);

// The truth pose at time t: linear in position, slerp in rotation between the rows around it.
// False (T untouched) outside the truth's span or without truth.
bool TruthAt(const RecordedLog& log, double t, lie::SE3* T);

}  // namespace flexbench::sim
