#include "scenarios/identify/problem.h"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "estimators/kinematics/model_effects.h"
#include "estimators/lie/so3.h"
#include "scenarios/identify/parallel.h"

namespace flexbench::identify {

int NumTheta(const EffectModel& em, const std::vector<int>& active) {
  int n = 0;
  for (int i : active) n += em.candidates()[i].num_params;
  return n;
}

double Bic(double rss, int n, int k) {
  return n * std::log(std::max(rss, 1e-300) / n) + k * std::log(static_cast<double>(n));
}

IdentifyOptions TaskOptions(const IdentifyOptions& opt, int threads) {
  IdentifyOptions out = opt;
  if (threads > 1) out.threads = 1;
  return out;
}

int RowDim(const Observation& o) {
  switch (o.type) {
    case ObservationType::kPose:
      return 6;
    case ObservationType::kPixel:
    case ObservationType::kGravity:
      return 2;
    default:
      return 3;
  }
}

lie::SE3 CameraPose(const EffectModel& em, const DataSet& data, const std::vector<int>& active,
                    const double* theta) {
  // Offsets add up, the declared file's own (EffectModel::SetBaseEffects) included, as
  // ModelEffects sums a frame's origin terms.
  Vec6 xi = Vec6::Zero();
  bool any = false;
  const auto add = [&](const std::vector<int>& list, const double* t) {
    for (int i : list) {
      const Candidate& c = em.candidates()[i];
      if (c.type == EffectType::kCameraOffset) {
        xi += Eigen::Map<const Vec6>(t);
        any = true;
      }
      t += c.num_params;
    }
  };
  add(em.base_effects(), em.base_theta().data());
  add(active, theta);
  return any ? data.camera.T_base_cam * lie::SE3::Exp(xi) : data.camera.T_base_cam;
}

Vec3 GravityUp(const EffectModel& em, const std::vector<int>& active, const double* theta) {
  Eigen::Vector2d phi = Eigen::Vector2d::Zero();
  bool any = false;
  const auto add = [&](const std::vector<int>& list, const double* t) {
    for (int i : list) {
      const Candidate& c = em.candidates()[i];
      if (c.type == EffectType::kGravityTilt) {
        phi += Eigen::Map<const Eigen::Vector2d>(t);
        any = true;
      }
      t += c.num_params;
    }
  };
  add(em.base_effects(), em.base_theta().data());
  if (theta != nullptr) add(active, theta);
  const Vec3 g = any ? kinematics::TiltedGravity(em.g_base(), phi[0], phi[1]) : em.g_base();
  return -g.normalized();
}

Eigen::Matrix<double, 3, 2> NormalPlane(const Vec3& up) {
  Vec3 a1, a2;
  kinematics::GravityTiltAxes(-up, &a1, &a2);
  Eigen::Matrix<double, 3, 2> B;
  B << a1, a2;
  return B;
}

Eigen::Vector2d Project(const CameraModel& cam, const lie::SE3& T_base_cam, const Vec3& p_base) {
  const Vec3 p = T_base_cam.rotation().transpose() * (p_base - T_base_cam.translation());
  const double z = std::max(p.z(), 1e-6);
  const PinholeCamera& k = cam.intrinsics;
  return Eigen::Vector2d(k.fx * p.x() / z + k.cx, k.fy * p.y() / z + k.cy);
}

namespace {

// The measured point and orientation of a point or pose row in the base frame, with the
// measurement frames at T_base_frame.
Vec3 MeasuredPoint(const Observation& o, const std::vector<lie::SE3>& T_base_frame) {
  return o.frame < 0 ? o.p_base : T_base_frame[o.frame] * o.p_frame;
}
Mat3 MeasuredRotation(const Observation& o, const std::vector<lie::SE3>& T_base_frame) {
  return o.frame < 0 ? o.R_base.get() : T_base_frame[o.frame].rotation() * o.R_frame.get();
}

// The marker's point: the predicted frame's origin moved by the marker's fitted offset, if any.
Vec3 MarkerPoint(const lie::SE3& T, const std::vector<Vec3>& d_marker, int point) {
  return d_marker.empty() ? T.translation() : T * d_marker[point];
}

// The prior's standard deviation of each entry of xi = [rho; theta].
Vec6 PriorStd(const MeasurementFrame& f) {
  Vec6 s;
  s << Vec3::Constant(f.prior_std_m), Vec3::Constant(f.prior_std_rad);
  return s;
}

}  // namespace

Problem::Problem(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                 const std::vector<int>& active, const std::vector<Eigen::MatrixXd>& basis,
                 const IdentifyOptions& opt, const std::vector<int>* rows)
    : em_(em), data_(data), loads_(loads), rows_(rows), active_(active), opt_(opt) {
  if (rows && !data.groups.empty()) {
    throw std::invalid_argument("Problem: a row subset of data with groups needs Subset");
  }
  basis_.resize(active.size());
  for (size_t e = 0; e < active.size(); ++e) {
    const int np = em.candidates()[active[e]].num_params;
    basis_[e] =
        e < basis.size() && basis[e].size() > 0 ? basis[e] : Eigen::MatrixXd::Identity(np, np);
    num_alpha_ += static_cast<int>(basis_[e].cols());
    num_theta_ += np;
  }
  offset_.reserve(num_rows());
  int o = 0;
  for (size_t i = 0; i < num_rows(); ++i) {
    offset_.push_back(o);
    o += RowDim(row(i));
  }
  rows_dim_ = o;
  prior_row_.assign(data.frames.size(), -1);
  for (size_t f = 0; f < data.frames.size(); ++f) {
    if (!data.frames[f].has_prior) continue;
    prior_row_[f] = rows_dim_ + static_cast<int>(data.distances.size()) + 6 * num_priors_;
    ++num_priors_;
  }
  offset_col_.assign(data.offset_unknown.size(), -1);
  for (size_t k = 0; k < data.offset_unknown.size(); ++k) {
    if (!data.offset_unknown[k]) continue;
    offset_col_[k] = frame_col(static_cast<int>(data.frames.size())) + 3 * num_offsets_;
    ++num_offsets_;
  }
}

std::vector<Vec3> Problem::MarkerOffsets(const Eigen::VectorXd& x) const {
  std::vector<Vec3> d;
  if (num_offsets_ == 0) return d;
  d.assign(offset_col_.size(), Vec3::Zero());
  for (size_t k = 0; k < d.size(); ++k) {
    if (offset_col_[k] >= 0) d[k] = x.segment<3>(offset_col_[k]);
  }
  return d;
}

std::vector<lie::SE3> Problem::FramePoses(const Eigen::VectorXd& x) const {
  std::vector<lie::SE3> T(data_.frames.size());
  for (size_t f = 0; f < T.size(); ++f) {
    const Vec6 xi = x.segment<6>(frame_col(static_cast<int>(f)));
    T[f] = data_.frames[f].T_ref * lie::SE3::Exp(xi);
  }
  return T;
}

Eigen::VectorXd Problem::Theta(const Eigen::VectorXd& x) const {
  Eigen::VectorXd theta(num_theta_);
  int a = 0, t = 0;
  for (const Eigen::MatrixXd& B : basis_) {
    theta.segment(t, B.rows()) = B * x.segment(a, B.cols());
    a += static_cast<int>(B.cols());
    t += static_cast<int>(B.rows());
  }
  return theta;
}

Eigen::VectorXd Problem::Alpha(const Eigen::VectorXd& theta) const {
  Eigen::VectorXd alpha = Eigen::VectorXd::Zero(num_alpha_);
  int a = 0, t = 0;
  for (const Eigen::MatrixXd& B : basis_) {
    if (t + B.rows() <= theta.size() && B.cols() > 0) {
      alpha.segment(a, B.cols()) = B.colPivHouseholderQr().solve(theta.segment(t, B.rows()));
    }
    a += static_cast<int>(B.cols());
    t += static_cast<int>(B.rows());
  }
  return alpha;
}

int Problem::threads() const { return PassThreads(static_cast<int>(num_rows()), opt_.threads); }

void Problem::Poses(const Eigen::VectorXd& theta, std::vector<lie::SE3>* T) const {
  T->resize(num_rows());
  ForEachRowChunk(static_cast<int>(num_rows()), threads(), [&](int begin, int end) {
    EffectModel::Workspace ws = em_.MakeWorkspace();
    for (int r = begin; r < end; ++r) {
      const Observation& o = row(r);
      (*T)[r] = em_.PredictPose(o.q, loads(r, ws), active_, theta.data(), ws, o.point);
    }
  });
}

Eigen::VectorXd Problem::ResidualsAt(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                                     const std::vector<int>& active) const {
  Eigen::VectorXd r(num_residuals());
  const lie::SE3 T_base_cam =
      data_.camera.present ? CameraPose(em_, data_, active, theta.data()) : lie::SE3();
  const auto group_point = [&](int g) -> Vec3 { return x.segment<3>(num_alpha_ + 3 * g); };
  const std::vector<lie::SE3> T_base_frame = FramePoses(x);
  const std::vector<Vec3> d_marker = MarkerOffsets(x);
  const Vec3 up = GravityUp(em_, active, theta.data());
  const Eigen::Matrix<double, 3, 2> B = NormalPlane(up);
  ForEachRowChunk(static_cast<int>(num_rows()), threads(), [&](int begin, int end) {
    EffectModel::Workspace ws = em_.MakeWorkspace();
    for (int i = begin; i < end; ++i) {
      const Observation& o = row(i);
      const lie::SE3 T = em_.PredictPose(o.q, loads(i, ws), active, theta.data(), ws, o.point);
      const int k = offset_[i];
      const Vec3 p = MarkerPoint(T, d_marker, o.point);
      switch (o.type) {
        case ObservationType::kGroup:
          r.segment<3>(k) = (p - group_point(o.group)) / opt_.point_std_m;
          break;
        case ObservationType::kPoint:
          r.segment<3>(k) = (p - MeasuredPoint(o, T_base_frame)) / opt_.point_std_m;
          break;
        case ObservationType::kPose:
          r.segment<3>(k) = (p - MeasuredPoint(o, T_base_frame)) / opt_.point_std_m;
          r.segment<3>(k + 3) =
              lie::SO3Log(MeasuredRotation(o, T_base_frame).transpose() * T.rotation()) /
              opt_.rotation_std_rad;
          break;
        case ObservationType::kPixel:
          // The camera sees the declared point (a marker offset is for point and pose rows).
          r.segment<2>(k) =
              (Project(data_.camera, T_base_cam, T.translation()) - o.uv) / opt_.pixel_std_px;
          break;
        case ObservationType::kGravity:
          // The measured up seen in the base frame against the base's up, in the plane normal
          // to it (2 entries: the rotation about up is not measured).
          r.segment<2>(k) = B.transpose() * (T.rotation() * o.up() - up) / opt_.gravity_std_rad;
          break;
      }
    }
  });
  for (size_t k = 0; k < data_.distances.size(); ++k) {
    const GroupDistance& d = data_.distances[k];
    r[rows_dim_ + k] =
        ((group_point(d.a) - group_point(d.b)).norm() - d.distance_m) / opt_.distance_std_m;
  }
  for (size_t f = 0; f < data_.frames.size(); ++f) {
    if (prior_row_[f] < 0) continue;
    r.segment<6>(prior_row_[f]) =
        x.segment<6>(frame_col(static_cast<int>(f))).cwiseQuotient(PriorStd(data_.frames[f]));
  }
  return r;
}

Eigen::VectorXd Problem::Residuals(const Eigen::VectorXd& x) const {
  return ResidualsAt(x, Theta(x), active_);
}

namespace {

// Whitened residual change of row o, predicted pose T, per unit change (w, d p) of the point
// frame's pose (d R = [w]x R; columns: w, then d p). A pose row's rotation residual r =
// Log(R_obs^T R) moves by Jr^-1(r) R^T w (d Exp(r) = Exp(r) [Jr(r) dr]); a pixel by the
// pinhole's derivative at the camera-frame point (z held at its floor, as Project); a gravity
// row's B^T (R u - up) by -B^T [R u]x w (d (R u) = [w]x R u), B = NormalPlane(up).
using RowMap = Eigen::Matrix<double, Eigen::Dynamic, 6, 0, 6, 6>;
void RowTangentMap(const Observation& o, const lie::SE3& T, const Mat3& R_base_meas,
                   const CameraModel& cam, const lie::SE3& T_base_cam, const Vec3& up,
                   const IdentifyOptions& opt, RowMap* G) {
  switch (o.type) {
    case ObservationType::kGroup:
    case ObservationType::kPoint:
      G->resize(3, 6);
      G->leftCols<3>().setZero();
      G->rightCols<3>() = Mat3::Identity() / opt.point_std_m;
      break;
    case ObservationType::kPose: {
      G->resize(6, 6);
      G->setZero();
      G->topRightCorner<3, 3>() = Mat3::Identity() / opt.point_std_m;
      const Vec3 r = lie::SO3Log(R_base_meas.transpose() * T.rotation());
      G->bottomLeftCorner<3, 3>() =
          lie::SO3RightJacobianInverse(r) * T.rotation().transpose() / opt.rotation_std_rad;
      break;
    }
    case ObservationType::kPixel: {
      const Mat3 Rt = T_base_cam.rotation().transpose();
      const Vec3 p = Rt * (T.translation() - T_base_cam.translation());
      const bool floor = !(p.z() > 1e-6);
      const double z = std::max(p.z(), 1e-6);
      Eigen::Matrix<double, 2, 3> dproj;
      const PinholeCamera& k = cam.intrinsics;
      dproj << k.fx / z, 0.0, floor ? 0.0 : -k.fx * p.x() / (z * z),  //
          0.0, k.fy / z, floor ? 0.0 : -k.fy * p.y() / (z * z);
      G->resize(2, 6);
      G->leftCols<3>().setZero();
      G->rightCols<3>() = dproj * Rt / opt.pixel_std_px;
      break;
    }
    case ObservationType::kGravity:
      G->resize(2, 6);
      G->rightCols<3>().setZero();
      G->leftCols<3>() =
          -NormalPlane(up).transpose() * lie::Skew(T.rotation() * o.up()) / opt.gravity_std_rad;
      break;
  }
}

}  // namespace

Eigen::MatrixXd Problem::TangentColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                                        const std::vector<int>& cs) const {
  Eigen::MatrixXd D = Eigen::MatrixXd::Zero(num_residuals(), NumTheta(em_, cs));
  std::vector<double*> cols(D.cols());
  for (Eigen::Index k = 0; k < D.cols(); ++k) cols[k] = D.col(k).data();
  TangentColumns(x, theta, cs, cols);
  return D;
}

