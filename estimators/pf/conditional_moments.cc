#include "estimators/pf/conditional_moments.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

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
  if (nq_ > 32) throw std::invalid_argument("ConditionalMoments: more than 32 joints");
  const double s = position_info(0, 0);
  const bool isotropic =
      (position_info - s * Mat3::Identity()).cwiseAbs().maxCoeff() <= 1e-12 * std::abs(s);
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
  a_.assign(total, 0.0);
  b_.assign(total, 0.0);
  mc_.assign(total, 0.0);
  ms_.assign(total, 0.0);
  for (auto& v : axis_) v.assign(total, 0.0);
  for (auto& v : scratch_) v.assign(stride_, 0.0);
}

void ConditionalMoments::Bind(const BatchKinematics& fk) {
  for (int j = 0; j < nq_; ++j) {
    const bool needed = std::find(joint_frames_.begin(), joint_frames_.end(),
                                  joint_frame_ids_[j]) != joint_frames_.end();
    joint_output_[j] = needed ? fk.OutputIndex(joint_frame_ids_[j]) : -1;
  }
}

void ConditionalMoments::Begin(const kinematics::PpoeModel& model, const BatchKinematics& fk,
                               const double* prev_c, const double* prev_s, const double* u,
                               double kappa_v, double kappa_w, int n) {
  prev_c_ = prev_c;
  prev_s_ = prev_s;
  kappa_v_ = kappa_v;
  for (int j = 0; j < nq_; ++j) {
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    cu_[j] = u != nullptr ? kappa_w * std::cos(u[j]) : 0.0;
    su_[j] = u != nullptr ? kappa_w * std::sin(u[j]) : 0.0;
    std::fill(a_.begin() + off, a_.begin() + off + n, 0.0);
    std::fill(b_.begin() + off, b_.begin() + off + n, 0.0);
    const int k = joint_output_[j];
    if (k < 0) continue;
    // The joint's axis line in the world: direction R w, through R r + t.
    const kinematics::Joint& joint = model.frame(joint_frame_ids_[j]).joint;
    double* __restrict w[3] = {&axis_[0][off], &axis_[1][off], &axis_[2][off]};
    double* __restrict o[3] = {&axis_[3][off], &axis_[4][off], &axis_[5][off]};
    for (int r = 0; r < 3; ++r) {
      const double* R0 = fk.R(k, r, 0);
      const double* R1 = fk.R(k, r, 1);
      const double* R2 = fk.R(k, r, 2);
      const double* t = fk.t(k, r);
      for (int i = 0; i < n; ++i) {
        w[r][i] = R0[i] * joint.axis.x() + R1[i] * joint.axis.y() + R2[i] * joint.axis.z();
        o[r][i] =
            R0[i] * joint.point.x() + R1[i] * joint.point.y() + R2[i] * joint.point.z() + t[i];
      }
    }
  }
}

