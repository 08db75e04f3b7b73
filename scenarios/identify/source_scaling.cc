#include "scenarios/identify/source_scaling.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/ppoe_data.h"
#include "estimators/lie/so3.h"

namespace flexbench::identify {
namespace {

using Mat36 = Eigen::Matrix<double, 3, 6>;

// A direction no row's noise reaches at all (a planar arm's points out of its plane) still
// compares with something: a nanometre.
constexpr double kNoiseFloorM = 1e-9;

bool IsDiagonal(const Mat6& m) {
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) {
      if (r != c && m(r, c) != 0.0) return false;
    }
  }
  return true;
}

// The directions of one source's covariance: its axes when it is diagonal (the names a
// declared std_rot_deg / std_trans_m gives), else its eigenvectors.
void CovarianceDirections(const sim::DeclaredSource& s, SourceDirection base,
                          std::vector<SourceDirection>* out) {
  static const char* kAxis[6] = {"trans_x", "trans_y", "trans_z", "rot_x", "rot_y", "rot_z"};
  if (IsDiagonal(s.cov)) {
    for (int k = 0; k < 6; ++k) {
      if (!(s.cov(k, k) > 0.0)) continue;
      base.v = Vec6::Unit(k);
      base.variance = s.cov(k, k);
      base.name = s.at + ":" + kAxis[k];
      out->push_back(base);
    }
    return;
  }
  const Eigen::SelfAdjointEigenSolver<Mat6> eig(s.cov);
  const double largest = eig.eigenvalues().maxCoeff();
  for (int k = 5, n = 1; k >= 0; --k) {
    if (!(eig.eigenvalues()[k] > 1e-12 * largest)) continue;
    base.v = eig.eigenvectors().col(k);
    base.variance = eig.eigenvalues()[k];
    base.name = s.at + ":dir" + std::to_string(n++);
    out->push_back(base);
  }
}

// Rows whose nuisance unknowns are fitted together: a socket's rows (its point, 3 unknowns)
// or the rows of one measurement frame (its pose: any rigid motion, 6). Key: (kind, index).
std::map<std::pair<int, int>, std::vector<int>> NuisanceBlocks(const DataSet& d) {
  std::map<std::pair<int, int>, std::vector<int>> blocks;
  for (size_t r = 0; r < d.rows.size(); ++r) {
    const Observation& o = d.rows[r];
    if (UnitOf(o.type) != RowUnit::kMetres) continue;
    if (o.type == ObservationType::kGroup) {
      blocks[{0, o.group}].push_back(static_cast<int>(r));
    } else if (o.frame >= 0) {
      blocks[{1, o.frame}].push_back(static_cast<int>(r));
    }
  }
  return blocks;
}

// The nuisance's effect on row r's point per unknown: a socket's point moves it one to one, a
// frame's pose by a rigid motion rho + theta x p.
Mat36 NuisanceColumns(bool frame, const Vec3& p) {
  Mat36 A = Mat36::Zero();
  A.leftCols<3>().setIdentity();
  if (frame) A.rightCols<3>() = -lie::Skew(p);
  return A;
}

// The frame of that name, or -1 (the base body has none of its own).
kinematics::FrameId FrameNamed(const kinematics::PpoeModel& model, const std::string& name) {
  for (kinematics::FrameId f = 1; f < model.num_frames(); ++f) {
    if (model.frame(f).name == name) return f;
  }
  return -1;
}

}  // namespace

std::vector<SourceDirection> SourceDirections(const mjModel* m, const sim::DeclaredModel& d,
                                              const kinematics::PpoeModel& model) {
  std::vector<SourceDirection> out;
  for (size_t i = 0; i < d.sources.size(); ++i) {
    const sim::DeclaredSource& s = d.sources[i];
    const int j = mj_name2id(m, mjOBJ_JOINT, s.at.c_str());
    SourceDirection base;
    base.source = static_cast<int>(i);
    base.frame = FrameNamed(model, (j >= 0 ? "joint/" : "body/") + s.at);
    if (base.frame <= kinematics::kBaseFrame) continue;  // on the base: it moves nothing
    if (j >= 0 && s.about_axis_rad > 0.0) {
      SourceDirection axis = base;
      axis.about_axis = true;
      axis.v.tail<3>() = Eigen::Map<const Vec3>(m->jnt_axis + 3 * j).normalized();
      axis.variance = s.about_axis_rad * s.about_axis_rad;
      axis.name = s.at + ":about_axis";
      out.push_back(axis);
    }
    CovarianceDirections(s, base, &out);
  }
  return out;
}

