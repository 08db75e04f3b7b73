#include "scenarios/runner/common/trajectories.h"

#include <Eigen/Geometry>
#include <cctype>
#include <cstdio>
#include <sstream>

#include "scenarios/runner/output.h"

namespace flexbench::scenarios {

std::string TumLine(double t, const lie::SE3& T) {
  const Eigen::Quaterniond q(T.rotation());
  const Vec3& p = T.translation();
  char line[512];
  std::snprintf(line, sizeof(line), "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g", t, p.x(),
                p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
  return line;
}

void TrajectoryRecorder::AddTruth(double t, const lie::SE3& T_frame_ee) {
  truth_.push_back({t, T_frame_ee, Mat6::Zero()});
}

void TrajectoryRecorder::Add(const std::string& estimator, double t, const lie::SE3& T_frame_ee,
                             const Mat6& cov) {
  estimates_[estimator].push_back({t, T_frame_ee, cov});
}

void TrajectoryRecorder::Write(const OutputDir& out, const std::string& frame_in,
                               const std::string& part) const {
  // A folder name: a model's frame name may hold anything.
  std::string frame = frame_in;
  for (char& ch : frame) {
    if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '_' && ch != '-') ch = '_';
  }
  const std::string dir = "trajectories/" + frame + "/" + (part.empty() ? "" : part + "/");
  const auto tum = [&](const std::vector<Pose>& poses) {
    std::ostringstream s;
    s << "# timestamp tx ty tz qx qy qz qw (end effector in " << frame << "; m, s)\n";
    for (const Pose& p : poses) s << TumLine(p.t, p.T) << "\n";
    return s.str();
  };
  WriteFileAtomic(out.File(dir + "truth.tum"), tum(truth_));
  for (const auto& [name, poses] : estimates_) {
    WriteFileAtomic(out.File(dir + name + ".tum"), tum(poses));
    std::ostringstream c;
    c << "timestamp";
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j) c << ",c" << i << j;
    }
    c << "\n";
    char num[40];
    for (const Pose& p : poses) {
      std::snprintf(num, sizeof(num), "%.17g", p.t);
      c << num;
      for (int i = 0; i < 6; ++i) {
        for (int j = i; j < 6; ++j) {
          std::snprintf(num, sizeof(num), ",%.17g", p.cov(i, j));
          c << num;
        }
      }
      c << "\n";
    }
    WriteFileAtomic(out.File(dir + name + ".cov.csv"), c.str());
  }
}

}  // namespace flexbench::scenarios
