// A recorded-log folder (sim/recorded_log.h) of jsk_arm written from its declared kinematics,
// not by the replay code: a smooth motion of every joint, the encoders (the two pitch joints'
// `pitch_offset` rad off: a calibration error the IMUs can see) at 100 Hz, two IMUs at 200 Hz
// whose gyro and accelerometer follow their links' orientations, the grasp point's truth at
// 100 Hz. For the replay and closed-loop tests and bench_replay.
#pragma once

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "estimators/camera/pinhole.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/lie/so3.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

namespace flexbench::testing {

// What the writer puts in the log.
struct JskLogOptions {
  double duration = 20.0;      // s
  double pitch_offset = 0.05;  // rad, both pitch encoders (a calibration error the IMUs see)
  // Added to the IMU times written (a clock running ahead).
  double imu_clock_s = 0.0;
  // The truth is the grasp point where the joints were that long before (a lag no static effect
  // explains: the arm trailing its encoders, as an elastic arm's inertia does).
  double truth_lag_s = 0.0;
  // The external camera (640 x 480, 45 deg vertical field of view) sees the gripper's 4 cm tag
  // at 10 Hz, its corners projected exactly, written where all four fall on the image
  // (tags.csv; the log's pixel_std_px 1).
  bool tags = false;
  // The camera is turned that much about its optical x axis from where the declared model has
  // it (a sagged mount).
  double camera_tilt_rad = 0.0;
  // A distance sensor reads the grasp point's height over a level plane at z = 0.9 m (known
  // within 1 mm / 0.5 deg) at 10 Hz, exactly, with a stated 0.5 mm (contacts.csv).
  bool contacts = false;
  // The arm rests for rest_s after every move_s of its motion (0: it never rests).
  double move_s = 0.0, rest_s = 0.0;
  // imu3's accelerometer reads this much more (m/s^2, its frame): a bias no effect of the
  // kinematics explains.
  Vec3 imu3_accel_bias = Vec3::Zero();
};

inline void WriteJskLog(const std::filesystem::path& dir, const JskLogOptions& o = {}) {
  const auto num = [](double v) {
    char b[40];
    std::snprintf(b, sizeof(b), "%.17g", v);
    return std::string(b);
  };
  const std::string declared_path =
      std::string(FLEXBENCH_SOURCE_DIR) + "/models/jsk_arm.declared.yaml";
  const sim::DeclaredModel declared = sim::LoadDeclaredModel(declared_path);
  const sim::MjModelPtr m = sim::LoadModel(declared.model_path);
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), declared);
  const int nq = chain.model.nq();
  const auto q_at = [&](double t) {
    if (o.move_s > 0.0) {  // the motion's own clock stands still while the arm rests
      const double cycle = o.move_s + o.rest_s;
      t = std::floor(t / cycle) * o.move_s + std::min(std::fmod(t, cycle), o.move_s);
    }
    Eigen::VectorXd q(nq);
    for (int k = 0; k < nq; ++k) q[k] = 0.2 * (k + 1) + 0.4 * std::sin((0.5 + 0.3 * k) * t);
    return q;
  };
  kinematics::PpoeData data(chain.model);
  const auto pose = [&](double t, kinematics::FrameId f) {
    kinematics::ForwardKinematics(chain.model, data, q_at(t));
    return data.T_base_frame[f];
  };
  std::filesystem::create_directories(dir);
  std::ofstream joints(dir / "joints.csv"), truth(dir / "truth.tum"), imu(dir / "imu.csv");
  joints << "t_s";
  for (const std::string& j : chain.q_joints) joints << "," << j << "_rad";
  joints << "\n";
  truth << "# t x y z qx qy qz qw\n";
  for (int i = 0; i * 0.01 <= o.duration + 1e-9; ++i) {
    const double t = i * 0.01;
    const Eigen::VectorXd q = q_at(t);
    joints << num(t);
    for (int k = 0; k < nq; ++k) {
      const bool pitch = chain.q_joints[k].find("pitch") != std::string::npos;
      joints << "," << num(q[k] + (pitch ? o.pitch_offset : 0.0));
    }
    joints << "\n";
    const lie::SE3 T = pose(t - o.truth_lag_s, chain.end_effector);
    const Quat r(T.rotation());
    truth << num(t) << " " << num(T.translation().x()) << " " << num(T.translation().y()) << " "
          << num(T.translation().z()) << " " << num(r.x()) << " " << num(r.y()) << " " << num(r.z())
          << " " << num(r.w()) << "\n";
  }
  imu << "t_s,sensor,gx_rad_s,gy_rad_s,gz_rad_s,ax_m_s2,ay_m_s2,az_m_s2\n";
  const kinematics::FrameId frames[2] = {chain.ObservedFrame("imu_link2"),
                                         chain.ObservedFrame("imu_link3")};
  for (int i = 1; i * 0.005 <= o.duration + 1e-9; ++i) {
    const double t = i * 0.005;
    for (int k = 0; k < 2; ++k) {
      const Mat3 R = pose(t, frames[k]).rotation();
      // The angular velocity at t (a central difference: a gyro's rate is of its instant).
      const double h = 1e-5;
      const Vec3 w = lie::SO3Log(pose(t - h, frames[k]).rotation().transpose() *
                                 pose(t + h, frames[k]).rotation()) /
                     (2.0 * h);
      const Vec3 a =
          R.transpose() * Vec3(0.0, 0.0, 9.81) + (k == 1 ? o.imu3_accel_bias : Vec3::Zero());
      imu << num(t + o.imu_clock_s) << ",imu" << (k + 2);
      for (int c = 0; c < 3; ++c) imu << "," << num(w[c]);
      for (int c = 0; c < 3; ++c) imu << "," << num(a[c]);
      imu << "\n";
    }
  }
  std::ofstream yaml(dir / "log.yaml");
  yaml << "robot: jsk_arm\ndeclared: " << declared_path
       << "\njoints: {file: joints.csv}\n"
          "imu: {file: imu.csv, sensors: {imu2: {frame: imu_link2}, imu3: {frame: imu_link3}}}\n"
          "truth: {file: truth.tum, frame: grasp_point}\n";
  if (o.contacts) {
    yaml << "contacts: {file: contacts.csv, planes: {table: {T_base_plane: [0, 0, 0.9, 1, 0, 0, "
            "0], std_m: 0.001, std_deg: 0.5}}, points: {tip: {frame: grasp_point}}}\n";
    std::ofstream csv(dir / "contacts.csv");
    csv << "t_s,point,plane,distance_m,std_m\n";
    for (int i = 0; i * 0.1 <= o.duration + 1e-9; ++i) {
      const double t = i * 0.1;
      csv << num(t) << ",tip,table,"
          << num(pose(t - o.truth_lag_s, chain.end_effector).translation().z() - 0.9)
          << ",0.0005\n";
    }
  }
  if (!o.tags) return;
  PinholeCamera cam;
  cam.width = 640;
  cam.height = 480;
  cam.fy = cam.fx = 240.0 / std::tan(22.5 * M_PI / 180.0);
  cam.cx = 320.0;
  cam.cy = 240.0;
  yaml
      << "cameras: {cam0: {frame: external_camera, fx: " << num(cam.fx) << ", fy: " << num(cam.fy)
      << ", cx: 320, cy: 240, width: 640, height: 480}}\n"
         "tags: {file: tags.csv, pixel_std_px: 1, ids: {20: {frame: tag_gripper, size_m: 0.04}}}\n";
  const Vec3 corners[4] = {Vec3(-0.02, 0.02, 0), Vec3(0.02, 0.02, 0), Vec3(0.02, -0.02, 0),
                           Vec3(-0.02, -0.02, 0)};
  const kinematics::FrameId camera = chain.ObservedFrame("external_camera");
  const kinematics::FrameId tag = chain.ObservedFrame("tag_gripper");
  std::ofstream csv(dir / "tags.csv");
  csv << "t_s,camera,tag_id,u0_px,v0_px,u1_px,v1_px,u2_px,v2_px,u3_px,v3_px\n";
  for (int i = 0; i * 0.1 <= o.duration + 1e-9; ++i) {
    const double t = i * 0.1;
    const lie::SE3 T_base_cam =
        pose(t - o.truth_lag_s, camera) *
        lie::SE3(Eigen::AngleAxisd(o.camera_tilt_rad, Vec3::UnitX()).toRotationMatrix(),
                 Vec3::Zero());
    const lie::SE3 T_cam_tag = T_base_cam.Inverse() * pose(t - o.truth_lag_s, tag);
    std::string row = num(t) + ",cam0,20";
    bool seen = true;
    for (const Vec3& c : corners) {
      Eigen::Vector2d uv;
      seen = seen && cam.Project(T_cam_tag * c, &uv) && cam.InImage(uv);
      row += "," + num(uv.x()) + "," + num(uv.y());
    }
    if (seen) csv << row << "\n";
  }
}

}  // namespace flexbench::testing
