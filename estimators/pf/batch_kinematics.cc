#include "estimators/pf/batch_kinematics.h"

#include <algorithm>
#include <functional>
#include <map>
#include <stdexcept>
#include <utility>

#include "estimators/error.h"
#include "estimators/pf/particle_loop.h"

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

// One non-root node for a block of particles: R = Rp Rrel, t = Rp trel + tp, Rrel and trel in
// registers, every entry written out so that the loop vectorises.
FLEXBENCH_PARTICLE_LOOP void NodeProduct(const double* __restrict c, const double* __restrict s,
                                         const double* __restrict a, double* __restrict d, int m,
                                         const double* k0, const double* k1, const double* k2,
                                         double u0, double u1, double u2, double p0, double p1,
                                         double p2) {
  constexpr int B = BatchKinematics::kBlock;
  // R = Rp Rrel, t = Rp trel + tp, with Rrel and trel in registers (written out so that the
  // loop vectorises).
  const double k000 = k0[0], k001 = k0[1], k002 = k0[2], k010 = k0[3], k011 = k0[4], k012 = k0[5],
               k020 = k0[6], k021 = k0[7], k022 = k0[8];
  const double k100 = k1[0], k101 = k1[1], k102 = k1[2], k110 = k1[3], k111 = k1[4], k112 = k1[5],
               k120 = k1[6], k121 = k1[7], k122 = k1[8];
  const double k200 = k2[0], k201 = k2[1], k202 = k2[2], k210 = k2[3], k211 = k2[4], k212 = k2[5],
               k220 = k2[6], k221 = k2[7], k222 = k2[8];
  const double* __restrict a00 = a + 0 * B;
  const double* __restrict a01 = a + 1 * B;
  const double* __restrict a02 = a + 2 * B;
  const double* __restrict a10 = a + 3 * B;
  const double* __restrict a11 = a + 4 * B;
  const double* __restrict a12 = a + 5 * B;
  const double* __restrict a20 = a + 6 * B;
  const double* __restrict a21 = a + 7 * B;
  const double* __restrict a22 = a + 8 * B;
  const double* __restrict at0 = a + 9 * B;
  const double* __restrict at1 = a + 10 * B;
  const double* __restrict at2 = a + 11 * B;
  double* __restrict d00 = d + 0 * B;
  double* __restrict d01 = d + 1 * B;
  double* __restrict d02 = d + 2 * B;
  double* __restrict d10 = d + 3 * B;
  double* __restrict d11 = d + 4 * B;
  double* __restrict d12 = d + 5 * B;
  double* __restrict d20 = d + 6 * B;
  double* __restrict d21 = d + 7 * B;
  double* __restrict d22 = d + 8 * B;
  double* __restrict dt0 = d + 9 * B;
  double* __restrict dt1 = d + 10 * B;
  double* __restrict dt2 = d + 11 * B;
  for (int i = 0; i < m; ++i) {
    const double si = s[i], vi = 1.0 - c[i];
    const double r00 = k000 + si * k100 + vi * k200, r01 = k001 + si * k101 + vi * k201,
                 r02 = k002 + si * k102 + vi * k202;
    const double r10 = k010 + si * k110 + vi * k210, r11 = k011 + si * k111 + vi * k211,
                 r12 = k012 + si * k112 + vi * k212;
    const double r20 = k020 + si * k120 + vi * k220, r21 = k021 + si * k121 + vi * k221,
                 r22 = k022 + si * k122 + vi * k222;
    const double t0 = u0 - (r00 * p0 + r01 * p1 + r02 * p2);
    const double t1 = u1 - (r10 * p0 + r11 * p1 + r12 * p2);
    const double t2 = u2 - (r20 * p0 + r21 * p1 + r22 * p2);
    const double b00 = a00[i], b01 = a01[i], b02 = a02[i];
    const double b10 = a10[i], b11 = a11[i], b12 = a12[i];
    const double b20 = a20[i], b21 = a21[i], b22 = a22[i];
    d00[i] = b00 * r00 + b01 * r10 + b02 * r20;
    d01[i] = b00 * r01 + b01 * r11 + b02 * r21;
    d02[i] = b00 * r02 + b01 * r12 + b02 * r22;
    d10[i] = b10 * r00 + b11 * r10 + b12 * r20;
    d11[i] = b10 * r01 + b11 * r11 + b12 * r21;
    d12[i] = b10 * r02 + b11 * r12 + b12 * r22;
    d20[i] = b20 * r00 + b21 * r10 + b22 * r20;
    d21[i] = b20 * r01 + b21 * r11 + b22 * r21;
    d22[i] = b20 * r02 + b21 * r12 + b22 * r22;
    dt0[i] = b00 * t0 + b01 * t1 + b02 * t2 + at0[i];
    dt1[i] = b10 * t0 + b11 * t1 + b12 * t2 + at1[i];
    dt2[i] = b20 * t0 + b21 * t1 + b22 * t2 + at2[i];
  }
}

}  // namespace