void Problem::TangentColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                             const std::vector<int>& cs, const std::vector<double*>& cols,
                             std::vector<lie::SE3>* poses, int row_begin, int row_end,
                             int base) const {
  if (row_end < 0) row_end = static_cast<int>(num_rows());
  if (poses) poses->resize(num_rows());
  const std::vector<lie::SE3> T_base_frame = FramePoses(x);
  const std::vector<Vec3> d_marker = MarkerOffsets(x);
  const lie::SE3 T_base_cam =
      data_.camera.present ? CameraPose(em_, data_, active_, theta.data()) : lie::SE3();
  const Vec3 up = GravityUp(em_, active_, theta.data());
  ForEachRowChunk(row_end - row_begin, threads(), [&](int chunk_begin, int chunk_end) {
    EffectModel::Workspace ws = em_.MakeWorkspace();
    std::vector<EffectModel::Tangent> tangent(cols.size());
    RowMap G(3, 6);
    for (int i = row_begin + chunk_begin; i < row_begin + chunk_end; ++i) {
      const Observation& o = row(i);
      const lie::SE3 T = em_.PoseTangents(o.q, loads(i, ws), active_, theta.data(), cs, ws,
                                          tangent.data(), o.point);
      if (poses) (*poses)[i] = T;
      if (!d_marker.empty() && UnitOf(o.type) == RowUnit::kMetres) {
        // The marker turns with its frame: d p += w x (R d).
        const Vec3 lever = T.rotation() * d_marker[o.point];
        for (EffectModel::Tangent& t : tangent) t.dp += t.w.cross(lever);
      }
      const Mat3 R_base_meas =
          o.type == ObservationType::kPose ? MeasuredRotation(o, T_base_frame) : Mat3::Identity();
      RowTangentMap(o, T, R_base_meas, data_.camera, T_base_cam, up, opt_, &G);
      for (size_t k = 0; k < cols.size(); ++k) {
        // Through a fixed-size vector: Eigen picks its summation order by the destination's
        // alignment, and a column must not depend on which others are computed with it.
        Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 6, 1> dr =
            G.leftCols<3>() * tangent[k].w + G.rightCols<3>() * tangent[k].dp;
        Eigen::Map<Eigen::VectorXd>(cols[k] + offset_[i] - base, G.rows()) = dr;
      }
    }
  });
}

