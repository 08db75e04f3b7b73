// The recorded-log folder (sim/recorded_log.h): streams read with their clocks' offsets, counts of
// duplicated times and gaps, the truth interpolated between its rows; every bad input one
// InputError naming the file, the line and the column.
#include "sim/recorded_log.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <string>

#include "estimators/error.h"
#include "tests/common/test_util.h"

namespace flexbench::sim {
namespace {

struct Files {
  std::string log_yaml =
      "robot: jsk_arm\n"
      "declared: models/arm.declared.yaml\n"
      "joints: {file: joints.csv, clock_offset_s: 0.5}\n"
      "imu:\n"
      "  file: imu.csv\n"
      "  sensors:\n"
      "    imu2: {frame: imu_link2, initial_wxyz: [2, 0, 0, 0]}\n"
      "    imu3: {frame: imu_link3}\n"
      "truth: {file: truth.tum, frame: grasp_point}\n";
  std::string joints =
      "t_s,shoulder_rad,elbow_rad,slide_m\n"
      "# a comment\n"
      "0.00,0.1,0.2,0.01\n"
      "0.01,0.1,0.2,0.01\n"
      "0.01,0.1,0.2,0.01\n"  // a duplicated time
      "0.02,0.1,0.25,0.01\n"
      "0.05,0.1,0.3,0.01\n";  // a gap
  std::string imu =
      "t_s,sensor,gx_rad_s,gy_rad_s,gz_rad_s,ax_m_s2,ay_m_s2,az_m_s2\n"
      "0.000,imu2,0.1,0,0,0,0,9.81\n"
      "0.001,imu3,0,0.2,0,0,0,9.81\n"
      "0.005,imu2,0.1,0,0,0,0,9.81\n"
      "0.004,imu3,0,0.2,0,0,0,9.81\n";  // each sensor's own times only go forward
  std::string truth =
      "# t x y z qx qy qz qw\n"
      "1.0 0 0 0 0 0 0 1\n"
      "2.0 1 2 3 0 0 0.70710678118654746 0.70710678118654757\n";