BatchKinematics::BatchKinematics(const PpoeModel& model, const std::vector<FrameId>& outputs,
                                 int capacity, const std::vector<bool>& translation_needed)
    : capacity_(capacity) {
  if (!translation_needed.empty() && translation_needed.size() != outputs.size()) {
    throw std::invalid_argument(
        "BatchKinematics: translation_needed must have one flag per output");
  }
  if (capacity <= 0) throw std::invalid_argument("BatchKinematics: capacity must be > 0");
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
    Node n;
    n.frame = joint_frame;
    n.parent = node_for(NearestJointFrame(model, f.parent).first);
    Fold(model, &n);
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
    o.rotation_identity = T.rotation() == Mat3::Identity();
    o.translation = translation_needed.empty() || translation_needed[outputs_.size()];
    outputs_.push_back(o);
  }
  node_buf_.assign(nodes_.size() * 12 * kBlock, 0.0);
  // The distance between two output arrays: capacity rounded up to a cache line, plus one line,
  // so that the 12 arrays of a pose do not all start at the same offset modulo 4 KiB (they
  // would evict each other from the same L1 sets when N is a power of two).
  ld_ = (static_cast<std::size_t>(capacity_) + 7) / 8 * 8 + 8;
  out_.assign(outputs_.size() * 12 * ld_, 0.0);
}

void BatchKinematics::Fold(const PpoeModel& model, Node* n) {
  const PpoeFrame& f = model.frame(n->frame);
  const lie::SE3 T_pj_ip = NearestJointFrame(model, f.parent).second * f.T_parent_ip;
  const Mat3 W = lie::Skew(f.joint.axis);
  n->q_index = f.q_index;
  n->K0 = T_pj_ip.rotation();
  n->K1 = n->K0 * W;
  n->K2 = n->K1 * W;
  n->r = f.joint.point;
  n->u0 = T_pj_ip.translation() + n->K0 * n->r;
}

void BatchKinematics::Refold(const PpoeModel& model) {
  for (Node& n : nodes_) {
    if (n.frame >= model.num_frames() || model.frame(n.frame).q_index != n.q_index) {
      throw std::invalid_argument("BatchKinematics: Refold with PPOE model '" + model.name() +
                                  "', which has other joints than the model it was built for");
    }
    Fold(model, &n);
  }
  for (Output& o : outputs_) {
    o.T_node_frame = NearestJointFrame(model, o.frame).second;
    o.rotation_identity = o.T_node_frame.rotation() == Mat3::Identity();
  }
}

int BatchKinematics::OutputIndex(FrameId frame) const {
  for (int k = 0; k < num_outputs(); ++k) {
    if (outputs_[k].frame == frame) return k;
  }
  return -1;
}

