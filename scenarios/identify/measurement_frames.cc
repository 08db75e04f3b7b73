#include "scenarios/identify/measurement_frames.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "estimators/error.h"
#include "scenarios/identify/problem.h"

namespace flexbench::identify {
namespace {

bool IsIdentifier(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  for (char c : s) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  }
  return true;
}

double PositiveStd(const ConfigNode& parent, const char* key) {
  const double s = parent.GetDouble(key);
  if (!(std::isfinite(s) && s > 0.0)) parent.Child(key).Fail("must be > 0 (a standard deviation)");
  return s;
}

MeasurementFrame ParseFrame(const std::string& name, const ConfigNode& n) {
  MeasurementFrame f;
  f.name = name;
  f.where = n.Where();
  CheckFrameName(name, n.WhereKey());
  if (!n.IsMap() && !(n.IsScalar() && n.AsString().empty())) {
    n.Fail("expected a map ({} for an unknown pose)");
  }
  if (!n.IsMap()) return f;
  if (const auto t = n.Optional("T_base_frame")) {
    f.T_ref = ParseFramePose(*t);
    f.has_guess = true;
  }
  const bool m = n.Has("prior_std_m"), d = n.Has("prior_std_deg");
  if (m != d) n.Fail("prior_std_m and prior_std_deg go together");
  if (m) {
    f.prior_std_m = PositiveStd(n, "prior_std_m");
    f.prior_std_rad = PositiveStd(n, "prior_std_deg") * kDeg;
    if (!f.has_guess) n.Fail("a prior needs its mean, T_base_frame");
    f.has_prior = true;
  }
  return f;
}

}  // namespace

void CheckFrameName(const std::string& name, const std::string& where) {
  if (!IsIdentifier(name) || name == "base") {
    throw InputError(where + ": a frame name is letters, digits, '_' or '-' (and not 'base')");
  }
}

lie::SE3 ParseFramePose(const ConfigNode& n) {
  const std::vector<double> v = n.AsDoubleList();
  if (v.size() != 7) n.Fail("expected [x, y, z, qw, qx, qy, qz] (m)");
  for (double e : v) {
    if (!std::isfinite(e) || std::abs(e) > 1e3) n.Fail("values must be finite, |value| <= 1000");
  }
  const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
  if (std::abs(q.norm() - 1.0) > 1e-6) n.Fail("quaternion is not of unit length");
  return lie::SE3(q.normalized().toRotationMatrix(), Vec3(v[0], v[1], v[2]));
}

std::vector<MeasurementFrame> ParseMeasurementFrames(const ConfigNode& node) {
  if (!node.IsMap()) node.Fail("expected a map of frame name -> {T_base_frame, prior_std_*}");
  std::vector<MeasurementFrame> frames;
  for (const std::string& name : node.Keys()) frames.push_back(ParseFrame(name, node.Child(name)));
  return frames;
}

void CheckFramesUsed(const DataSet& data, const std::string& what) {
  std::vector<int> count(data.frames.size(), 0);
  for (const Observation& o : data.rows) {
    if (o.frame >= 0) ++count[o.frame];
  }
  for (size_t f = 0; f < count.size(); ++f) {
    if (count[f] > 0) continue;
    throw InputError(data.frames[f].where + ": frame '" + data.frames[f].name +
                     "' is declared but no " + what + " row is measured in it (column 'frame')");
  }
}

std::vector<lie::SE3> ReferencePoses(const DataSet& data) {
  std::vector<lie::SE3> T;
  for (const MeasurementFrame& f : data.frames) T.push_back(f.T_ref);
  return T;
}

