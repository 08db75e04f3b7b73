#include "estimators/kinematics/forward_kinematics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "estimators/error.h"
#include "estimators/lie/sincos.h"
#include "estimators/target_clones.h"

namespace flexbench::kinematics {
namespace {

using lie::SE3;

void CheckInputs(const PpoeModel& model, const PpoeData& data,
                 const Eigen::Ref<const Eigen::VectorXd>& q, const char* caller) {
  if (data.num_frames != model.num_frames() || data.nq != model.nq() ||
      static_cast<int>(data.T_base_frame.size()) != model.num_frames() ||
      static_cast<int>(data.T_parent_frame.size()) != model.num_frames() ||
      static_cast<int>(data.Sigma_frame.size()) != model.num_frames() ||
      static_cast<int>(data.sigma_is_zero.size()) != model.num_frames()) {
    std::ostringstream msg;
    msg << caller << ": PpoeData was built for a model with " << data.num_frames << " frames and "
        << data.nq << " joints, but PPOE model '" << model.name() << "' has " << model.num_frames()
        << " frames and " << model.nq() << " joints";
    throw std::invalid_argument(msg.str());
  }
  if (q.size() != model.nq()) {
    std::ostringstream msg;
    msg << caller << ": q has " << q.size() << " entries, PPOE model '" << model.name() << "' has "
        << model.nq() << " joints";
    throw InputError(msg.str());
  }
  if (!q.allFinite()) {
    for (int k = 0; k < q.size(); ++k) {
      if (!std::isfinite(q[k])) {
        std::ostringstream msg;
        msg << caller << ": q[" << k << "] (joint of frame '"
            << model.frame(model.joint_frame(k)).name << "' in PPOE model '" << model.name()
            << "') is " << q[k];
        throw InputError(msg.str());
      }
    }
  }
}

EIGEN_ALWAYS_INLINE double JointValue(const PpoeFrame& f,
                                      const Eigen::Ref<const Eigen::VectorXd>& q) {
  return f.q_index >= 0 ? q[f.q_index] : 0.0;
}

// The two coefficients of PpoeFrame's precomputed form: (sin q, 1 - cos q) for a revolute joint,
// from one inline sincos of q/2 (1 - cos q = 2 sin^2(q/2) keeps full precision for small q), (q, 0)
// for a prismatic joint, (0, 0) for a fixed frame.
struct JointTrig {
  double a = 0.0;
  double b = 0.0;
};

JointTrig ComputeTrig(const PpoeFrame& f, double q) {
  JointTrig t;
  if (f.joint.type == JointType::kRevolute) {
    double sh, ch;
    lie::SinCos(0.5 * q, &sh, &ch);
    t.a = 2.0 * sh * ch;
    t.b = 2.0 * sh * sh;
  } else if (f.joint.type == JointType::kPrismatic) {
    t.a = q;
  }
  return t;
}

// T_parent_i at the mean: T_parent_ip * Exp(zeta q) with the precomputed Rodrigues terms. Forced
// inline, as RelativeMeans: a baseline-compiled call from the x86-64-v3 entry point (its upper
// vector halves in use) ran ~3x slower.
EIGEN_ALWAYS_INLINE SE3 RelativeMean(const PpoeFrame& f, const JointTrig& t) {
  if (f.joint.type == JointType::kFixed) return f.T_parent_ip;
  return SE3(f.T_parent_ip.rotation() + t.a * f.K1 + t.b * f.K2, f.u0 + t.a * f.u1 + t.b * f.u2);
}

// Exp(zeta q) alone, for moving a covariance across the joint.
SE3 JointTransform(const PpoeFrame& f, const JointTrig& t) {
  switch (f.joint.type) {
    case JointType::kRevolute: {
      const Mat3 R = Mat3::Identity() + t.a * lie::Skew(f.joint.axis) + t.b * f.W2;
      return SE3(R, f.joint.point - R * f.joint.point);
    }
    case JointType::kPrismatic:
      return SE3::Translation(t.a * f.joint.axis);
    case JointType::kFixed:
      break;
  }
  return SE3();
}

// First pass: every T_parent_i(q). The frames are independent here, so their trigonometry runs
// four frames at a time (lie::internal::SinCos4, the same bits as ComputeTrig's SinCos) and the
// small matrix products overlap; the serial parent-to-child products come after. Forced inline
// so that each CPU's entry point gets its own vector width.
EIGEN_ALWAYS_INLINE void RelativeMeans(const std::vector<PpoeFrame>& frames,
                                       const Eigen::Ref<const Eigen::VectorXd>& q, PpoeData& data) {
  using lie::internal::V4;
  const int n = data.num_frames;
  for (int i0 = 1; i0 < n; i0 += 4) {
    const int m = std::min(4, n - i0);
    V4 half = {0.0, 0.0, 0.0, 0.0};
    for (int l = 0; l < m; ++l) half[l] = 0.5 * JointValue(frames[i0 + l], q);
    V4 sh, ch;
    lie::internal::SinCos4(half, &sh, &ch);
    const V4 a = 2.0 * sh * ch, b = 2.0 * sh * sh;  // as ComputeTrig
    for (int l = 0; l < m; ++l) {
      const PpoeFrame& f = frames[i0 + l];
      JointTrig t;
      if (f.joint.type == JointType::kRevolute) {
        t.a = a[l];
        t.b = b[l];
      } else if (f.joint.type == JointType::kPrismatic) {
        t.a = JointValue(f, q);
      }
      data.T_parent_frame[i0 + l] = RelativeMean(f, t);
    }
  }
}

}  // namespace

void ForwardKinematics(const PpoeModel& model, PpoeData& data,
                       const Eigen::Ref<const Eigen::VectorXd>& q) {
  CheckInputs(model, data, q, "ForwardKinematics");
  const std::vector<PpoeFrame>& frames = model.frames();
  RelativeMeans(frames, q, data);
  data.T_base_frame[kBaseFrame] = SE3::Identity();
  for (int i = 1; i < data.num_frames; ++i) {
    data.T_base_frame[i] = data.T_base_frame[frames[i].parent] * data.T_parent_frame[i];
  }
}

namespace {

// Whether every entry of S is +0.0.
EIGEN_ALWAYS_INLINE bool IsAllZeroBits(const Mat6& S) {
  std::uint64_t any = 0;
  for (int k = 0; k < 36; ++k) {
    std::uint64_t b;
    std::memcpy(&b, S.data() + k, sizeof b);
    any |= b;
  }
  return any == 0;
}

// The two implementations of the covariance transport (lie/se3.h), chosen per CPU below: four
// lanes on x86-64-v3, two on the baseline.
struct VectorTransport {
  EIGEN_ALWAYS_INLINE static void Run(const SE3& X, const Mat6& S1, const Mat6* S2, Mat6* out) {
    lie::internal::TransportBlocks(X.rotation(), X.translation(), S1, S2, out);
  }
};
struct Sse2Transport {
  EIGEN_ALWAYS_INLINE static void Run(const SE3& X, const Mat6& S1, const Mat6* S2, Mat6* out) {
    lie::internal::TransportBlocksSse2(X.rotation(), X.translation(), S1, S2, out);
  }
};

// [PPOE eqs. 14-18] along the tree; inlined into each CPU's entry point so that the transports
// compile for that CPU.
template <class Transport>
EIGEN_ALWAYS_INLINE void CovarianceRecursion(const PpoeModel& model, PpoeData& data,
                                             const Eigen::Ref<const Eigen::VectorXd>& q,
                                             lie::CompoundOrder order) {
  const bool fourth = order == lie::CompoundOrder::kFourth;
  const std::vector<PpoeFrame>& frames = model.frames();
  data.T_base_frame[kBaseFrame] = SE3::Identity();
  // The base's covariance is zero from PpoeData's construction and never written here, so it is
  // only checked (18 loads): the unconditional setZero was a memset (rep stos, ~30 cycles of
  // start-up), 2.5% of the 7-DoF baseline path.
  if (!IsAllZeroBits(data.Sigma_frame[kBaseFrame])) data.Sigma_frame[kBaseFrame].setZero();
  data.sigma_is_zero[kBaseFrame] = 1;
  RelativeMeans(frames, q, data);
  for (int i = 1; i < data.num_frames; ++i) {
    const PpoeFrame& f = frames[i];
    const SE3& T_parent_i = data.T_parent_frame[i];
    data.T_base_frame[i] = data.T_base_frame[f.parent] * T_parent_i;

    const bool parent_zero = data.sigma_is_zero[f.parent] != 0;
    const Mat6& Sigma_parent = data.Sigma_frame[f.parent];
    Mat6& Sigma_i = data.Sigma_frame[i];
    data.sigma_is_zero[i] = parent_zero && !f.has_source;

    if (!f.has_source) {
      // No source: the whole of [PPOE eq. 16] is a fixed transform, moved exactly [PPOE eq. 11b].
      if (parent_zero) {
        Sigma_i.setZero();
      } else {
        Transport::Run(T_parent_i, Sigma_parent, nullptr, &Sigma_i);
      }
      continue;
    }
    if (parent_zero || !fourth) {
      // [PPOE eq. 18]: without the BCH terms the source adds linearly, so it joins the upstream
      // covariance at the parent frame and both cross T_parent_i(q) in one exact transport.
      if (parent_zero) {
        Transport::Run(T_parent_i, f.source_cov_parent, nullptr, &Sigma_i);
      } else {
        Transport::Run(T_parent_i, Sigma_parent, &f.source_cov_parent, &Sigma_i);
      }
      continue;
    }
    // 4th order: compound at F_{i,p}, where the source sits, then cross the joint.
    const JointTrig trig = ComputeTrig(f, JointValue(f, q));
    Mat6 Sigma_at_source;
    Transport::Run(f.T_parent_ip, Sigma_parent, nullptr, &Sigma_at_source);
    const Mat6 Sigma_ixi = lie::BchSecondMoment(Sigma_at_source, f.source_cov, order);
    if (f.joint.type == JointType::kFixed) {
      Sigma_i = Sigma_ixi;
    } else {
      Transport::Run(JointTransform(f, trig), Sigma_ixi, nullptr, &Sigma_i);
    }
  }
}

#if FLEXBENCH_MULTIVERSION
// x86-64-v3 (AVX2, FMA): the vector transports run 4-wide.
__attribute__((target("arch=x86-64-v3"))) void CovarianceRecursionV3(
    const PpoeModel& model, PpoeData& data, const Eigen::Ref<const Eigen::VectorXd>& q,
    lie::CompoundOrder order) {
  CovarianceRecursion<VectorTransport>(model, data, q, order);
}
#endif

}  // namespace

namespace internal {

// The baseline: two-lane (SSE2) transports. 4-wide vector code compiled for plain x86-64 is slower
// than scalar code (GCC splits every operation in two and lowers the lane shuffles through
// memory), and scalar transports are slower than two-lane ones; the two-lane transport does each
// element's operations in the vector lane's order, so both paths give the same bits
// (tests/unit/kinematics, lie). bench_kinematics' BM_ForwardKinematicsCov2Baseline measures it
// against the x86-64-v3 path. Besides the transports: the joints' sincos four frames at a time
// (lie::internal::SinCos4) and no memset of the base frame's covariance per call.
void ForwardKinematicsWithCovarianceBaseline(const PpoeModel& model, PpoeData& data,
                                             const Eigen::Ref<const Eigen::VectorXd>& q,
                                             lie::CompoundOrder order) {
  CovarianceRecursion<Sse2Transport>(model, data, q, order);
}

}  // namespace internal

void ForwardKinematicsWithCovariance(const PpoeModel& model, PpoeData& data,
                                     const Eigen::Ref<const Eigen::VectorXd>& q,
                                     lie::CompoundOrder order) {
  CheckInputs(model, data, q, "ForwardKinematicsWithCovariance");
  if (order != lie::CompoundOrder::kSecond && order != lie::CompoundOrder::kFourth) {
    throw std::invalid_argument(
        "ForwardKinematicsWithCovariance: order must be kSecond or kFourth, got " +
        std::to_string(static_cast<int>(order)));
  }
#if FLEXBENCH_MULTIVERSION
  static const bool v3 = __builtin_cpu_supports("x86-64-v3");
  if (v3) {
    CovarianceRecursionV3(model, data, q, order);
    return;
  }
#endif
  internal::ForwardKinematicsWithCovarianceBaseline(model, data, q, order);
}

void RelativeCovariance(const PpoeModel& model, const PpoeData& data, FrameId ref, FrameId frame,
                        Mat6* Sigma_ref_frame) {
  const int n = model.num_frames();
  if (ref < 0 || ref >= n || frame < 0 || frame >= n) {
    throw InputError("RelativeCovariance: frame id " +
                     std::to_string(ref < 0 || ref >= n ? ref : frame) +
                     " does not exist in PPOE model '" + model.name() + "'");
  }
  if (static_cast<int>(data.T_base_frame.size()) != n) {
    throw std::invalid_argument("RelativeCovariance: data was built for another model than '" +
                                model.name() + "'");
  }
  // Lowest common ancestor: parents have smaller ids (frames are added below existing ones),
  // so step the larger id up until both meet.
  FrameId a = ref;
  FrameId b = frame;
  while (a != b) {
    if (a > b) {
      a = model.frame(a).parent;
    } else {
      b = model.frame(b).parent;
    }
  }
  const FrameId lca = a;
  Mat6& out = *Sigma_ref_frame;
  out.setZero();
  const SE3& T_base_frame = data.T_base_frame[frame];
  Mat6 contribution;
  for (FrameId start : {frame, ref}) {
    for (FrameId k = start; k != lca; k = model.frame(k).parent) {
      const PpoeFrame& f = model.frame(k);
      if (!f.has_source) continue;
      const SE3 T_base_kp = data.T_base_frame[f.parent] * f.T_parent_ip;
      lie::TransportCovariance(T_base_kp.Between(T_base_frame), f.source_cov, &contribution);
      out += contribution;
    }
  }
}

void ComputeFrameJacobian(const PpoeModel& model, const PpoeData& data, FrameId frame,
                          Eigen::Ref<Matrix6Xd> J_frame_q) {
  if (frame < 0 || frame >= model.num_frames()) {
    throw InputError("ComputeFrameJacobian: frame id " + std::to_string(frame) +
                     " does not exist in PPOE model '" + model.name() + "'");
  }
  if (J_frame_q.cols() != model.nq() ||
      static_cast<int>(data.T_base_frame.size()) != model.num_frames()) {
    throw std::invalid_argument("ComputeFrameJacobian: J_frame_q has " +
                                std::to_string(J_frame_q.cols()) + " columns, PPOE model '" +
                                model.name() + "' has " + std::to_string(model.nq()) + " joints");
  }
  J_frame_q.setZero();
  const SE3 T_frame_base = data.T_base_frame[frame].Inverse();
  for (FrameId j = frame; j != kBaseFrame; j = model.frame(j).parent) {
    const PpoeFrame& f = model.frame(j);
    if (f.q_index < 0) continue;
    // Exp(zeta (q + dq)) = Exp(zeta q) Exp(zeta dq): the increment sits at F_j and reaches the
    // frame through the rigid T_j_frame.
    J_frame_q.col(f.q_index) = (T_frame_base * data.T_base_frame[j]).AdjointTimes(f.zeta);
  }
}

void AddJointNoiseCovariance(const PpoeModel& model, const PpoeData& data, FrameId frame,
                             const Eigen::Ref<const Eigen::VectorXd>& q_std,
                             Eigen::Ref<Matrix6Xd> J_frame_q, Mat6* Sigma) {
  if (q_std.size() != model.nq()) {
    throw InputError("AddJointNoiseCovariance: " + std::to_string(q_std.size()) +
                     " joint stds for PPOE model '" + model.name() + "' with " +
                     std::to_string(model.nq()) + " joints");
  }
  ComputeFrameJacobian(model, data, frame, J_frame_q);
  for (int k = 0; k < model.nq(); ++k) {
    const double v = q_std[k] * q_std[k];
    if (v > 0.0) Sigma->noalias() += v * J_frame_q.col(k) * J_frame_q.col(k).transpose();
  }
}

}  // namespace flexbench::kinematics
