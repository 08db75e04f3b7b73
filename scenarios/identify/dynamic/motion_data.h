// A moving arm's recorded log arranged for rollouts: the encoder rows, the servo commands and
// the IMU readings in the MuJoCo model's actuator order and sites, the segments the log is cut
// into (multiple shooting: each started from the recorded state), and the folds by time that
// hold segments out.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "estimators/camera/pinhole.h"
#include "sim/recorded_log.h"
#include "sim/simulation.h"

namespace flexbench::identify::dynamic {

struct MotionImu {
  std::string name;  // imu.csv's sensor
  std::string site;  // the MJCF site it is (the log's frame)
  int site_id = -1;
  std::vector<double> t;
  Eigen::MatrixXd gyro;   // rows x 3, rad/s, sensor frame
  Eigen::MatrixXd accel;  // rows x 3, m/s^2, specific force
};

// A camera of the log's tags: its optical frame in the model and its intrinsics.
struct MotionCamera {
  std::string name;
  sim::FrameRef frame;
  PinholeCamera intrinsics;
};

// A tag of the log: the model frame it is fixed to and its corners there (libapriltag's order).
struct MotionTag {
  int id = -1;
  sim::FrameRef frame;
  std::array<Vec3, 4> corners_m;
};

// One detection: a tag's four corners in one camera's image, libapriltag's pixel convention.
struct MotionTagRow {
  double t = 0.0;
  int camera = 0;  // MotionData::cameras
  int tag = 0;     // MotionData::tags
  std::array<Eigen::Vector2d, 4> uv;
};

struct Segment {
  int row_begin = 0;  // the encoder row the rollout starts from
  int row_end = 0;    // one past its last row
  int fold = 0;
};

struct MotionData {
  std::string log_dir;
  std::vector<std::string> joints;  // the model's actuated joints, actuator order
  std::vector<double> t;            // encoder rows
  Eigen::MatrixXd q;                // rows x joints, rad (m)
  Eigen::MatrixXd qd;               // rows x joints: a local line through nearby rows
  std::vector<double> command_t;
  Eigen::MatrixXd command;  // rows x joints: the position targets sent, or the torques
  bool torque = false;      // commands are the motors' torques (the log's type: torque)
  std::vector<MotionImu> imus;
  std::vector<MotionCamera> cameras;
  std::vector<MotionTag> tags;
  std::vector<MotionTagRow> tag_rows;  // in time order
  // The readings' noise: the log's (joints.std_rad, imu.gyro_std_rad_s, accel_std_m_s2,
  // tags.pixel_std_px), or, where it gives none, the spread of the declared model's residual
  // (SetUnknownNoise).
  double std_q = 0.0, std_gyro = 0.0, std_accel = 0.0, std_px = 0.0;
  bool noise_from_log[4] = {false, false, false, false};
  // The noise of stream s (rollout.h's Stream order: encoders, gyro, accel, tag pixels).
  double Noise(int s) const {
    return s == 0 ? std_q : s == 1 ? std_gyro : s == 2 ? std_accel : std_px;
  }
  double* MutableNoise(int s) {
    return s == 0 ? &std_q : s == 1 ? &std_gyro : s == 2 ? &std_accel : &std_px;
  }
  std::vector<Segment> segments;
  // Each segment's starting speeds (segments x joints): qd at its first row, until the final fit
  // fits them with the effects (DynamicProblem::JointFit).
  Eigen::MatrixXd start_qd;
  int folds = 1;
};

struct MotionOptions {
  double segment_s = 0.5;  // multiple shooting: each segment a rollout from the recorded state
  int folds = 3;           // contiguous blocks of segments held out in turn
  // The span each side of a segment's start whose encoder rows a line is fitted to for its speed.
  double velocity_window_s = 0.02;
  int velocity_degree = 1;  // of the polynomial
  bool use_imus = true;
  bool use_tags = true;  // the tags' corner pixels (tags.csv rows), when the log has them
};

// The log's encoders, commands and IMUs for `sim`'s model. InputError (one line, the file or
// key) for a log without commands, a joint or command column the model's actuated joints do not
// match, an IMU frame that is no site of the model, a camera or tag frame the model does not
// name, tags given as images only (detect them first: flexbench replay writes tags.csv), a
// command outside an actuator's range,
// segments shorter than the model's time step, or too few rows for two segments.
MotionData ReadMotionData(const sim::RecordedLog& log, const sim::Simulation& sim,
                          const MotionOptions& options);

}  // namespace flexbench::identify::dynamic
