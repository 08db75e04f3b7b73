#include "estimators/pf/conditional_moments.h"

#include <algorithm>
#include <cmath>

#include "estimators/pf/bessel.h"

namespace flexbench::pf {
namespace {

// The joints whose motion moves `frame` (its own joint included).
std::uint32_t JointsAbove(const kinematics::PpoeModel& model, FrameId frame) {
  std::uint32_t mask = 0;
  for (FrameId f = frame; f != kinematics::kBaseFrame; f = model.frame(f).parent) {
    const int q = model.frame(f).q_index;
    if (q >= 0) mask |= 1u << q;
  }
  return mask;
}

}  // namespace

std::vector<FrameId> ConditionalMoments::JointFrames(
    const kinematics::PpoeModel& model, const std::vector<FrameId>& position_frames,
    const std::vector<FrameId>& orientation_frames) {
  std::uint32_t seen = 0;
  for (FrameId f : position_frames) seen |= JointsAbove(model, f);
  for (FrameId f : orientation_frames) seen |= JointsAbove(model, f);
  std::vector<FrameId> out;
  for (int j = 0; j < model.nq(); ++j) {
    if ((seen >> j) & 1u) out.push_back(model.joint_frame(j));
  }
  return out;
}

ConditionalMoments::ConditionalMoments(const kinematics::PpoeModel& model,
                                       const std::vector<FrameId>& position_frames,
                                       const std::vector<FrameId>& orientation_frames,
                                       const Mat3& position_info, std::size_t stride)
    : nq_(model.nq()), stride_(stride) {
  const double s = position_info(0, 0);
  const bool isotropic = (position_info - s * Mat3::Identity()).cwiseAbs().maxCoeff() <=
                         1e-12 * std::abs(s);
  position_scale_ = s;
  std::uint32_t with_position = 0;
  for (FrameId f : position_frames) {
    position_below_.push_back(JointsAbove(model, f));
    with_position |= position_below_.back();
  }
  for (FrameId f : orientation_frames) orientation_below_.push_back(JointsAbove(model, f));
  const std::uint32_t all = nq_ >= 32 ? ~0u : (1u << nq_) - 1u;
  exact_ = isotropic ? all : all & ~with_position;
  joint_output_.assign(nq_, -1);
  for (int j = 0; j < nq_; ++j) joint_frame_ids_.push_back(model.joint_frame(j));
  joint_frames_ = JointFrames(model, position_frames, orientation_frames);
  const std::size_t total = static_cast<std::size_t>(nq_) * stride_;
  zc_.assign(total, 0.0);
  zs_.assign(total, 0.0);
  a_.assign(total, 0.0);
  b_.assign(total, 0.0);
  mc_.assign(total, 0.0);
  ms_.assign(total, 0.0);
}

void ConditionalMoments::Bind(const BatchKinematics& fk) {
  for (int j = 0; j < nq_; ++j) {
    const bool needed = std::find(joint_frames_.begin(), joint_frames_.end(),
                                  joint_frame_ids_[j]) != joint_frames_.end();
    joint_output_[j] = needed ? fk.OutputIndex(joint_frame_ids_[j]) : -1;
  }
}

void ConditionalMoments::Axis(const kinematics::PpoeModel& model, const BatchKinematics& fk,
                              int j, int i, Vec3* w, Vec3* o) const {
  const int k = joint_output_[j];
  const kinematics::Joint& joint = model.frame(joint_frame_ids_[j]).joint;
  Mat3 R;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = fk.R(k, r, c)[i];
  }
  const Vec3 t(fk.t(k, 0)[i], fk.t(k, 1)[i], fk.t(k, 2)[i]);
  *w = R * joint.axis;
  *o = R * joint.point + t;
}