void Problem::NumericEffectColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta, size_t e,
                                   int col, int t, Eigen::MatrixXd* J) const {
  const Eigen::MatrixXd& B = basis_[e];
  const double step = em_.candidates()[active_[e]].step;
  for (int k = 0; k < B.cols(); ++k) {
    Eigen::VectorXd tp = theta, tm = theta;
    tp.segment(t, B.rows()) += step * B.col(k);
    tm.segment(t, B.rows()) -= step * B.col(k);
    J->col(col + k) = (ResidualsAt(x, tp, active_) - ResidualsAt(x, tm, active_)) / (2 * step);
  }
}

void Problem::PointColumns(const Eigen::VectorXd& x, Eigen::MatrixXd* J) const {
  for (size_t r = 0; r < num_rows(); ++r) {
    if (row(r).type == ObservationType::kGroup) {
      J->block<3, 3>(offset_[r], num_alpha_ + 3 * row(r).group) =
          -Mat3::Identity() / opt_.point_std_m;
    }
  }
  for (size_t k = 0; k < data_.distances.size(); ++k) {
    const GroupDistance& d = data_.distances[k];
    const Vec3 diff = x.segment<3>(num_alpha_ + 3 * d.a) - x.segment<3>(num_alpha_ + 3 * d.b);
    const double len = diff.norm();
    if (len < 1e-12) continue;
    const Eigen::RowVector3d u = diff.transpose() / (len * opt_.distance_std_m);
    const int row = rows_dim_ + static_cast<int>(k);
    J->block<1, 3>(row, num_alpha_ + 3 * d.a) += u;
    J->block<1, 3>(row, num_alpha_ + 3 * d.b) -= u;
  }
}