void RegisterFrames(const EffectModel& em, const RowLoads& loads, DataSet* data) {
  const std::vector<Vec3> p_pred = PredictAll(em, *data, loads, {}, Eigen::VectorXd());
  for (size_t f = 0; f < data->frames.size(); ++f) {
    MeasurementFrame& frame = data->frames[f];
    if (frame.has_guess) continue;
    std::vector<int> rows;
    for (size_t r = 0; r < data->rows.size(); ++r) {
      if (data->rows[r].frame == static_cast<int>(f)) rows.push_back(static_cast<int>(r));
    }
    Eigen::Matrix3Xd p_frame(3, rows.size()), p_base(3, rows.size());
    for (size_t k = 0; k < rows.size(); ++k) {
      p_frame.col(k) = data->rows[rows[k]].p_frame;
      p_base.col(k) = p_pred[rows[k]];
    }
    const Eigen::Matrix3Xd centred = p_frame.colwise() - p_frame.rowwise().mean();
    const Eigen::JacobiSVD<Eigen::Matrix3Xd> svd(centred);
    if (rows.size() < 3 || !(svd.singularValues()[1] > 1e-6 * svd.singularValues()[0])) {
      throw InputError(frame.where + ": frame '" + frame.name +
                       "': its rows' points lie on a line or are fewer than 3; the frame's pose "
                       "cannot be registered (give T_base_frame)");
    }
    const Eigen::Matrix4d T = Eigen::umeyama(p_frame, p_base, false);
    frame.T_ref = lie::SE3(T.topLeftCorner<3, 3>(), T.topRightCorner<3, 1>());
  }
}

DataSet InBase(const DataSet& data, const std::vector<lie::SE3>& T_base_frames) {
  DataSet d = data;
  for (Observation& o : d.rows) {
    if (o.frame < 0) continue;
    const lie::SE3& T = T_base_frames.at(o.frame);
    o.p_base = T * o.p_frame;
    o.R_base = T.rotation() * o.R_frame.get();
    o.frame = -1;
  }
  return d;
}

std::vector<Mat6> FrameCovariances(const EffectModel& em, const DataSet& data,
                                   const RowLoads& loads, const Fit& fit,
                                   const IdentifyOptions& opt, std::vector<Mat3>* offset_cov) {
  std::vector<Mat6> cov;
  const bool offsets = std::count(data.offset_unknown.begin(), data.offset_unknown.end(), 1) > 0;
  if (data.frames.empty() && !offsets) return cov;
  const Problem pr(em, data, loads, fit.active, fit.basis, opt);
  Eigen::MatrixXd info;
  NormalEquations(pr, StateOf(pr, fit), nullptr, &info, nullptr);
  // Pseudo-inverse of the normalised information (as Report): a direction the data does not
  // determine adds nothing instead of an arbitrary variance.
  const Eigen::VectorXd s = info.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(s.asDiagonal() * info * s.asDiagonal());
  const Eigen::VectorXd& lam = eig.eigenvalues();
  Eigen::MatrixXd pinv = Eigen::MatrixXd::Zero(info.rows(), info.cols());
  for (int i = 0; i < lam.size(); ++i) {
    if (lam[i] > opt.singular_tol * lam.maxCoeff()) {
      pinv += eig.eigenvectors().col(i) * eig.eigenvectors().col(i).transpose() / lam[i];
    }
  }
  const int dof = std::max(1, pr.num_residuals() - pr.num_params());
  const Eigen::MatrixXd cov_x = (fit.rss / dof) * s.asDiagonal() * pinv * s.asDiagonal();
  for (size_t f = 0; f < data.frames.size(); ++f) {
    const int c = pr.frame_col(static_cast<int>(f));
    cov.push_back(cov_x.block<6, 6>(c, c));
  }
  if (offset_cov) {
    offset_cov->assign(data.offset_unknown.size(), Mat3::Zero());
    for (size_t k = 0; k < offset_cov->size(); ++k) {
      const int c = pr.offset_col(static_cast<int>(k));
      if (c >= 0) (*offset_cov)[k] = cov_x.block<3, 3>(c, c);
    }
  }
  return cov;
}

std::vector<Vec3> PredictMarkers(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                                 const Fit& fit) {
  std::vector<Vec3> p = PredictAll(em, data, loads, fit.active, fit.theta);
  if (fit.marker_offsets.empty()) return p;
  EffectModel::Workspace ws = em.MakeWorkspace();
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const Observation& o = data.rows[r];
    if (UnitOf(o.type) != RowUnit::kMetres) continue;
    p[r] = em.PredictPose(o.q, loads.At(r, o, ws), fit.active, fit.theta.data(), ws, o.point) *
           fit.marker_offsets[o.point];
  }
  return p;
}

}  // namespace flexbench::identify
