#include "estimators/kinematics/ppoe_model.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "estimators/error.h"

namespace flexbench::kinematics {
namespace {

// Tolerances of the input checks, relative to the largest entry (covariances) or absolute
// (rotations and axes, which are dimensionless).
constexpr double kSymmetryTol = 1e-9;
constexpr double kPsdTol = 1e-12;
constexpr double kRotationTol = 1e-9;
constexpr double kMinAxisNorm = 1e-9;

std::string Describe(const std::string& model, const std::string& frame) {
  return "PPOE model '" + model + "', frame '" + frame + "'";
}

template <class Derived>
bool AllFinite(const Eigen::MatrixBase<Derived>& m) {
  return m.allFinite();
}

// Returns the symmetrised covariance or throws InputError naming the culprit.
Mat6 ValidatedCovariance(const Mat6& cov, const std::string& where) {
  if (!AllFinite(cov)) {
    throw InputError(where + ": source covariance has a NaN or infinite entry");
  }
  const double scale = std::max(1.0, cov.cwiseAbs().maxCoeff());
  const double asym = (cov - cov.transpose()).cwiseAbs().maxCoeff();
  if (asym > kSymmetryTol * scale) {
    std::ostringstream msg;
    msg << where << ": source covariance is not symmetric (max |S - S^T| = " << asym << ")";
    throw InputError(msg.str());
  }
  const Mat6 sym = 0.5 * (cov + cov.transpose());
  const double min_eig =
      Eigen::SelfAdjointEigenSolver<Mat6>(sym, Eigen::EigenvaluesOnly).eigenvalues().minCoeff();
  if (min_eig < -kPsdTol * scale) {
    std::ostringstream msg;
    msg << where << ": source covariance is not positive semi-definite (smallest eigenvalue "
        << min_eig << ")";
    throw InputError(msg.str());
  }
  return sym;
}

void ValidatePose(const lie::SE3& T, const std::string& where) {
  const Mat3& R = T.rotation();
  if (!AllFinite(R) || !AllFinite(T.translation())) {
    throw InputError(where + ": static transform has a NaN or infinite entry");
  }
  const double orth_err = (R.transpose() * R - Mat3::Identity()).cwiseAbs().maxCoeff();
  if (orth_err > kRotationTol || R.determinant() < 0.0) {
    std::ostringstream msg;
    msg << where
        << ": static transform rotation is not a rotation matrix (max |R^T R - I| = " << orth_err
        << ", det = " << R.determinant() << ")";
    throw InputError(msg.str());
  }
}

}  // namespace

PpoeModel::PpoeModel(std::string name) : name_(std::move(name)) {
  PpoeFrame base;
  base.name = "base";
  base.parent = -1;
  frames_.push_back(base);
}

bool PpoeModel::HasFrame(const std::string& name) const {
  return std::any_of(frames_.begin(), frames_.end(),
                     [&](const PpoeFrame& f) { return f.name == name; });
}

FrameId PpoeModel::FindFrame(const std::string& name) const {
  for (int i = 0; i < num_frames(); ++i) {
    if (frames_[i].name == name) return i;
  }
  throw InputError("PPOE model '" + name_ + "' has no frame named '" + name + "'");
}

FrameId PpoeModel::AddLink(FrameId parent, const std::string& name, const lie::SE3& T_parent_ip,
                           const Joint& joint, const Mat6& source_cov) {
  const std::string where = Describe(name_, name);
  if (name.empty()) throw InputError("PPOE model '" + name_ + "': frame name is empty");
  if (HasFrame(name)) throw InputError(where + ": a frame with this name already exists");
  if (parent < 0 || parent >= num_frames()) {
    throw InputError(where + ": parent frame id " + std::to_string(parent) +
                     " does not exist (the model has " + std::to_string(num_frames()) + " frames)");
  }
  ValidatePose(T_parent_ip, where);

  PpoeFrame f;
  f.name = name;
  f.parent = parent;
  f.T_parent_ip = T_parent_ip;
  f.source_cov = ValidatedCovariance(source_cov, where);
  f.has_source = !f.source_cov.isZero(0.0);
  f.joint = joint;

  if (joint.type != JointType::kFixed) {
    const double norm = joint.axis.norm();
    if (!std::isfinite(norm) || !AllFinite(joint.point) || norm < kMinAxisNorm) {
      std::ostringstream msg;
      msg << where << ": joint axis must be finite and non-zero (got [" << joint.axis.transpose()
          << "], point [" << joint.point.transpose() << "])";
      throw InputError(msg.str());
    }
    f.joint.axis = joint.axis / norm;
    if (joint.type == JointType::kPrismatic) f.joint.point.setZero();
    f.q_index = nq();
  }
  Precompute(&f);
  if (f.q_index >= 0) q_frames_.push_back(num_frames());
  frames_.push_back(f);
  return num_frames() - 1;
}

void PpoeModel::Precompute(PpoeFrame* f, bool move_source) {
  const lie::SE3& T_parent_ip = f->T_parent_ip;
  const Mat3& R_p = T_parent_ip.rotation();
  f->u0 = T_parent_ip.translation();
  const Vec3& w = f->joint.axis;
  if (f->joint.type == JointType::kRevolute) {
    const Vec3& r = f->joint.point;
    f->zeta.segment<3>(kTransIdx) = r.cross(w);
    f->zeta.segment<3>(kRotIdx) = w;
    f->W2 = lie::Skew(w) * lie::Skew(w);
    // R_p [w]x and R_p [w]x^2 column by column: [w]x e_k = w x e_k.
    f->K1 = R_p * lie::Skew(w);
    f->K2 = R_p * f->W2;
    f->u1 = -(f->K1 * r);
    f->u2 = -(f->K2 * r);
  } else if (f->joint.type == JointType::kPrismatic) {
    f->zeta.segment<3>(kTransIdx) = w;
    f->u1 = R_p * w;
  }
  if (move_source) f->source_cov_parent = lie::TransformCovariance(T_parent_ip, f->source_cov);
}

void PpoeModel::SetFixedTransform(FrameId id, const lie::SE3& T_parent_ip, bool move_source) {
  if (id <= kBaseFrame || id >= num_frames()) {
    throw std::invalid_argument("PPOE model '" + name_ + "': SetFixedTransform of frame id " +
                                std::to_string(id) + ", which does not exist");
  }
  PpoeFrame& f = frames_[id];
  f.T_parent_ip = T_parent_ip;
  if (move_source) {
    Precompute(&f, true);
    return;
  }
  // Only the terms that depend on T_parent_ip (the joint's own stay).
  const Mat3& R_p = T_parent_ip.rotation();
  f.u0 = T_parent_ip.translation();
  if (f.joint.type == JointType::kRevolute) {
    f.K1.noalias() = R_p * lie::Skew(f.joint.axis);
    f.K2.noalias() = R_p * f.W2;
    f.u1.noalias() = -(f.K1 * f.joint.point);
    f.u2.noalias() = -(f.K2 * f.joint.point);
  } else if (f.joint.type == JointType::kPrismatic) {
    f.u1.noalias() = R_p * f.joint.axis;
  }
}

void PpoeModel::SetSourceCovariance(FrameId id, const Mat6& source_cov) {
  if (id <= kBaseFrame || id >= num_frames()) {
    throw std::invalid_argument("PPOE model '" + name_ + "': SetSourceCovariance of frame id " +
                                std::to_string(id) + ", which does not exist");
  }
  PpoeFrame& f = frames_[id];
  f.source_cov = source_cov;
  f.has_source = !source_cov.isZero(0.0);
  f.source_cov_parent = lie::TransformCovariance(f.T_parent_ip, source_cov);
}

FrameId PpoeModel::AddFrame(FrameId parent, const std::string& name, const lie::SE3& T_parent_fp,
                            const Mat6& source_cov) {
  return AddLink(parent, name, T_parent_fp, Joint::Fixed(), source_cov);
}

}  // namespace flexbench::kinematics