void Problem::FrameColumns(const Eigen::VectorXd& x, Eigen::MatrixXd* J) const {
  if (data_.frames.empty()) return;
  const std::vector<lie::SE3> T_base_frame = FramePoses(x);
  std::vector<Mat6> J_tangent_xi(data_.frames.size());
  for (size_t f = 0; f < data_.frames.size(); ++f) {
    J_tangent_xi[f] = lie::SE3RightJacobian(x.segment<6>(frame_col(static_cast<int>(f))));
  }
  const Eigen::VectorXd theta = Theta(x);
  EffectModel::Workspace ws = em_.MakeWorkspace();
  for (size_t i = 0; i < num_rows(); ++i) {
    const Observation& o = row(i);
    if (o.frame < 0) continue;
    // The measured point T_base_frame Exp(d) p_frame moves by R (d_rho - [p_frame]x d_theta),
    // d = Jr(xi) d_xi; the residual is prediction minus measurement.
    const Mat3& R = T_base_frame[o.frame].rotation();
    Eigen::Matrix<double, 3, 6> J_p_tangent;
    J_p_tangent << R, -R * lie::Skew(o.p_frame);
    const int col = frame_col(o.frame);
    J->block<3, 6>(offset_[i], col) = -J_p_tangent * J_tangent_xi[o.frame] / opt_.point_std_m;
    if (o.type != ObservationType::kPose) continue;
    // The measured orientation R R_frame turns to R_meas Exp(R_frame^T d_theta), and
    // Log(Exp(-a) Exp(r)) = r - Jl^-1(r) a to first order.
    const lie::SE3 T = em_.PredictPose(o.q, loads(i, ws), active_, theta.data(), ws, o.point);
    const Vec3 r = lie::SO3Log(MeasuredRotation(o, T_base_frame).transpose() * T.rotation());
    J->block<3, 6>(offset_[i] + 3, col) =
        -lie::SO3LeftJacobianInverse(r) * o.R_frame.get().transpose() *
        J_tangent_xi[o.frame].bottomRows<3>() / opt_.rotation_std_rad;
  }
  for (size_t f = 0; f < data_.frames.size(); ++f) {
    if (prior_row_[f] < 0) continue;
    J->block<6, 6>(prior_row_[f], frame_col(static_cast<int>(f))) =
        PriorStd(data_.frames[f]).cwiseInverse().asDiagonal();
  }
}