  void Write(const std::filesystem::path& dir) const {
    std::ofstream(dir / "log.yaml") << log_yaml;
    std::ofstream(dir / "joints.csv") << joints;
    std::ofstream(dir / "imu.csv") << imu;
    std::ofstream(dir / "truth.tum") << truth;
  }
};

TEST(RecordedLog, ReadsTheStreamsWithTheirClocksAndCounts) {
  testing::TempDir dir;
  Files().Write(dir.path());
  const RecordedLog log = ReadRecordedLog(dir.path().string());
  EXPECT_EQ(log.robot, "jsk_arm");
  EXPECT_EQ(log.declared_path, (dir.path() / "models/arm.declared.yaml").string());
  ASSERT_EQ(log.joints, (std::vector<std::string>{"shoulder", "elbow", "slide"}));
  EXPECT_EQ(log.joint_is_slide, (std::vector<char>{0, 0, 1}));
  ASSERT_EQ(log.joint_t.size(), 5u);
  EXPECT_DOUBLE_EQ(log.joint_t[0], 0.5);  // the clock offset
  EXPECT_DOUBLE_EQ(log.q(3)[1], 0.25);
  EXPECT_EQ(log.joint_stats.rows, 5);
  EXPECT_EQ(log.joint_stats.duplicates, 1);
  EXPECT_EQ(log.joint_stats.gaps, 1);
  EXPECT_NEAR(log.joint_stats.median_dt_s, 0.01, 1e-12);
  ASSERT_EQ(log.imus.size(), 2u);
  EXPECT_TRUE(log.imus[0].has_initial);
  EXPECT_DOUBLE_EQ(log.imus[0].q_base_frame_initial.w(), 2.0);  // as given: the filter normalises
  EXPECT_FALSE(log.imus[1].has_initial);
  EXPECT_EQ(log.imus[1].frame, "imu_link3");
  ASSERT_EQ(log.imu.size(), 4u);
  EXPECT_EQ(log.imu[1].imu, 1);
  EXPECT_DOUBLE_EQ(log.imu[1].gyro.y(), 0.2);
  EXPECT_DOUBLE_EQ(log.imu[3].t, 0.004);
  EXPECT_EQ(log.imu_stats.duplicates, 0);
  lie::SE3 T;
  ASSERT_TRUE(TruthAt(log, 1.5, &T));
  EXPECT_LT((T.translation() - Vec3(0.5, 1.0, 1.5)).norm(), 1e-12);
  EXPECT_NEAR(Quat(T.rotation()).angularDistance(Quat(Eigen::AngleAxisd(M_PI / 4, Vec3::UnitZ()))),
              0.0, 1e-12);
  EXPECT_FALSE(TruthAt(log, 2.5, &T));
  EXPECT_FALSE(TruthAt(log, 0.5, &T));
}

struct BadCase {
  const char* name;
  std::string Files::*file;
  std::string content;
  std::string expect;  // in the message
};

TEST(RecordedLog, BadInputIsOneLineNamingTheFileLineAndColumn) {
  const std::vector<BadCase> cases = {
      {"time column", &Files::joints, "time,shoulder_rad\n0,1\n",
       "joints.csv:1: column 1 is 'time'"},
      {"unit", &Files::joints, "t_s,shoulder\n0,1\n", "joints.csv:1: column 'shoulder': expected"},
      {"twice", &Files::joints, "t_s,a_rad,a_rad\n0,1,1\n", "joints.csv:1: joint 'a' has two"},
      {"not a number", &Files::joints, "t_s,a_rad\n0,abc\n", "joints.csv:2: column 'a_rad': 'abc'"},
      {"nan", &Files::joints, "t_s,a_rad\n0,nan\n", "joints.csv:2: column 'a_rad' is nan"},
      {"columns", &Files::joints, "t_s,a_rad\n0,1,2\n", "joints.csv:2: 3 columns"},
      {"backwards", &Files::joints, "t_s,a_rad\n0.2,1\n0.1,1\n",
       "joints.csv:3: column 't_s': 0.1 is before the previous row's 0.2"},
      {"no rows", &Files::joints, "t_s,a_rad\n", "joints.csv: no data rows"},
      {"imu header", &Files::imu, "t_s,sensor,gx,gy,gz,ax,ay,az\n",
       "imu.csv:1: the header must be"},
      {"sensor", &Files::imu,
       "t_s,sensor,gx_rad_s,gy_rad_s,gz_rad_s,ax_m_s2,ay_m_s2,az_m_s2\n0,imu9,0,0,0,0,0,9.8\n",
       "imu.csv:2: column 'sensor': 'imu9' is not a sensor of the log's imu.sensors (imu2, imu3)"},
      {"imu backwards", &Files::imu,
       "t_s,sensor,gx_rad_s,gy_rad_s,gz_rad_s,ax_m_s2,ay_m_s2,az_m_s2\n1,imu2,0,0,0,0,0,9.8\n"
       "0.5,imu2,0,0,0,0,0,9.8\n",
       "imu.csv:3: column 't_s': 0.5 is before"},
      {"imu inf", &Files::imu,
       "t_s,sensor,gx_rad_s,gy_rad_s,gz_rad_s,ax_m_s2,ay_m_s2,az_m_s2\n1,imu2,inf,0,0,0,0,9.8\n",
       "imu.csv:2: column 'gx_rad_s' is inf"},
      {"truth values", &Files::truth, "1 2 3\n", "truth.tum:1: 3 values, expected 8"},
      {"truth quaternion", &Files::truth, "1 0 0 0 0 0 0 0\n",
       "truth.tum:1: the quaternion is zero"},
      {"unknown key", &Files::log_yaml, "declared: a.yaml\njoints: {file: joints.csv}\nspeed: 3\n",
       "log.yaml:3: unknown key 'speed'"},
      {"initial", &Files::log_yaml,
       "declared: a.yaml\njoints: {file: joints.csv}\nimu: {file: imu.csv, sensors: {imu2: "
       "{frame: f, initial_wxyz: [0, 0, 0, 0]}}}\n",
       "expected [w, x, y, z], finite and not zero"},
  };
  for (const BadCase& c : cases) {
    testing::TempDir dir;
    Files f;
    f.*(c.file) = c.content;
    f.Write(dir.path());
    try {
      ReadRecordedLog(dir.path().string());
      ADD_FAILURE() << c.name << ": no error";
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(c.expect), std::string::npos) << c.name << ": " << msg;
      EXPECT_EQ(msg.find('\n'), std::string::npos) << c.name << ": one line";
    }
  }
}

// Cameras, tags and their detections: written, they read back as the same numbers, with the
// camera and tag of each row, and tags given by size get libapriltag's corner order.
TEST(RecordedLog, TagDetectionsRoundTrip) {
  testing::TempDir dir;
  Files f;
  f.log_yaml +=
      "cameras: {cam0: {frame: external_camera, fx: 600.5, fy: 601, cx: 320, cy: 240.25, "
      "width: 640, height: 480}}\n"
      "tags: {file: tags.csv, clock_offset_s: 0.5, pixel_std_px: 0.7,\n"
      "       ids: {20: {frame: tag_gripper, size_m: 0.04}, 3: {frame: tag_base, corners_m: "
      "[[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0], [0, 0.1, 0.01]]}}}\n";
  f.Write(dir.path());
  std::ofstream(dir.path() / "tags.csv")
      << "t_s,camera,tag_id,u0_px,v0_px,u1_px,v1_px,u2_px,v2_px,u3_px,v3_px\n"
         "0.1,cam0,20,1,2,3,4,5,6,7,8\n"
         "0.1,cam0,3,10.5,20,30,40,50,60,70,80.25\n"
         "0.2,cam0,20,1,2,3,4,5,6,7,8\n";
  const RecordedLog log = ReadRecordedLog(dir.path().string());
  ASSERT_EQ(log.cameras.size(), 1u);
  EXPECT_DOUBLE_EQ(log.cameras[0].intrinsics.fx, 600.5);
  ASSERT_EQ(log.tags.size(), 2u);
  const LogTag& t20 = log.tags[0].id == 20 ? log.tags[0] : log.tags[1];
  EXPECT_EQ(t20.corners_m[0], Vec3(-0.02, 0.02, 0.0));
  EXPECT_EQ(t20.corners_m[2], Vec3(0.02, -0.02, 0.0));
  EXPECT_DOUBLE_EQ(log.pixel_std_px, 0.7);
  ASSERT_EQ(log.tag_rows.size(), 3u);
  EXPECT_DOUBLE_EQ(log.tag_rows[1].t, 0.6);  // the clock offset
  EXPECT_EQ(log.tags[log.tag_rows[1].tag].id, 3);
  EXPECT_EQ(log.tag_rows[1].uv[3], Eigen::Vector2d(70, 80.25));
  EXPECT_EQ(log.tag_stats.rows, 3);
  EXPECT_EQ(log.tag_stats.duplicates, 0);  // two tags at one time: two streams
  const std::string again = (dir.path() / "again").string();
  WriteRecordedLog(log, again);
  const RecordedLog back = ReadRecordedLog(again);
  ASSERT_EQ(back.tag_rows.size(), 3u);
  for (size_t r = 0; r < 3; ++r) {
    EXPECT_EQ(back.tag_rows[r].t, log.tag_rows[r].t);
    EXPECT_EQ(back.tag_rows[r].camera, log.tag_rows[r].camera);
    EXPECT_EQ(back.tags[back.tag_rows[r].tag].id, log.tags[log.tag_rows[r].tag].id);
    for (int k = 0; k < 4; ++k) EXPECT_EQ(back.tag_rows[r].uv[k], log.tag_rows[r].uv[k]);
  }
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(back.tags[i].frame, log.tags[i].frame);
    for (int k = 0; k < 4; ++k) EXPECT_EQ(back.tags[i].corners_m[k], log.tags[i].corners_m[k]);
  }
  EXPECT_EQ(back.cameras[0].intrinsics.cy, 240.25);
  EXPECT_EQ(back.pixel_std_px, 0.7);
  // A camera that saw no tag: its tags.csv is a header, written and read back.
  RecordedLog unseen = log;
  unseen.tag_rows.clear();
  const std::string none = (dir.path() / "none").string();
  WriteRecordedLog(unseen, none);
  EXPECT_TRUE(ReadRecordedLog(none).tag_rows.empty());
  EXPECT_EQ(ReadRecordedLog(none).tags.size(), 2u);
  // One id twice (20 and 020) is refused.
  f.log_yaml.replace(f.log_yaml.find("3: {frame: tag_base"), 19, "020: {frame: tag_base");
  f.Write(dir.path());
  try {
    ReadRecordedLog(dir.path().string());
    ADD_FAILURE() << "a tag id read twice";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("tag 20 twice"), std::string::npos) << e.what();
  }
}