// -|y - o - Rot(w, d) r|^2 / (2 sigma^2) = const + s (y - o)^T Rot(w, d) r, with
// Rot r = cos d r + sin d (w x r) + (1 - cos d) w (w . r).
void ConditionalMoments::AddPosition(const BatchKinematics& fk, int a, int k_frame,
                                     const Vec3& p_frame, const Vec3& p_base, int n) {
  const std::uint32_t joints = position_below_[a] & exact_;
  if (joints == 0) return;
  const double sc = position_scale_;
  double* __restrict p[3] = {scratch_[0].data(), scratch_[1].data(), scratch_[2].data()};
  for (int r = 0; r < 3; ++r) {
    const double* R0 = fk.R(k_frame, r, 0);
    const double* R1 = fk.R(k_frame, r, 1);
    const double* R2 = fk.R(k_frame, r, 2);
    const double* t = fk.t(k_frame, r);
    for (int i = 0; i < n; ++i) {
      p[r][i] = R0[i] * p_frame.x() + R1[i] * p_frame.y() + R2[i] * p_frame.z() + t[i];
    }
  }
  const double y0 = p_base.x(), y1 = p_base.y(), y2 = p_base.z();
  for (int j = 0; j < nq_; ++j) {
    if (!((joints >> j) & 1u)) continue;
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    const double* __restrict w0 = &axis_[0][off];
    const double* __restrict w1 = &axis_[1][off];
    const double* __restrict w2 = &axis_[2][off];
    const double* __restrict o0 = &axis_[3][off];
    const double* __restrict o1 = &axis_[4][off];
    const double* __restrict o2 = &axis_[5][off];
    double* __restrict A = &a_[off];
    double* __restrict B = &b_[off];
    for (int i = 0; i < n; ++i) {
      const double d0 = y0 - o0[i], d1 = y1 - o1[i], d2 = y2 - o2[i];
      const double r0 = p[0][i] - o0[i], r1 = p[1][i] - o1[i], r2 = p[2][i] - o2[i];
      const double dw = d0 * w0[i] + d1 * w1[i] + d2 * w2[i];
      const double rw = r0 * w0[i] + r1 * w1[i] + r2 * w2[i];
      A[i] += sc * (d0 * r0 + d1 * r1 + d2 * r2 - dw * rw);
      // w . (r x d)
      B[i] += sc * (w0[i] * (r1 * d2 - r2 * d1) + w1[i] * (r2 * d0 - r0 * d2) +
                    w2[i] * (r0 * d1 - r1 * d0));
    }
  }
}

// tr(C^T Rot(w, d) R) = tr(G Rot) with G = R C^T: cos d (tr G - w^T G w) + sin d w . v(G) +
// w^T G w, v(G) = (G12 - G21, G20 - G02, G01 - G10).
void ConditionalMoments::AddOrientation(const BatchKinematics& fk, int a, int k_frame,
                                        const Mat3& C, int n) {
  const std::uint32_t joints = orientation_below_[a] & exact_;
  if (joints == 0) return;
  // G = R C^T, entry by entry.
  double* __restrict G[9];
  for (int e = 0; e < 9; ++e) G[e] = scratch_[e].data();
  for (int r = 0; r < 3; ++r) {
    const double* R0 = fk.R(k_frame, r, 0);
    const double* R1 = fk.R(k_frame, r, 1);
    const double* R2 = fk.R(k_frame, r, 2);
    for (int c = 0; c < 3; ++c) {
      const double c0 = C(c, 0), c1 = C(c, 1), c2 = C(c, 2);
      double* __restrict g = G[r * 3 + c];
      for (int i = 0; i < n; ++i) g[i] = R0[i] * c0 + R1[i] * c1 + R2[i] * c2;
    }
  }
  for (int j = 0; j < nq_; ++j) {
    if (!((joints >> j) & 1u)) continue;
    const std::size_t off = static_cast<std::size_t>(j) * stride_;
    const double* __restrict w0 = &axis_[0][off];
    const double* __restrict w1 = &axis_[1][off];
    const double* __restrict w2 = &axis_[2][off];
    double* __restrict A = &a_[off];
    double* __restrict B = &b_[off];
    for (int i = 0; i < n; ++i) {
      const double x = w0[i], y = w1[i], z = w2[i];
      const double Gw0 = G[0][i] * x + G[1][i] * y + G[2][i] * z;
      const double Gw1 = G[3][i] * x + G[4][i] * y + G[5][i] * z;
      const double Gw2 = G[6][i] * x + G[7][i] * y + G[8][i] * z;
      A[i] += G[0][i] + G[4][i] + G[8][i] - (x * Gw0 + y * Gw1 + z * Gw2);
      B[i] += x * (G[5][i] - G[7][i]) + y * (G[6][i] - G[2][i]) + z * (G[1][i] - G[3][i]);
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
      const double zc = kappa_v_ * prev_c_[off + i] + cu_[j] + A * c[i] - B * s[i];
      const double zs = kappa_v_ * prev_s_[off + i] + su_[j] + A * s[i] + B * c[i];
      const double kappa = std::sqrt(zc * zc + zs * zs);
      const double scale = kappa > 1e-300 ? a1_.Evaluate(kappa) / kappa : 0.0;
      mc[i] = scale * zc;
      ms[i] = scale * zs;
    }
  }
}

}  // namespace flexbench::pf