void Problem::OffsetColumns(const Eigen::VectorXd& x, const std::vector<lie::SE3>& poses,
                            Eigen::MatrixXd* J) const {
  if (num_offsets_ == 0) return;
  std::vector<lie::SE3> predicted;
  if (poses.empty()) Poses(Theta(x), &predicted);
  const std::vector<lie::SE3>& T = poses.empty() ? predicted : poses;
  for (size_t i = 0; i < num_rows(); ++i) {
    const int col = offset_col(row(i).point);
    if (col < 0 || UnitOf(row(i).type) != RowUnit::kMetres) continue;
    // p = T d: d p / d d = R (a pose row's orientation does not depend on it).
    J->block<3, 3>(offset_[i], col) = T[i].rotation() / opt_.point_std_m;
  }
}

Eigen::MatrixXd Problem::Jacobian(const Eigen::VectorXd& x) const {
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(num_residuals(), num_params());
  const Eigen::VectorXd theta = Theta(x);
  std::vector<int> analytic;
  for (int c : active_) {
    if (em_.HasTangent(c, active_)) analytic.push_back(c);
  }
  // An effect fitted in all its directions takes its tangent columns straight into J (no copy
  // of them); the others go through their full-parameter columns and their basis.
  const std::vector<char> direct = DirectColumns();
  // The tangent pass predicts every row's pose (the same operations as Poses): the offsets'
  // columns take them from there.
  std::vector<lie::SE3> poses;
  if (!analytic.empty()) {
    ReducedColumns(x, theta, analytic, direct, num_offsets_ > 0 ? &poses : nullptr, &J);
  }
  int col = 0, t = 0;
  for (size_t e = 0; e < active_.size(); ++e) {
    const Eigen::MatrixXd& B = basis_[e];
    if (em_.HasTangent(active_[e], active_) && direct[e]) {
      // Adding +0 turns -0 into +0 as the product with the identity did: the same bits.
      J.middleCols(col, B.cols()).array() += 0.0;
    } else if (!em_.HasTangent(active_[e], active_)) {
      NumericEffectColumns(x, theta, e, col, t, &J);
    }
    col += static_cast<int>(B.cols());
    t += static_cast<int>(B.rows());
  }
  PointColumns(x, &J);
  FrameColumns(x, &J);
  OffsetColumns(x, poses, &J);
  return J;
}

void Problem::ReducedColumns(const Eigen::VectorXd& x, const Eigen::VectorXd& theta,
                             const std::vector<int>& analytic, const std::vector<char>& direct,
                             std::vector<lie::SE3>* poses, Eigen::MatrixXd* J) const {
  int reduced = 0;
  for (size_t e = 0; e < active_.size(); ++e) {
    if (em_.HasTangent(active_[e], active_) && !direct[e]) reduced += basis_[e].rows();
  }
  // Blocks of opt.row_block rows (the last takes the rest), or all rows at once when that is one
  // block: then the product spans the distance and prior rows too, as Eigen sized it before.
  const int n = static_cast<int>(num_rows());
  const bool whole = reduced == 0 || n < 2 * opt_.row_block;
  for (int begin = 0; begin < n;) {
    const int end = whole || n - begin < 2 * opt_.row_block ? n : begin + opt_.row_block;
    const int r0 = whole ? 0 : offset_[begin];
    const int r1 = whole ? num_residuals() : (end < n ? offset_[end] : rows_dim_);
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(r1 - r0, reduced);
    std::vector<double*> cols;
    int col = 0, d = 0;
    for (size_t e = 0; e < active_.size(); ++e) {
      for (Eigen::Index k = 0; em_.HasTangent(active_[e], active_) && k < basis_[e].rows(); ++k) {
        cols.push_back(direct[e] ? J->col(col + k).data() + r0 : D.col(d++).data());
      }
      col += static_cast<int>(basis_[e].cols());
    }
    TangentColumns(x, theta, analytic, cols, poses, begin, end, r0);
    col = 0, d = 0;
    for (size_t e = 0; e < active_.size(); ++e) {
      const Eigen::MatrixXd& B = basis_[e];
      if (em_.HasTangent(active_[e], active_) && !direct[e]) {
        J->block(r0, col, r1 - r0, B.cols()).noalias() = D.middleCols(d, B.rows()) * B;
        d += static_cast<int>(B.rows());
      }
      col += static_cast<int>(B.cols());
    }
    begin = end;
  }
}

std::vector<char> Problem::DirectColumns() const {
  std::vector<char> direct(active_.size(), 0);
  for (size_t e = 0; e < active_.size(); ++e) {
    const Eigen::MatrixXd& B = basis_[e];
    // Eigen multiplies coefficient by coefficient below this size (EIGEN_GEMM_TO_COEFFBASED_
    // THRESHOLD), which keeps a -0 the identity's product elsewhere turns into +0.
    const bool gemm = num_residuals() + 2 * B.cols() >= 20;
    direct[e] = gemm && B.rows() == B.cols() && B == Eigen::MatrixXd::Identity(B.rows(), B.cols());
  }
  return direct;
}

