// Forward kinematics of many joint configurations at once, in structure-of-arrays form, from the
// same PpoeModel the EKF uses (mean poses, [PPOE eqs. 16-17] with every source at zero). No MuJoCo,
// no per-particle virtual call, no allocation after construction.
//
// The chain is compressed at construction: only the revolute joint frames on the paths from the
// base to the requested output frames are kept ("nodes"), every fixed transform between two of
// them is folded into one constant, and each node's Rodrigues terms are precomputed so that
//
//   R_parentnode_node = K0 + sin(q) K1 + (1 - cos q) K2,   t = u0 - R r               [PPOE eq. 16]
//
// needs only the particle's (cos q, sin q): the particle filter keeps its joint angles on the
// unit circle, so no trigonometric function is evaluated per particle. Particles are processed in
// blocks of kBlock so the intermediate poses stay in L1 cache; each block loop is branch-free
// and written entry by entry so the compiler can vectorise it.
//
// Only revolute joints are supported (the state lives on a torus): a prismatic joint on a path
// to an output is an InputError naming the frame.
#pragma once

#include <vector>

#include "estimators/kinematics/ppoe_model.h"
#include "estimators/lie/se3.h"

namespace flexbench::pf {

using kinematics::FrameId;

class BatchKinematics {
 public:
  static constexpr int kBlock = 64;

  // Poses of `outputs` (frame ids of `model`) for up to `capacity` particles. When given,
  // `translation_needed[k] == false` skips output k's translation (an orientation-only frame).
  BatchKinematics(const kinematics::PpoeModel& model, const std::vector<FrameId>& outputs,
                  int capacity, const std::vector<bool>& translation_needed = {});

  // Takes the fixed parts of `model` (the model this was built for, with other T_parent_ip: a
  // corrected model, kinematics::EffectiveChain); the outputs keep their last values until the
  // next Compute. Does not allocate. Throws std::invalid_argument for a model of another shape.
  void Refold(const kinematics::PpoeModel& model);

  int num_outputs() const { return static_cast<int>(outputs_.size()); }
  int capacity() const { return capacity_; }
  FrameId output_frame(int k) const { return outputs_[k].frame; }
  // Index of `frame` among the outputs, or -1.
  int OutputIndex(FrameId frame) const;

  // Joint j of particle i is (cos_q[j * stride + i], sin_q[j * stride + i]), j in the model's q
  // order. Computes the outputs for particles [0, n), n <= capacity.
  void Compute(const double* cos_q, const double* sin_q, int stride, int n);

  // Entry (r, c) of output k's rotation for every particle (contiguous, capacity long).
  const double* R(int k, int r, int c) const { return &out_[(k * 12 + r * 3 + c) * ld_]; }
  // Entry i of output k's translation.
  const double* t(int k, int i) const { return &out_[(k * 12 + 9 + i) * ld_]; }
  // Output k of particle i as an SE3.
  lie::SE3 Pose(int k, int i) const;

 private:
  struct Node {
    FrameId frame = -1;  // its joint frame in the model
    int parent = -1;     // node index, -1: the base
    int q_index = -1;
    Mat3 K0, K1, K2;
    Vec3 u0, r;
  };
  struct Output {
    FrameId frame = -1;
    int node = -1;                   // -1: a constant pose (no joint on its path)
    lie::SE3 T_node_frame;           // constant offset from the node (or the base)
    bool rotation_identity = false;  // R_node_frame = I exactly
    bool translation = true;         // compute the translation
  };

  // The constants of a node from its joint frame in `model`.
  static void Fold(const kinematics::PpoeModel& model, Node* node);

  int capacity_;
  std::size_t ld_ = 0;  // distance between two output arrays (padded capacity)
  std::vector<Node> nodes_;
  std::vector<Output> outputs_;
  std::vector<double> node_buf_;  // [node][12][kBlock]
  std::vector<double> out_;       // [output][12][ld_]
};

}  // namespace flexbench::pf
