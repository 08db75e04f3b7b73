#include "estimators/pf/batch_kinematics.h"

#include <algorithm>
#include <functional>
#include <map>
#include <utility>

#include "estimators/error.h"

namespace flexbench::pf {
namespace {

using kinematics::JointType;
using kinematics::PpoeFrame;
using kinematics::PpoeModel;

// The nearest frame at or above `frame` that has a joint (kBaseFrame if none) and the constant
// transform from it to `frame`.
std::pair<FrameId, lie::SE3> NearestJointFrame(const PpoeModel& model, FrameId frame) {
  lie::SE3 T = lie::SE3::Identity();
  while (frame != kinematics::kBaseFrame) {
    const PpoeFrame& f = model.frame(frame);
    if (f.joint.type != JointType::kFixed) return {frame, T};
    T = f.T_parent_ip * T;
    frame = f.parent;
  }
  return {kinematics::kBaseFrame, T};
}

}  // namespace

BatchKinematics::BatchKinematics(const PpoeModel& model, const std::vector<FrameId>& outputs,
                                 int capacity)
    : capacity_(capacity) {
  if (capacity <= 0) throw InputError("BatchKinematics: capacity must be > 0");
  std::map<FrameId, int> node_of_frame;
  std::function<int(FrameId)> node_for = [&](FrameId joint_frame) -> int {
    if (joint_frame == kinematics::kBaseFrame) return -1;
    const auto it = node_of_frame.find(joint_frame);
    if (it != node_of_frame.end()) return it->second;
    const PpoeFrame& f = model.frame(joint_frame);
    if (f.joint.type != JointType::kRevolute) {
      throw InputError("BatchKinematics: frame '" + f.name + "' of PPOE model '" + model.name() +
                       "' has a prismatic joint; the particle filter's state is joint angles on "
                       "a torus and needs revolute joints");
    }
    const auto [parent_joint, T_pj_parent] = NearestJointFrame(model, f.parent);
    Node n;
    n.parent = node_for(parent_joint);
    const lie::SE3 T_pj_ip = T_pj_parent * f.T_parent_ip;
    const Mat3 W = lie::Skew(f.joint.axis);
    n.q_index = f.q_index;
    n.K0 = T_pj_ip.rotation();
    n.K1 = n.K0 * W;
    n.K2 = n.K1 * W;
    n.r = f.joint.point;
    n.u0 = T_pj_ip.translation() + n.K0 * n.r;
    nodes_.push_back(n);
    node_of_frame[joint_frame] = static_cast<int>(nodes_.size()) - 1;
    return static_cast<int>(nodes_.size()) - 1;
  };
  for (FrameId frame : outputs) {
    if (frame < 0 || frame >= model.num_frames()) {
      throw InputError("BatchKinematics: frame id " + std::to_string(frame) +
                       " does not exist in PPOE model '" + model.name() + "'");
    }
    const auto [joint_frame, T] = NearestJointFrame(model, frame);
    Output o;
    o.frame = frame;
    o.node = node_for(joint_frame);
    o.T_node_frame = T;
    o.identity = T.IsApprox(lie::SE3::Identity(), 0.0);
    outputs_.push_back(o);
  }
  node_buf_.assign(nodes_.size() * 12 * kBlock, 0.0);
  rel_buf_.assign(12 * kBlock, 0.0);
  out_.assign(outputs_.size() * 12 * static_cast<size_t>(capacity_), 0.0);
}

int BatchKinematics::OutputIndex(FrameId frame) const {
  for (int k = 0; k < num_outputs(); ++k) {
    if (outputs_[k].frame == frame) return k;
  }
  return -1;
}

void BatchKinematics::Compute(const double* cos_q, const double* sin_q, int stride, int n) {
  if (n > capacity_ || n < 0) {
    throw InputError("BatchKinematics: " + std::to_string(n) + " particles for a capacity of " +
                     std::to_string(capacity_));
  }
  constexpr int B = kBlock;
  double* rel = rel_buf_.data();
  for (int start = 0; start < n; start += B) {
    const int m = std::min(B, n - start);
    for (size_t ni = 0; ni < nodes_.size(); ++ni) {
      const Node& node = nodes_[ni];
      const double* __restrict c = cos_q + node.q_index * stride + start;
      const double* __restrict s = sin_q + node.q_index * stride + start;
      // Relative pose of the node: R = K0 + s K1 + (1 - c) K2, t = u0 - R r.
      for (int e = 0; e < 9; ++e) {
        const int r = e / 3, col = e % 3;
        const double k0 = node.K0(r, col), k1 = node.K1(r, col), k2 = node.K2(r, col);
        double* __restrict out = rel + e * B;
        for (int i = 0; i < m; ++i) out[i] = k0 + s[i] * k1 + (1.0 - c[i]) * k2;
      }
      for (int a = 0; a < 3; ++a) {
        double* __restrict out = rel + (9 + a) * B;
        const double* __restrict r0 = rel + (a * 3 + 0) * B;
        const double* __restrict r1 = rel + (a * 3 + 1) * B;
        const double* __restrict r2 = rel + (a * 3 + 2) * B;
        const double u = node.u0(a), p0 = node.r(0), p1 = node.r(1), p2 = node.r(2);
        for (int i = 0; i < m; ++i) out[i] = u - (r0[i] * p0 + r1[i] * p1 + r2[i] * p2);
      }
      double* __restrict dst = node_buf_.data() + ni * 12 * B;
      if (node.parent < 0) {
        for (int e = 0; e < 12; ++e) {
          for (int i = 0; i < m; ++i) dst[e * B + i] = rel[e * B + i];
        }
        continue;
      }
      const double* __restrict p = node_buf_.data() + node.parent * 12 * B;
      // R = Rp Rrel, t = Rp trel + tp.
      for (int r = 0; r < 3; ++r) {
        const double* __restrict a0 = p + (r * 3 + 0) * B;
        const double* __restrict a1 = p + (r * 3 + 1) * B;
        const double* __restrict a2 = p + (r * 3 + 2) * B;
        for (int col = 0; col < 3; ++col) {
          const double* __restrict b0 = rel + (0 * 3 + col) * B;
          const double* __restrict b1 = rel + (1 * 3 + col) * B;
          const double* __restrict b2 = rel + (2 * 3 + col) * B;
          double* __restrict o = dst + (r * 3 + col) * B;
          for (int i = 0; i < m; ++i) o[i] = a0[i] * b0[i] + a1[i] * b1[i] + a2[i] * b2[i];
        }
        const double* __restrict t0 = rel + 9 * B;
        const double* __restrict t1 = rel + 10 * B;
        const double* __restrict t2 = rel + 11 * B;
        const double* __restrict tp = p + (9 + r) * B;
        double* __restrict o = dst + (9 + r) * B;
        for (int i = 0; i < m; ++i) o[i] = a0[i] * t0[i] + a1[i] * t1[i] + a2[i] * t2[i] + tp[i];
      }
    }
    for (size_t k = 0; k < outputs_.size(); ++k) {
      const Output& o = outputs_[k];
      double* __restrict base = out_.data() + k * 12 * static_cast<size_t>(capacity_) + start;
      if (o.node < 0) {
        const Mat3& R = o.T_node_frame.rotation();
        const Vec3& t = o.T_node_frame.translation();
        for (int e = 0; e < 9; ++e) {
          for (int i = 0; i < m; ++i) base[e * capacity_ + i] = R(e / 3, e % 3);
        }
        for (int a = 0; a < 3; ++a) {
          for (int i = 0; i < m; ++i) base[(9 + a) * capacity_ + i] = t(a);
        }
        continue;
      }
      const double* __restrict src = node_buf_.data() + o.node * 12 * B;
      if (o.identity) {
        for (int e = 0; e < 12; ++e) {
          for (int i = 0; i < m; ++i) base[e * capacity_ + i] = src[e * B + i];
        }
        continue;
      }
      const Mat3& Rc = o.T_node_frame.rotation();
      const Vec3& tc = o.T_node_frame.translation();
      for (int r = 0; r < 3; ++r) {
        const double* __restrict a0 = src + (r * 3 + 0) * B;
        const double* __restrict a1 = src + (r * 3 + 1) * B;
        const double* __restrict a2 = src + (r * 3 + 2) * B;
        for (int col = 0; col < 3; ++col) {
          const double b0 = Rc(0, col), b1 = Rc(1, col), b2 = Rc(2, col);
          double* __restrict dst = base + (r * 3 + col) * capacity_;
          for (int i = 0; i < m; ++i) dst[i] = a0[i] * b0 + a1[i] * b1 + a2[i] * b2;
        }
        const double* __restrict tn = src + (9 + r) * B;
        double* __restrict dst = base + (9 + r) * capacity_;
        for (int i = 0; i < m; ++i) dst[i] = a0[i] * tc(0) + a1[i] * tc(1) + a2[i] * tc(2) + tn[i];
      }
    }
  }
}

lie::SE3 BatchKinematics::Pose(int k, int i) const {
  Mat3 R;
  Vec3 t;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = this->R(k, r, c)[i];
    t(r) = this->t(k, r)[i];
  }
  return lie::SE3(R, t);
}

}  // namespace flexbench::pf