Eigen::MatrixXd Problem::NumericJacobian(const Eigen::VectorXd& x) const {
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(num_residuals(), num_params());
  const Eigen::VectorXd theta = Theta(x);
  int col = 0, t = 0;
  for (size_t e = 0; e < active_.size(); ++e) {
    NumericEffectColumns(x, theta, e, col, t, &J);
    col += static_cast<int>(basis_[e].cols());
    t += static_cast<int>(basis_[e].rows());
  }
  PointColumns(x, &J);
  FrameColumns(x, &J);
  OffsetColumns(x, {}, &J);
  return J;
}

Eigen::MatrixXd Problem::CandidateColumns(const Eigen::VectorXd& x, int c) const {
  if (!em_.HasTangent(c, active_)) return NumericCandidateColumns(x, c);
  // Added at zero, c changes no prediction: its derivatives at the active effects' theta.
  return TangentColumns(x, Theta(x), {c});
}

std::vector<Eigen::MatrixXd> Problem::CandidateColumns(const Eigen::VectorXd& x,
                                                       const std::vector<int>& cs) const {
  std::vector<int> analytic;
  for (int c : cs) {
    if (em_.HasTangent(c, active_)) analytic.push_back(c);
  }
  // The analytic columns go straight into their candidate's matrix (no copy of them all).
  std::vector<Eigen::MatrixXd> out(cs.size());
  std::vector<double*> cols;
  for (size_t i = 0; i < cs.size(); ++i) {
    if (!em_.HasTangent(cs[i], active_)) continue;
    out[i] = Eigen::MatrixXd::Zero(num_residuals(), em_.candidates()[cs[i]].num_params);
    for (Eigen::Index k = 0; k < out[i].cols(); ++k) cols.push_back(out[i].col(k).data());
  }
  if (!analytic.empty()) TangentColumns(x, Theta(x), analytic, cols);
  for (size_t i = 0; i < cs.size(); ++i) {
    if (!em_.HasTangent(cs[i], active_)) out[i] = NumericCandidateColumns(x, cs[i]);
  }
  return out;
}

Eigen::MatrixXd Problem::NumericCandidateColumns(const Eigen::VectorXd& x, int c) const {
  const Candidate& cand = em_.candidates()[c];
  std::vector<int> act = active_;
  act.push_back(c);
  Eigen::VectorXd theta(num_theta_ + cand.num_params);
  theta << Theta(x), Eigen::VectorXd::Zero(cand.num_params);
  Eigen::MatrixXd out(num_residuals(), cand.num_params);
  for (int k = 0; k < cand.num_params; ++k) {
    Eigen::VectorXd tp = theta, tm = theta;
    tp[num_theta_ + k] += cand.step;
    tm[num_theta_ + k] -= cand.step;
    out.col(k) = (ResidualsAt(x, tp, act) - ResidualsAt(x, tm, act)) / (2 * cand.step);
  }
  return out;
}

Fit MakeFit(const Problem& pr, const std::vector<int>& active, const Eigen::VectorXd& x,
            double rss) {
  const int G = (pr.frame_col(0) - pr.num_alpha()) / 3;
  Fit f;
  f.active = active;
  for (size_t e = 0; e < active.size(); ++e) f.basis.push_back(pr.basis(e));
  f.theta = pr.Theta(x);
  f.group_points.resize(G);
  for (int g = 0; g < G; ++g) f.group_points[g] = x.segment<3>(pr.num_alpha() + 3 * g);
  f.T_base_frames = pr.FramePoses(x);
  f.marker_offsets = pr.MarkerOffsets(x);
  f.rss = rss;
  f.num_residuals = pr.num_residuals();
  f.num_params = pr.num_params();
  f.bic = Bic(rss, f.num_residuals, pr.num_params());
  return f;
}

void SetFrameStates(const Problem& pr, const Fit& fit, Eigen::VectorXd* x) {
  const std::vector<MeasurementFrame>& frames = pr.data().frames;
  for (size_t f = 0; f < frames.size(); ++f) {
    const int col = pr.frame_col(static_cast<int>(f));
    x->segment<6>(col) = f < fit.T_base_frames.size()
                             ? (frames[f].T_ref.Inverse() * fit.T_base_frames[f]).Log()
                             : Vec6::Zero();
  }
  for (size_t k = 0; k < pr.data().offset_unknown.size(); ++k) {
    const int col = pr.offset_col(static_cast<int>(k));
    if (col < 0) continue;
    x->segment<3>(col) = k < fit.marker_offsets.size() ? fit.marker_offsets[k] : Vec3::Zero();
  }
}

Eigen::VectorXd StateOf(const Problem& pr, const Fit& fit) {
  Eigen::VectorXd x(pr.num_params());
  x.head(pr.num_alpha()) = pr.Alpha(fit.theta);
  for (size_t g = 0; g < fit.group_points.size(); ++g) {
    x.segment<3>(pr.num_alpha() + 3 * g) = fit.group_points[g];
  }
  SetFrameStates(pr, fit, &x);
  return x;
}

bool Problem::InRowBlocks() const {
  return num_rows() >= 2 * static_cast<size_t>(opt_.row_block) && data_.groups.empty();
}

