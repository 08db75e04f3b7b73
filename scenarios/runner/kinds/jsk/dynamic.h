// Dynamic runs: the truth moved along the trajectory by its servos (sim::Simulation::Step), the
// sensors polled at their rates, and snapshots at the filter rate. Every estimator later sees the
// same snapshots: the raw IMU readings since the last one (each estimator that uses IMUs runs
// its own Madgwick filter per IMU on them, estimators/imu/imu_orientations.h), then the step,
// then the encoders.
//
//   filter_rate_hz: 10
//   madgwick: {beta: 0.05, init: accel}   # init: accel (yaw 0) or truth (a calibrated yaw)
//   sensors: [...]                        # sim sensors: motor-side encoders and the IMUs
//   tag_camera: {camera: external_camera, pixel_std_px: 1, export_images: false}   # optional,
//                                         # with the render: and detector: blocks
//                                         # (common/render_config.h)
// With a tag camera, each snapshot also renders that camera (OSMesa) and runs libapriltag on the
// image: the tags on observed frames become TagCorners, which the estimators see after the
// encoders (the EKFs correct their kinematic prior with them; the particle filters ignore them).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "estimators/measurement.h"
#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "scenarios/runner/kinds/jsk/rig.h"
#include "scenarios/runner/kinds/jsk/trace.h"
#include "scenarios/runner/kinds/jsk/trajectory.h"
#include "sim/sensors/sensor.h"

namespace flexbench::scenarios::jsk {

// A camera of the truth that sees the arm's tags.
struct TagCamera {
  std::string camera;  // an MJCF camera and an observed frame of the declared model
  int cam_id = -1;
  render::RenderMode mode = render::RenderMode::kFast;
  render::DetectorSettings detector;
  double pixel_std_px = 1.0;             // each corner's, in u and v
  bool export_images = false;            // --export-log writes the frames, not their detections
  std::vector<render::TagInModel> tags;  // the truth's textured tags
  std::map<int, kinematics::FrameId> tag_frames;  // those on observed frames, by id
};

struct DynamicOptions {
  double filter_rate_hz = 10.0;
  double madgwick_beta = 0.05;
  bool madgwick_init_truth = false;
  std::optional<TagCamera> tag_camera;
};
// Reads the options; a tag camera textures the truth's tags and adds the camera to rig.setup
// (InputError for a camera that is not in the model or not an observed frame).
DynamicOptions ParseDynamicOptions(const ConfigNode& root, Rig& rig);

struct Snapshot {
  double t = 0.0;
  int segment = 0;                                   // waypoint being approached or held
  Eigen::VectorXd reference;                         // commanded angles (declared order)
  Eigen::VectorXd link;                              // true link-side angles (declared order)
  estimators::JointReading joints;                   // latest encoder readings
  std::vector<estimators::ImuReading> imu_raw;       // IMU readings since the last snapshot
  std::vector<estimators::OrientationReading> imus;  // the IMUs' filters' orientations here
  lie::SE3 T_true;                                   // the end effector (declared) in the world
  std::vector<Quat> imu_true;                        // true IMU orientations (for diagnostics)
  std::vector<estimators::TagCorners> tags;          // the tag camera's detections here
  std::string png;  // its frame, encoded (tag_camera.export_images)
};

// Settles the truth at the first waypoint, then steps through the trajectory. The sensor list
// must give an encoder for every declared joint and every IMU (InputError otherwise). Sets the
// IMUs' filter options in rig.setup (with madgwick init: truth, each IMU's true orientation at
// its first reading).
std::vector<Snapshot> SimulateDynamic(Rig& rig, const Trajectory& trajectory,
                                      sim::SensorSuite& sensors, const DynamicOptions& options,
                                      const RunContext& ctx);

// Writes the snapshots as a recorded-log folder `dir` (sim/recorded_log.h) that `flexbench
// replay` turns into the estimates RunOnSnapshots makes (the same bits): a joint row per
// snapshot (its encoder readings), every IMU reading of the snapshots, the end effector's truth
// at each, the IMUs' initial orientations when the run started them at the truth, the tag
// camera's detections (cameras, tags, tags.csv) or its frames (images/<camera>/<t_ns>.png), and
// the declared model (declared.yaml).
void ExportLog(const Rig& rig, const DynamicOptions& options, const std::vector<Snapshot>& snaps,
               const std::string& dir);

// Runs an estimator over snapshots; `with_position` adds the end effector's position reading.
Trace RunOnSnapshots(const Rig& rig, const EstimatorSpec& spec, const std::vector<Snapshot>& snaps,
                     std::uint64_t seed, bool with_position, const RunContext& ctx, int* rejected);

}  // namespace flexbench::scenarios::jsk
