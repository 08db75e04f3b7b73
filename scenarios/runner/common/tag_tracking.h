// Shared by the kinds that watch the end effector's AprilTags with a pan-tilt camera
// (tag_fusion, closed_loop_estimators): aiming the camera at the arm's nominal hand, and turning
// libapriltag's detections into the estimators' typed measurements.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "estimators/measurement.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "sim/recorded_log.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {

// Pan and tilt so that the camera's optical axis passes through `at` on the nominal arm at the
// current command (three fixed-point passes: the camera sits off the pan and tilt axes). Starts
// from the centred head, so the result depends on the arm's command only.
void AimCamera(sim::Simulation* sim, const std::string& pan, const std::string& tilt,
               const std::string& at, const std::string& camera);

// One measurement per detected tag that rides on an observed frame (`tag_frames`: tag id ->
// declared frame): its four corners (8-D) or its centre pixel (libapriltag's centre is the
// homography image of the tag centre, i.e. the projection of the 3-D centre), on camera 0.
std::vector<estimators::Measurement> TagMeasurements(
    const render::DetectionResult& det, const std::vector<render::TagInModel>& tags,
    const std::map<int, kinematics::FrameId>& tag_frames, bool corners, double pixel_std, double t);

// The camera (an observed frame named as the MuJoCo camera) and the tags on observed frames as a
// recorded log's cameras and tags (--export-log). `centres`: the estimators fuse the centre
// pixel (tags.measurement: centre), and tags.csv keeps the detector's centres.
void AddTagCameraToLog(const mjModel* m, const std::string& camera, const PinholeCamera& intrinsics,
                       const std::vector<render::TagInModel>& tags,
                       const std::map<int, kinematics::FrameId>& tag_frames, double pixel_std,
                       bool centres, sim::RecordedLog* log);

// The detections of the log's tags by its camera `camera` at time t as its tags.csv rows, with
// the detector's centres, in the detector's order (as TagMeasurements feeds them to the
// estimators). Returns the detections of tags the log does not have.
int AddDetectionsToLog(const render::DetectionResult& det, double t, int camera,
                       sim::RecordedLog* log);

}  // namespace flexbench::scenarios