void Problem::ForEachRowBlock(const std::function<void(const Problem&, int)>& fn) const {
  const int n = static_cast<int>(num_rows());
  if (!InRowBlocks()) {
    fn(*this, 0);
    return;
  }
  std::vector<int> rows;
  for (int begin = 0; begin < n;) {
    const int end = n - begin < 2 * opt_.row_block ? n : begin + opt_.row_block;
    rows.clear();
    for (int i = begin; i < end; ++i) rows.push_back(static_cast<int>(RowIndex(i)));
    const Problem block(em_, data_, loads_, active_, basis_, opt_, &rows);
    fn(block, offset_[begin]);
    begin = end;
  }
}

void NormalEquations(const Problem& pr, const Eigen::VectorXd& x, const Eigen::VectorXd* r,
                     Eigen::MatrixXd* A, Eigen::VectorXd* g) {
  const int n = pr.num_params();
  pr.ForEachRowBlock([&](const Problem& block, int at) {
    const Eigen::MatrixXd J = block.Jacobian(x);
    if (&block == &pr) {
      *A = J.transpose() * J;
      if (r) *g = J.transpose() * *r;
      return;
    }
    if (A->rows() != n) {
      A->setZero(n, n);
      if (r) g->setZero(n);
    }
    const int d = block.rows_dim();
    A->noalias() += J.topRows(d).transpose() * J.topRows(d);
    if (r) g->noalias() += J.topRows(d).transpose() * r->segment(at, d);
    const int priors = static_cast<int>(J.rows()) - d;
    if (at == 0 && priors > 0) {
      A->noalias() += J.bottomRows(priors).transpose() * J.bottomRows(priors);
      if (r) g->noalias() += J.bottomRows(priors).transpose() * r->tail(priors);
    }
  });
}

std::vector<double> RemovalRises(const Problem& pr, const Fit& fit) {
  std::vector<double> rises(fit.active.size(), std::nan(""));
  const Eigen::VectorXd x = StateOf(pr, fit);
  Eigen::MatrixXd A;
  NormalEquations(pr, x, nullptr, &A, nullptr);
  // Scaled to unit diagonal: the unknowns' units differ by orders of magnitude.
  const Eigen::VectorXd d = A.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  A = d.asDiagonal() * A * d.asDiagonal();
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(A);
  if (ldlt.info() != Eigen::Success) return rises;
  const Eigen::MatrixXd Sigma = ldlt.solve(Eigen::MatrixXd::Identity(A.rows(), A.cols()));
  if (!Sigma.allFinite()) return rises;
  for (size_t e = 0, off = 0; e < fit.active.size(); ++e) {
    const int m = static_cast<int>(pr.basis(e).cols());
    const Eigen::VectorXd a = x.segment(off, m).cwiseQuotient(d.segment(off, m));
    const Eigen::LDLT<Eigen::MatrixXd> S(Sigma.block(off, off, m, m));
    const double rise = a.dot(S.solve(a));
    off += m;
    if (S.info() == Eigen::Success && std::isfinite(rise) && rise >= 0.0) rises[e] = rise;
  }
  return rises;
}

Fit FitEffects(const EffectModel& em, const DataSet& data, const RowLoads& loads,
               const std::vector<int>& active, const std::vector<Eigen::MatrixXd>& basis,
               const Eigen::VectorXd& init, const IdentifyOptions& opt,
               const std::vector<int>* rows) {
  const Problem pr(em, data, loads, active, basis, opt, rows);
  const int G = static_cast<int>(data.groups.size());
  const int nt = pr.num_theta();
  Eigen::VectorXd theta0 = Eigen::VectorXd::Zero(nt);
  const int n_init = std::min<int>(nt, static_cast<int>(init.size()));
  theta0.head(n_init) = init.head(n_init);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(pr.num_params());
  x.head(pr.num_alpha()) = pr.Alpha(theta0);
  if (G > 0) {
    // Group points start at their rows' mean.
    std::vector<lie::SE3> T;
    pr.Poses(pr.Theta(x), &T);
    std::vector<Vec3> points(T.size());
    for (size_t r = 0; r < T.size(); ++r) points[r] = T[r].translation();
    const std::vector<Vec3> mean = GroupMeans(data, points);
    for (int g = 0; g < G; ++g) x.segment<3>(pr.num_alpha() + 3 * g) = mean[g];
  }
  Eigen::VectorXd r = pr.Residuals(x);
  double rss = r.squaredNorm();
  double lambda = 1e-3;
  for (int it = 0; it < opt.max_iterations; ++it) {
    Eigen::MatrixXd A;
    Eigen::VectorXd g;
    NormalEquations(pr, x, &r, &A, &g);
    bool improved = false;
    for (int tries = 0; tries < 12; ++tries) {
      Eigen::MatrixXd Ad = A;
      for (int k = 0; k < A.rows(); ++k) Ad(k, k) += lambda * std::max(A(k, k), 1e-12);
      const Eigen::VectorXd dx = -Ad.ldlt().solve(g);
      if (!dx.allFinite()) {
        lambda *= 10;
        continue;
      }
      const Eigen::VectorXd xn = x + dx;
      const Eigen::VectorXd rn = pr.Residuals(xn);
      const double rss_n = rn.squaredNorm();
      if (std::isfinite(rss_n) && rss_n < rss) {
        const double gain = rss - rss_n;
        x = xn;
        r = rn;
        rss = rss_n;
        lambda = std::max(lambda / 3.0, 1e-12);
        improved = gain > 1e-12 * rss;
        break;
      }
      lambda *= 4.0;
    }
    if (!improved) break;
  }
  return MakeFit(pr, active, x, rss);
}