// The detector's centres (uc_px, vc_px), what the estimators fuse (tags.measurement) and the
// encoders' noise (joints.std_rad) are read, written and read back; without the centre columns
// the centre is where the corners' diagonals cross; a bad measurement is named.
TEST(RecordedLog, TagCentresAndJointNoiseRoundTrip) {
  testing::TempDir dir;
  Files f;
  f.log_yaml.replace(f.log_yaml.find("joints: {file: joints.csv"), 25,
                     "joints: {file: joints.csv, std_rad: 0.00125");
  f.log_yaml +=
      "cameras: {cam0: {frame: external_camera, fx: 600, fy: 600, cx: 320, cy: 240, width: 640, "
      "height: 480}}\n"
      "tags: {file: tags.csv, measurement: centre, ids: {20: {frame: tag_gripper, size_m: "
      "0.04}}}\n";
  f.Write(dir.path());
  std::ofstream(dir.path() / "tags.csv")
      << "t_s,camera,tag_id,u0_px,v0_px,u1_px,v1_px,u2_px,v2_px,u3_px,v3_px,uc_px,vc_px\n"
         "0.1,cam0,20,0,0,10,0,10,10,0,10,5.25,4.75\n";
  const RecordedLog log = ReadRecordedLog(dir.path().string());
  EXPECT_EQ(log.joint_std, 0.00125);
  EXPECT_TRUE(log.tag_centres);
  EXPECT_TRUE(log.has_centre_columns);
  ASSERT_EQ(log.tag_rows.size(), 1u);
  EXPECT_EQ(log.tag_rows[0].centre, Eigen::Vector2d(5.25, 4.75));
  const std::string again = (dir.path() / "again").string();
  WriteRecordedLog(log, again);
  const RecordedLog back = ReadRecordedLog(again);
  EXPECT_EQ(back.joint_std, 0.00125);
  EXPECT_TRUE(back.tag_centres && back.has_centre_columns);
  EXPECT_EQ(back.tag_rows[0].centre, Eigen::Vector2d(5.25, 4.75));
  // Without the columns: the diagonals' crossing.
  std::ofstream(dir.path() / "tags.csv")
      << "t_s,camera,tag_id,u0_px,v0_px,u1_px,v1_px,u2_px,v2_px,u3_px,v3_px\n"
         "0.1,cam0,20,0,0,10,0,10,10,0,10\n";
  const RecordedLog crossing = ReadRecordedLog(dir.path().string());
  EXPECT_FALSE(crossing.has_centre_columns);
  EXPECT_EQ(crossing.tag_rows[0].centre, Eigen::Vector2d(5, 5));
  f.log_yaml.replace(f.log_yaml.find("measurement: centre"), 19, "measurement: middle");
  f.Write(dir.path());
  try {
    ReadRecordedLog(dir.path().string());
    ADD_FAILURE() << "an unknown tag measurement read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected corners or centre"), std::string::npos)
        << e.what();
  }
}