void ConditionalMoments::Begin(const double* prev_c, const double* prev_s, const double* u,
                               double kappa_v, double kappa_w, int n) {
  for (int j = 0; j < nq_; ++j) {
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    const double cu = u != nullptr ? kappa_w * std::cos(u[j]) : 0.0;
    const double su = u != nullptr ? kappa_w * std::sin(u[j]) : 0.0;
    for (int i = 0; i < n; ++i) {
      zc_[off + i] = kappa_v * prev_c[off + i] + cu;
      zs_[off + i] = kappa_v * prev_s[off + i] + su;
      a_[off + i] = 0.0;
      b_[off + i] = 0.0;
    }
  }
}

// -|y - o - Rot(w, d) r|^2 / (2 sigma^2) = const + s (y - o)^T Rot(w, d) r, with
// Rot r = cos d r + sin d (w x r) + (1 - cos d) w (w . r).
void ConditionalMoments::AddPosition(const kinematics::PpoeModel& model, const BatchKinematics& fk,
                                     int a, int k_frame, const Vec3& p_frame, const Vec3& p_base,
                                     int n) {
  const std::uint32_t joints = position_below_[a] & exact_;
  const double s = position_scale_;
  for (int j = 0; j < nq_; ++j) {
    if (!((joints >> j) & 1u)) continue;
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    for (int i = 0; i < n; ++i) {
      Vec3 p;
      for (int r = 0; r < 3; ++r) {
        p(r) = fk.R(k_frame, r, 0)[i] * p_frame.x() + fk.R(k_frame, r, 1)[i] * p_frame.y() +
               fk.R(k_frame, r, 2)[i] * p_frame.z() + fk.t(k_frame, r)[i];
      }
      Vec3 w, o;
      Axis(model, fk, j, i, &w, &o);
      const Vec3 d = p_base - o;
      const Vec3 r = p - o;
      a_[off + i] += s * (d.dot(r) - d.dot(w) * r.dot(w));
      b_[off + i] += s * w.dot(r.cross(d));
    }
  }
}

// tr(C^T Rot(w, d) R) = tr(G Rot) with G = R C^T: cos d (tr G - w^T G w) + sin d w . v(G) +
// w^T G w, v(G) = (G12 - G21, G20 - G02, G01 - G10).
void ConditionalMoments::AddOrientation(const kinematics::PpoeModel& model,
                                        const BatchKinematics& fk, int a, int k_frame,
                                        const Mat3& C, int n) {
  const std::uint32_t joints = orientation_below_[a] & exact_;
  for (int j = 0; j < nq_; ++j) {
    if (!((joints >> j) & 1u)) continue;
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    for (int i = 0; i < n; ++i) {
      Mat3 R;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) R(r, c) = fk.R(k_frame, r, c)[i];
      }
      const Mat3 G = R * C.transpose();
      Vec3 w, o;
      Axis(model, fk, j, i, &w, &o);
      const Vec3 v(G(1, 2) - G(2, 1), G(2, 0) - G(0, 2), G(0, 1) - G(1, 0));
      a_[off + i] += G.trace() - w.dot(G * w);
      b_[off + i] += w.dot(v);
    }
  }
}

void ConditionalMoments::Finish(const double* cos, const double* sin, int n) {
  for (int j = 0; j < nq_; ++j) {
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    const double* c = cos + off;
    const double* s = sin + off;
    double* mc = mc_.data() + off;
    double* ms = ms_.data() + off;
    if (!exact(j)) {
      std::copy(c, c + n, mc);
      std::copy(s, s + n, ms);
      continue;
    }
    for (int i = 0; i < n; ++i) {
      // a cos(x - x_i) + b sin(x - x_i) = Re(conj((a + i b) e^{i x_i}) e^{i x}).
      const double A = a_[off + i], B = b_[off + i];
      const double zc = zc_[off + i] + A * c[i] - B * s[i];
      const double zs = zs_[off + i] + A * s[i] + B * c[i];
      const double kappa = std::sqrt(zc * zc + zs * zs);
      const double scale = kappa > 1e-300 ? BesselRatioA1(kappa) / kappa : 0.0;
      mc[i] = scale * zc;
      ms[i] = scale * zs;
    }
  }
}

}  // namespace flexbench::pf