Fit ScreenWith(const EffectModel& em, const DataSet& data, const RowLoads& loads, const Fit& fit,
               int c, const Eigen::MatrixXd& basis_c, const Eigen::MatrixXd& J_fit,
               const Eigen::MatrixXd& J_c, const Eigen::VectorXd& r_fit,
               const IdentifyOptions& opt) {
  std::vector<int> act = fit.active;
  act.push_back(c);
  std::vector<Eigen::MatrixXd> basis = fit.basis;
  basis.resize(fit.active.size());
  basis.push_back(basis_c);
  const Problem pr(em, data, loads, act, basis, opt);
  const int m = static_cast<int>(basis_c.cols());
  const int n = pr.num_params();
  const int na = static_cast<int>(J_fit.cols()) - (n - pr.num_alpha());  // fit's alpha
  Eigen::VectorXd theta0 = Eigen::VectorXd::Zero(pr.num_theta());
  theta0.head(fit.theta.size()) = fit.theta;
  Eigen::VectorXd x(n);
  x.head(pr.num_alpha()) = pr.Alpha(theta0);
  for (size_t g = 0; g < fit.group_points.size(); ++g) {
    x.segment<3>(pr.num_alpha() + 3 * g) = fit.group_points[g];
  }
  SetFrameStates(pr, fit, &x);
  // A Gauss-Newton step, undamped: a candidate nearly equivalent to a chosen effect (a link's
  // bending beside its joint's compliance) moves along a narrow valley that a damped step
  // (Levenberg-Marquardt's first) barely enters. ObservableBasis keeps such directions well
  // enough apart (rank_tol) for the normal equations.
  Eigen::MatrixXd A;
  Eigen::VectorXd g;
  if (J_fit.rows() < 2 * opt.row_block) {
    Eigen::MatrixXd J(J_fit.rows(), n);
    J << J_fit.leftCols(na), J_c * basis_c, J_fit.rightCols(n - na - m);
    A = J.transpose() * J;
    g = J.transpose() * r_fit;
  } else {
    // Many rows: the products of the columns one screen per thread would otherwise copy whole
    // (fit's columns, then c's in its basis, then the rest: the unknowns' order).
    const int nf = static_cast<int>(J_fit.cols());
    std::vector<int> at(nf);
    for (int k = 0; k < nf; ++k) at[k] = k < na ? k : k + m;
    const Eigen::MatrixXd FF = J_fit.transpose() * J_fit;
    const Eigen::MatrixXd FC = (J_fit.transpose() * J_c) * basis_c;
    const Eigen::VectorXd Fr = J_fit.transpose() * r_fit;
    A.resize(n, n);
    g.resize(n);
    A.block(na, na, m, m) = basis_c.transpose() * (J_c.transpose() * J_c) * basis_c;
    g.segment(na, m) = basis_c.transpose() * (J_c.transpose() * r_fit);
    for (int i = 0; i < nf; ++i) {
      g[at[i]] = Fr[i];
      A.block(at[i], na, 1, m) = FC.row(i);
      A.block(na, at[i], m, 1) = FC.row(i).transpose();
      for (int j = 0; j < nf; ++j) A(at[i], at[j]) = FF(i, j);
    }
  }
  const Eigen::VectorXd dx = -A.ldlt().solve(g);
  if (dx.allFinite()) {
    const Eigen::VectorXd xn = x + dx;
    const double rss = pr.Residuals(xn).squaredNorm();
    if (std::isfinite(rss) && rss < fit.rss) return MakeFit(pr, act, xn, rss);
  }
  return FitWith(em, data, loads, fit, c, basis_c, opt);
}

Fit FitWithout(const EffectModel& em, const DataSet& data, const RowLoads& loads, const Fit& fit,
               size_t e, const IdentifyOptions& opt) {
  std::vector<int> rest;
  std::vector<Eigen::MatrixXd> basis;
  std::vector<double> init;
  int off = 0;
  for (size_t k = 0; k < fit.active.size(); ++k) {
    const int np = em.candidates()[fit.active[k]].num_params;
    if (k != e) {
      rest.push_back(fit.active[k]);
      basis.push_back(k < fit.basis.size() ? fit.basis[k] : Eigen::MatrixXd());
      for (int i = 0; i < np; ++i) init.push_back(fit.theta[off + i]);
    }
    off += np;
  }
  return FitEffects(em, data, loads, rest, basis,
                    Eigen::Map<const Eigen::VectorXd>(init.data(), init.size()), opt);
}

Fit FitWith(const EffectModel& em, const DataSet& data, const RowLoads& loads, const Fit& fit,
            int c, const Eigen::MatrixXd& basis_c, const IdentifyOptions& opt) {
  std::vector<int> act = fit.active;
  act.push_back(c);
  std::vector<Eigen::MatrixXd> basis = fit.basis;
  basis.resize(fit.active.size());
  basis.push_back(basis_c);
  Eigen::VectorXd init = Eigen::VectorXd::Zero(NumTheta(em, act));
  init.head(fit.theta.size()) = fit.theta;
  return FitEffects(em, data, loads, act, basis, init, opt);
}

}  // namespace flexbench::identify