// Orientation and position readings of observed frames and posture starts: read (with the
// stream's clock offset), written and read back; a quaternion off unit length and a std of 0
// are named.
TEST(RecordedLog, OrientationsAndPositionsRoundTrip) {
  testing::TempDir dir;
  Files f;
  f.log_yaml +=
      "orientations: {file: orientations.csv, clock_offset_s: 0.25}\n"
      "positions: {file: positions.csv}\npostures: {file: postures.csv}\n";
  f.Write(dir.path());
  std::ofstream(dir.path() / "orientations.csv")
      << "t_s,frame,qw,qx,qy,qz\n0.1,imu_link2,1,0,0,0\n0.1,imu_link3,0.6,0.8,0,0\n"
         "0.2,imu_link2,0,0,1,0\n";
  std::ofstream(dir.path() / "positions.csv")
      << "t_s,frame,x_m,y_m,z_m,std_m\n0.1,grasp_point,0.5,-0.25,1.125,0.001\n";
  std::ofstream(dir.path() / "postures.csv") << "t_s\n0\n0.2\n";
  const RecordedLog log = ReadRecordedLog(dir.path().string());
  EXPECT_EQ(log.posture_starts, (std::vector<double>{0.0, 0.2}));
  ASSERT_EQ(log.orientations.size(), 3u);
  ASSERT_EQ(log.positions.size(), 1u);
  EXPECT_EQ(log.sensed_frames, (std::vector<std::string>{"imu_link2", "imu_link3", "grasp_point"}));
  EXPECT_DOUBLE_EQ(log.orientations[1].t, 0.35);
  EXPECT_EQ(log.orientations[1].frame, 1);
  EXPECT_EQ(log.orientations[1].q_base_frame.x(), 0.8);
  EXPECT_EQ(log.positions[0].frame, 2);
  EXPECT_EQ(log.positions[0].p_base, Vec3(0.5, -0.25, 1.125));
  EXPECT_EQ(log.orientation_stats.rows, 3);
  const std::string again = (dir.path() / "again").string();
  WriteRecordedLog(log, again);
  const RecordedLog back = ReadRecordedLog(again);
  ASSERT_EQ(back.orientations.size(), 3u);
  for (size_t r = 0; r < 3; ++r) {
    EXPECT_EQ(back.orientations[r].t, log.orientations[r].t);
    EXPECT_EQ(back.orientations[r].q_base_frame.coeffs(),
              log.orientations[r].q_base_frame.coeffs());
  }
  EXPECT_EQ(back.positions[0].p_base, log.positions[0].p_base);
  EXPECT_EQ(back.positions[0].std_m, 0.001);
  EXPECT_EQ(back.posture_starts, log.posture_starts);
  const auto error = [&](const std::string& file, const std::string& text) {
    std::ofstream(dir.path() / file) << text;
    try {
      ReadRecordedLog(dir.path().string());
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error("orientations.csv", "t_s,frame,qw,qx,qy,qz\n0.1,imu_link2,1,0.1,0,0\n")
                .find("orientations.csv:2: (qw, qx, qy, qz) is not of unit length"),
            std::string::npos);
  std::ofstream(dir.path() / "orientations.csv") << "t_s,frame,qw,qx,qy,qz\n";
  EXPECT_NE(error("positions.csv", "t_s,frame,x_m,y_m,z_m,std_m\n0.1,grasp_point,0,0,1,0\n")
                .find("positions.csv:2: column 'std_m' must be > 0"),
            std::string::npos);
}

// Contact readings: planes (pose, its standard deviations as a diagonal covariance), points on
// frames, and contacts.csv read with the stream's clock offset, then written and read back.
TEST(RecordedLog, ContactsRoundTrip) {
  testing::TempDir dir;
  Files f;
  f.log_yaml +=
      "contacts: {file: contacts.csv, clock_offset_s: 0.5, planes: {table: {T_base_plane: [0, "
      "0, 0.9, 1, 0, 0, 0], std_m: 0.002, std_deg: 0.5}}, points: {tip: {frame: grasp_point, "
      "p_frame_m: [0, 0, 0.01]}}}\n";
  f.Write(dir.path());
  std::ofstream(dir.path() / "contacts.csv")
      << "t_s,point,plane,distance_m,std_m\n0.1,tip,table,0.003,0.0005\n0.2,tip,table,-0.001,"
         "0.0005\n";
  const RecordedLog log = ReadRecordedLog(dir.path().string());
  ASSERT_EQ(log.contacts.size(), 2u);
  EXPECT_DOUBLE_EQ(log.contacts[0].t, 0.6);
  EXPECT_DOUBLE_EQ(log.contacts[1].distance_m, -0.001);
  EXPECT_DOUBLE_EQ(log.planes[0].cov(0, 0), 0.002 * 0.002);
  EXPECT_NEAR(log.planes[0].cov(5, 5), std::pow(0.5 * M_PI / 180.0, 2), 1e-18);
  EXPECT_EQ(log.contact_points[0].p_frame, Vec3(0, 0, 0.01));
  const std::string again = (dir.path() / "again").string();
  WriteRecordedLog(log, again);
  const RecordedLog back = ReadRecordedLog(again);
  ASSERT_EQ(back.contacts.size(), 2u);
  for (size_t r = 0; r < 2; ++r) {
    EXPECT_EQ(back.contacts[r].t, log.contacts[r].t);
    EXPECT_EQ(back.contacts[r].distance_m, log.contacts[r].distance_m);
    EXPECT_EQ(back.contacts[r].std_m, log.contacts[r].std_m);
  }
  EXPECT_NEAR((back.planes[0].cov - log.planes[0].cov).norm(), 0.0, 1e-18);
  EXPECT_EQ(back.planes[0].T_base_plane.translation(), log.planes[0].T_base_plane.translation());
  // A plane known per axis (std: [6]), turned (its quaternion kept as stated, so its pose comes
  // back to the bit), and a log estimated in another frame.
  const std::string turned =
      "T_base_plane: [0, 0, 0.9, 0.6, 0.8, 0, 0], std: [0.5, 0.5, 0.001, "
      "0.017, 0.017, 0.17]";
  f.log_yaml.replace(f.log_yaml.find("T_base_plane"),
                     f.log_yaml.find("}}, points") - f.log_yaml.find("T_base_plane"), turned);
  f.log_yaml += "estimate_in: external_camera\n";
  f.Write(dir.path());
  const RecordedLog per_axis = ReadRecordedLog(dir.path().string());
  EXPECT_EQ(per_axis.planes[0].cov(2, 2), 0.001 * 0.001);
  EXPECT_EQ(per_axis.planes[0].cov(5, 5), 0.17 * 0.17);
  EXPECT_EQ(per_axis.estimate_in, "external_camera");
  const std::string again2 = (dir.path() / "again2").string();
  WriteRecordedLog(per_axis, again2);
  const RecordedLog back2 = ReadRecordedLog(again2);
  EXPECT_EQ(back2.planes[0].cov, per_axis.planes[0].cov);
  EXPECT_EQ(back2.planes[0].T_base_plane.rotation(), per_axis.planes[0].T_base_plane.rotation());
  EXPECT_EQ(back2.estimate_in, "external_camera");
}

// A camera's frames are files images/<camera>/<t_ns>.png, in time order, with the stream's clock
// offset; any other name in the folder, or images beside tags.csv, is refused naming it.
TEST(RecordedLog, ImagesAreNamedByTheirTime) {
  testing::TempDir dir;
  Files f;
  f.log_yaml +=
      "cameras: {cam0: {frame: external_camera, fx: 600, fy: 600, cx: 320, cy: 240, width: 640, "
      "height: 480}}\n"
      "tags: {ids: {20: {frame: tag_gripper, size_m: 0.04}}}\n"
      "images: {dir: images, clock_offset_s: 1}\n";
  f.Write(dir.path());
  std::filesystem::create_directories(dir.path() / "images" / "cam0");
  for (const char* name : {"250000000.png", "100000000.png"}) {
    std::ofstream(dir.path() / "images" / "cam0" / name) << "not read here";
  }
  const RecordedLog log = ReadRecordedLog(dir.path().string());
  ASSERT_EQ(log.images.size(), 2u);
  EXPECT_DOUBLE_EQ(log.images[0].t, 1.1);
  EXPECT_DOUBLE_EQ(log.images[1].t, 1.25);
  EXPECT_EQ(log.image_stats.rows, 2);
  EXPECT_TRUE(log.tag_rows.empty());
  std::ofstream(dir.path() / "images" / "cam0" / "frame7.png") << "x";
  try {
    ReadRecordedLog(dir.path().string());
    ADD_FAILURE() << "a frame not named by its time was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame7.png: expected <t_ns>.png"), std::string::npos)
        << e.what();
  }
  std::filesystem::remove(dir.path() / "images" / "cam0" / "frame7.png");
  std::filesystem::create_directories(dir.path() / "images" / "cam1");
  try {
    ReadRecordedLog(dir.path().string());
    ADD_FAILURE() << "a folder of no camera was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("cam1: not a folder named after one of the log's"),
              std::string::npos)
        << e.what();
  }
  std::filesystem::remove(dir.path() / "images" / "cam1");
  f.log_yaml.replace(f.log_yaml.find("tags: {ids"), 10, "tags: {file: tags.csv, ids");
  f.Write(dir.path());
  std::ofstream(dir.path() / "tags.csv")
      << "t_s,camera,tag_id,u0_px,v0_px,u1_px,v1_px,u2_px,v2_px,u3_px,v3_px\n";
  try {
    ReadRecordedLog(dir.path().string());
    ADD_FAILURE() << "tags.csv and images were both read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("tags.csv or images, not both"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace flexbench::sim

namespace flexbench::sim {
namespace {

// Commands (the servos' position targets) and the IMUs' noise: written, they read back as the
// same numbers; a command file like joints.csv is checked like it, and only position targets
// are read.
TEST(RecordedLog, CommandsAndImuNoiseRoundTrip) {
  testing::TempDir dir;
  RecordedLog log;
  log.declared_path = "/a/declared.yaml";
  log.joints = {"a", "b"};
  log.joint_is_slide = {0, 1};
  log.joint_t = {0.0, 0.002};
  log.joint_q = {0.1, 0.01, 0.2, 0.02};
  log.command_joints = {"b", "a"};
  log.command_is_slide = {1, 0};
  log.command_t = {0.0, 0.002, 0.004};
  log.command_q = {0.011, 0.12, 0.021, 0.22, 0.031, 0.32};
  log.imus.push_back({"imu2", "imu_link2", false, Quat::Identity()});
  log.imu.push_back({});
  log.gyro_std = 0.003;
  log.accel_std = 0.05;
  const std::string path = (dir.path() / "log").string();
  WriteRecordedLog(log, path);
  const RecordedLog back = ReadRecordedLog(path);
  EXPECT_EQ(back.command_joints, log.command_joints);
  EXPECT_EQ(back.command_is_slide, log.command_is_slide);
  EXPECT_EQ(back.command_t, log.command_t);
  EXPECT_EQ(back.command_q, log.command_q);
  EXPECT_EQ(back.command_stats.rows, 3);
  EXPECT_EQ(back.gyro_std, 0.003);
  EXPECT_EQ(back.accel_std, 0.05);
  EXPECT_EQ(back.command(1)[1], 0.22);

  std::ofstream(std::filesystem::path(path) / "commands.csv") << "t_s,a_rad\n0,nan\n";
  try {
    ReadRecordedLog(path);
    ADD_FAILURE() << "a NaN command was read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("commands.csv:2: column 'a_rad' is nan"),
              std::string::npos)
        << e.what();
  }
  std::string yaml;
  {
    std::ifstream in(std::filesystem::path(path) / "log.yaml");
    yaml.assign(std::istreambuf_iterator<char>(in), {});
  }
  const size_t at = yaml.find("type: position");
  ASSERT_NE(at, std::string::npos);
  // Torques need torque columns; a type that is neither is one line naming the key.
  for (const auto& [type, says] :
       {std::pair<std::string, std::string>{"type: torque", "expected <joint>_Nm or <joint>_N"},
        {"type: velocity", "position (the servos' targets) or torque"}}) {
    std::string y = yaml;
    y.replace(at, 14, type);
    std::ofstream(std::filesystem::path(path) / "log.yaml") << y;
    try {
      ReadRecordedLog(path);
      ADD_FAILURE() << type << ": read";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace flexbench::sim