std::vector<double> SourceSignalToNoise(const kinematics::PpoeModel& model, const DataSet& d,
                                        const std::vector<kinematics::FrameId>& points,
                                        const std::vector<Vec3>& p, const std::vector<Mat3>& noise,
                                        const std::vector<SourceDirection>& dirs) {
  const size_t nd = dirs.size();
  // g[r * nd + i]: row r's point per unit of direction i; W[r] = N_r^-1.
  std::vector<Vec3> g(d.rows.size() * nd, Vec3::Zero());
  std::vector<Mat3> W(d.rows.size(), Mat3::Zero());
  kinematics::PpoeData pd(model);
  std::vector<char> above(model.num_frames());
  const Mat3 floor = kNoiseFloorM * kNoiseFloorM * Mat3::Identity();
  for (size_t r = 0; r < d.rows.size(); ++r) {
    if (UnitOf(d.rows[r].type) != RowUnit::kMetres) continue;
    W[r] = (noise[r] + floor).inverse();
    kinematics::ForwardKinematics(model, pd, d.rows[r].q);
    std::fill(above.begin(), above.end(), 0);
    for (kinematics::FrameId f = points[d.rows[r].point]; f > 0; f = model.frame(f).parent) {
      above[f] = 1;
    }
    for (size_t i = 0; i < nd; ++i) {
      const kinematics::FrameId k = dirs[i].frame;
      if (!above[k]) continue;
      const lie::SE3 T_base_kp =
          pd.T_base_frame[model.frame(k).parent] * model.frame(k).T_parent_ip;
      const Mat3& R = T_base_kp.rotation();
      g[r * nd + i] =
          R * dirs[i].v.head<3>() + (R * dirs[i].v.tail<3>()).cross(p[r] - T_base_kp.translation());
    }
  }
  for (const auto& [key, rows] : NuisanceBlocks(d)) {
    const int n = key.first == 0 ? 3 : 6;
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n), b = Eigen::MatrixXd::Zero(n, nd);
    for (int r : rows) {
      const Eigen::MatrixXd A = NuisanceColumns(key.first == 1, p[r]).leftCols(n);
      H += A.transpose() * W[r] * A;
      for (size_t i = 0; i < nd; ++i) b.col(i) += A.transpose() * W[r] * g[r * nd + i];
    }
    const Eigen::MatrixXd c = H.completeOrthogonalDecomposition().solve(b);
    for (int r : rows) {
      const Eigen::MatrixXd A = NuisanceColumns(key.first == 1, p[r]).leftCols(n);
      for (size_t i = 0; i < nd; ++i) g[r * nd + i] -= A * c.col(i);
    }
  }
  std::vector<double> out(nd, 0.0);
  for (size_t r = 0; r < d.rows.size(); ++r) {
    for (size_t i = 0; i < nd; ++i) {
      const Vec3& gi = g[r * nd + i];
      out[i] = std::max(out[i], dirs[i].variance * gi.dot(W[r] * gi));
    }
  }
  return out;
}

kinematics::PpoeModel WithSourceDirections(const kinematics::PpoeModel& model,
                                           const std::vector<SourceDirection>& dirs,
                                           const std::vector<bool>& keep) {
  std::map<kinematics::FrameId, Mat6> cov;
  for (size_t i = 0; i < dirs.size(); ++i) {
    Mat6& c = cov.try_emplace(dirs[i].frame, Mat6::Zero()).first->second;
    if (keep[i]) c += dirs[i].variance * dirs[i].v * dirs[i].v.transpose();
  }
  kinematics::PpoeModel out = model;
  for (const auto& [frame, c] : cov) out.SetSourceCovariance(frame, c);
  return out;
}

void ScaleSourceDirections(const std::vector<SourceDirection>& dirs,
                           const std::vector<bool>& constrained, double scale,
                           std::vector<sim::DeclaredSource>* sources) {
  // Per source: whether every direction of its covariance is constrained (then the whole of it
  // scales, as one product).
  std::vector<int> cov_dirs(sources->size(), 0), cov_constrained(sources->size(), 0);
  for (size_t i = 0; i < dirs.size(); ++i) {
    if (dirs[i].about_axis) continue;
    ++cov_dirs[dirs[i].source];
    cov_constrained[dirs[i].source] += constrained[i] ? 1 : 0;
  }
  for (size_t s = 0; s < sources->size(); ++s) {
    if (cov_dirs[s] > 0 && cov_constrained[s] == cov_dirs[s]) (*sources)[s].cov *= scale;
  }
  for (size_t i = 0; i < dirs.size(); ++i) {
    if (!constrained[i]) continue;
    sim::DeclaredSource& s = (*sources)[dirs[i].source];
    if (dirs[i].about_axis) {
      s.about_axis_rad *= std::sqrt(scale);
    } else if (cov_constrained[dirs[i].source] < cov_dirs[dirs[i].source]) {
      s.cov += (scale - 1.0) * dirs[i].variance * dirs[i].v * dirs[i].v.transpose();
    }
  }
}

}  // namespace flexbench::identify