FLEXBENCH_PARTICLE_LOOP void BatchKinematics::Compute(const double* cos_q, const double* sin_q,
                                                      int stride, int n) {
  if (n > capacity_ || n < 0) {
    throw std::invalid_argument("BatchKinematics: " + std::to_string(n) +
                                " particles for a capacity of " + std::to_string(capacity_));
  }
  constexpr int B = kBlock;
  for (int start = 0; start < n; start += B) {
    const int m = std::min(B, n - start);
    for (size_t ni = 0; ni < nodes_.size(); ++ni) {
      const Node& node = nodes_[ni];
      const double* __restrict c = cos_q + node.q_index * stride + start;
      const double* __restrict s = sin_q + node.q_index * stride + start;
      double k0[9], k1[9], k2[9];
      for (int e = 0; e < 9; ++e) {
        k0[e] = node.K0(e / 3, e % 3);
        k1[e] = node.K1(e / 3, e % 3);
        k2[e] = node.K2(e / 3, e % 3);
      }
      const double u0 = node.u0(0), u1 = node.u0(1), u2 = node.u0(2);
      const double p0 = node.r(0), p1 = node.r(1), p2 = node.r(2);
      double* __restrict d = node_buf_.data() + ni * 12 * B;
      if (node.parent < 0) {
        // Relative pose of the node: R = K0 + s K1 + (1 - c) K2, t = u0 - R r.
        for (int i = 0; i < m; ++i) {
          const double si = s[i], vi = 1.0 - c[i];
          double r[9];
          for (int e = 0; e < 9; ++e) r[e] = k0[e] + si * k1[e] + vi * k2[e];
          for (int e = 0; e < 9; ++e) d[e * B + i] = r[e];
          d[9 * B + i] = u0 - (r[0] * p0 + r[1] * p1 + r[2] * p2);
          d[10 * B + i] = u1 - (r[3] * p0 + r[4] * p1 + r[5] * p2);
          d[11 * B + i] = u2 - (r[6] * p0 + r[7] * p1 + r[8] * p2);
        }
        continue;
      }
      NodeProduct(c, s, node_buf_.data() + node.parent * 12 * B, d, m, k0, k1, k2, u0, u1, u2, p0,
                  p1, p2);
    }
    for (size_t k = 0; k < outputs_.size(); ++k) {
      const Output& o = outputs_[k];
      double* __restrict base = out_.data() + k * 12 * ld_ + start;
      if (o.node < 0) {
        const Mat3& R = o.T_node_frame.rotation();
        const Vec3& t = o.T_node_frame.translation();
        for (int e = 0; e < 9; ++e) {
          for (int i = 0; i < m; ++i) base[e * ld_ + i] = R(e / 3, e % 3);
        }
        for (int a = 0; a < 3; ++a) {
          for (int i = 0; i < m; ++i) base[(9 + a) * ld_ + i] = t(a);
        }
        continue;
      }
      const double* __restrict src = node_buf_.data() + o.node * 12 * B;
      const Mat3& Rc = o.T_node_frame.rotation();
      const Vec3& tc = o.T_node_frame.translation();
      if (o.rotation_identity) {
        // A site aligned with its link: copy R, offset t.
        for (int e = 0; e < 9; ++e) {
          double* __restrict dst = base + e * ld_;
          const double* __restrict from = src + e * B;
          for (int i = 0; i < m; ++i) dst[i] = from[i];
        }
      } else {
        for (int r = 0; r < 3; ++r) {
          const double* __restrict a0 = src + (r * 3 + 0) * B;
          const double* __restrict a1 = src + (r * 3 + 1) * B;
          const double* __restrict a2 = src + (r * 3 + 2) * B;
          for (int col = 0; col < 3; ++col) {
            const double b0 = Rc(0, col), b1 = Rc(1, col), b2 = Rc(2, col);
            double* __restrict dst = base + (r * 3 + col) * ld_;
            for (int i = 0; i < m; ++i) dst[i] = a0[i] * b0 + a1[i] * b1 + a2[i] * b2;
          }
        }
      }
      if (!o.translation) continue;
      for (int r = 0; r < 3; ++r) {
        const double* __restrict a0 = src + (r * 3 + 0) * B;
        const double* __restrict a1 = src + (r * 3 + 1) * B;
        const double* __restrict a2 = src + (r * 3 + 2) * B;
        const double* __restrict tn = src + (9 + r) * B;
        double* __restrict dst = base + (9 + r) * ld_;
        const double c0 = tc(0), c1 = tc(1), c2 = tc(2);
        for (int i = 0; i < m; ++i) dst[i] = a0[i] * c0 + a1[i] * c1 + a2[i] * c2 + tn[i];
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
