#include "scenarios/runner/common/tag_tracking.h"

#include <algorithm>
#include <cmath>

namespace flexbench::scenarios {

void AimCamera(sim::Simulation* sim, const std::string& pan, const std::string& tilt,
               const std::string& at, const std::string& camera) {
  const auto& names = sim->actuated_joints();
  const auto index = [&](const std::string& j) {
    return static_cast<int>(std::find(names.begin(), names.end(), j) - names.begin());
  };
  sim->SetCommand(pan, 0.0);
  sim->SetCommand(tilt, 0.0);
  for (int pass = 0; pass < 3; ++pass) {
    const Eigen::VectorXd q = sim->command();
    const Vec3 target = sim->NominalPose(at, q).translation();
    const Eigen::Isometry3d T_w_cam = sim->NominalPose(camera, q);
    const Vec3 d_cam = T_w_cam.inverse() * target;  // optical frame: x right, y down, z fwd
    sim->SetCommand(pan, q[index(pan)] + std::atan2(-d_cam.x(), d_cam.z()));
    sim->SetCommand(tilt, q[index(tilt)] + std::atan2(d_cam.y(), d_cam.z()));
  }
}

std::vector<estimators::Measurement> TagMeasurements(
    const render::DetectionResult& det, const std::vector<render::TagInModel>& tags,
    const std::map<int, kinematics::FrameId>& tag_frames, bool corners, double pixel_std,
    double t) {
  std::vector<estimators::Measurement> out;
  const double sigma2 = pixel_std * pixel_std;
  for (const render::TagDetection& d : det.detections) {
    const auto frame_it = tag_frames.find(d.id);
    if (frame_it == tag_frames.end()) continue;
    const render::TagInModel* tag = nullptr;
    for (const auto& tm : tags) {
      if (tm.id == d.id) tag = &tm;
    }
    if (!tag) continue;
    if (corners) {
      estimators::TagCorners m;
      m.t = t;
      m.camera = 0;
      m.tag_id = d.id;
      m.frame = frame_it->second;
      for (int k = 0; k < 4; ++k) {
        m.p_frame[k] = tag->corners_geom[k];
        m.uv[k] = d.corners[k];
      }
      m.cov = Eigen::Matrix<double, 8, 8>::Identity() * sigma2;
      out.push_back(m);
    } else {
      estimators::PixelPoint m;
      m.t = t;
      m.camera = 0;
      m.frame = frame_it->second;
      m.p_frame = sim::TagCentre(tag->corners_geom);
      m.uv = d.center;
      m.cov = Eigen::Matrix2d::Identity() * sigma2;
      out.push_back(m);
    }
  }
  return out;
}

void AddTagCameraToLog(const mjModel* m, const std::string& camera, const PinholeCamera& intrinsics,
                       const std::vector<render::TagInModel>& tags,
                       const std::map<int, kinematics::FrameId>& tag_frames, double pixel_std,
                       bool centres, sim::RecordedLog* log) {
  log->cameras.push_back({camera, camera, intrinsics});
  log->pixel_std_px = pixel_std;
  log->pixel_std_stated = true;
  log->tag_centres = log->has_centre_columns = centres;
  for (const render::TagInModel& tag : tags) {
    if (!tag_frames.count(tag.id)) continue;
    sim::LogTag t;
    t.id = tag.id;
    t.frame = sim::ObjectName(m, mjOBJ_GEOM, tag.geom_id);
    for (int c = 0; c < 4; ++c) t.corners_m[c] = tag.corners_geom[c];
    log->tags.push_back(t);
  }
}

int AddDetectionsToLog(const render::DetectionResult& det, double t, int camera,
                       sim::RecordedLog* log) {
  int others = 0;
  for (const render::TagDetection& d : det.detections) {
    const int tag = sim::TagIndex(*log, d.id);
    if (tag < 0) {
      ++others;
      continue;
    }
    sim::LogTagRow row;
    row.t = t;
    row.camera = camera;
    row.tag = tag;
    row.uv = d.corners;
    row.centre = d.center;
    log->tag_rows.push_back(row);
  }
  return others;
}

}  // namespace flexbench::scenarios
