// Declared-model files: what an estimator may know about a robot (models/<name>.declared.yaml).
//
//   model: rover_arm.xml            # MJCF or URDF, relative to this file
//   base: world                     # body where the chains start (default world)
//   actuated_joints: [j1, j2]       # hinge/slide joints an estimator reads
//   end_effector: ee                # MJCF site (or body)
//   observed_frames: [tag_ee_top]   # sites, bodies, geoms or cameras an estimator may predict
//   sources:                        # PPOE perturbation sources [PPOE eq. 16]
//     - at: plate_pitch             # a joint (frame at its anchor, axes of its body) or a body
//       std_rot_deg: [0, 5, 0]      # rotation std about x, y, z of that frame
//       std_trans_m: [0, 0, 0]      # translation std
//       about_axis_deg: 0.5         # rotation std about the joint's own axis (joints only)
//       covariance: [36 numbers]    # or a full 6x6, [rho; theta] order, SI units
//   identified_effects:             # written by closed_loop / `flexbench identify`
//     - {effect: joint_offset@j3, value: [-0.0052], std: [1e-5], unit: rad}
//     - effect: joint_offset@j2     # the fitted member of an equivalence set:
//       equivalent: [joint_offset@j2, joint_axis_tilt_a@j1]   # every member (the data
//       value: [0.003]              # could not tell them apart); informative only
//   frames:                         # measurement frames' fitted poses in the base frame
//     tracker:                      #   (closed_loop / identify write them; a re-run starts
//       T_base_frame: [x, y, z, qw, qx, qy, qz]      # the frame's fit from here)
//       covariance: [36 numbers]    # optional: of xi, T = T_base_frame Exp(xi), [rho; theta]
//   marker_offsets:                 # observed frames moved by fitted offsets (their own axes;
//     ee:                           #   closed_loop's unknown_marker_offsets)
//       offset_m: [dx, dy, dz]
//       covariance: [9 numbers]     # optional, m^2
//   fitted_under:                   # written with the fit: where it holds (FittedUnder)
//     joint_range_deg: {j1: [-12.5, 3.1], j2: [20, 48.2]}   # hinges
//     joint_range_m: {lift: [0.1, 0.25]}                     # slides (optional)
//     gravity_torque_nm: {j2: [-31.2, -4.5]}   # optional: the torque each joint held
//     end_effector_box_m: {min: [x, y, z], max: [x, y, z]}  # optional: where the rows reached
//     source_scale: 1e-06
//     constrained_sources: [j3:about_axis]
//     kept_declared_sources: [base_plate:rot_x]
//   coupled:                        # joints driven by others, never read
//     torso_pitch_3: {torso_pitch_1: -1, torso_pitch_2: -1}   # q = sum_j c_j q_j
//     wrist_follower: mjcf          # the MJCF's <equality><joint> on it (a polynomial of one
//                                   # driver: q = a0 + a1 x + ... + a4 x^4, angles from qpos0)
//
// Identified effects are applied by BuildDeclaredChain (sim/declared_effects.h): every estimator
// given the chain's effects predicts with the corrected model.
//
// Passive joints that are not actuated are held at their reference angle (qpos0): the declared
// model does not know they move. A source at such a joint is how the model admits it.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "estimators/conventions.h"
#include "estimators/lie/se3.h"
#include "sim/config.h"

namespace flexbench::sim {

struct DeclaredSource {
  std::string at;  // joint or body name
  Mat6 cov = Mat6::Zero();
  // Rotation std about the joint axis, applied once the axis is known (about_axis_deg).
  double about_axis_rad = 0.0;
  std::string where;  // "<file>:<line>" for messages
};

struct IdentifiedEffect {
  std::string effect;  // type@location (scenarios/identify/effect_model.h)
  std::vector<double> value;
  std::vector<double> std;
  std::string unit;
  std::string where;
  // The members of the equivalence set `effect` was fitted for (empty: singled out).
  std::vector<std::string> equivalent;
};

// A measurement frame's pose in the base frame (`frames:`), fitted by closed_loop / `flexbench
// identify`: where re-scoring or estimating with this model starts the frame from.
struct DeclaredFramePose {
  std::string name;
  lie::SE3 T_base_frame;
  // Of xi, T = T_base_frame Exp(xi), [rho; theta] in m and rad (zero when not given).
  Mat6 cov = Mat6::Zero();
  std::string where;  // "<file>:<line>: key 'frames.<name>'"
};

// An observed frame (or the end effector) moved by a fitted offset in its own axes
// (`marker_offsets:`, closed_loop's unknown_marker_offsets): BuildDeclaredChain places the
// frame at T_parent_frame * Translation(offset_m).
struct DeclaredMarkerOffset {
  std::string frame;
  Vec3 offset_m = Vec3::Zero();
  Mat3 cov = Mat3::Zero();  // m^2, the frame's axes (zero when not given)
  std::string where;
};

// A coupled joint (`coupled:`): a hinge or slide of the model driven by other declared joints
// (actuated or coupled themselves, without cycles). Names are checked by BuildDeclaredChain.
struct DeclaredCoupling {
  std::string joint;
  std::vector<std::pair<std::string, double>> drivers;  // q = sum c_j q_j; empty with from_mjcf
  std::vector<std::string> driver_where;                // "<file>:<line>" of each driver's key
  bool from_mjcf = false;  // the model's <equality><joint> with this joint as joint1
  std::string where;       // "<file>:<line>: key 'coupled.<joint>'"
};

// The conditions an augmented model was fitted under (`fitted_under:`, written by closed_loop and
// `flexbench identify`): the range of each joint over the rows the effects were fitted and the
// sources sized on, and which source directions those rows constrained (scaled by
// `source_scale`) or left as declared. A run whose joints leave these ranges uses the model
// where nothing was measured: the runner warns (scenarios/runner/common/model_config.h).
struct FittedUnder {
  struct JointRange {
    std::string joint;
    double min = 0.0;  // rad, or m for a slide (joint_range_m)
    double max = 0.0;
    bool slide = false;
  };
  std::vector<JointRange> joint_ranges;
  // The gravity torque each joint held over the rows (sim::PostureLoad; N m, N for a slide):
  // the load a bending link or compliant mount was seen under. Empty in files written before.
  struct TorqueRange {
    std::string joint;
    double min = 0.0;
    double max = 0.0;
  };
  std::vector<TorqueRange> gravity_torques;
  // The box the end effector's position in the base frame stayed in (m); has_box false when the
  // file does not say.
  bool has_box = false;
  Vec3 box_min = Vec3::Zero();
  Vec3 box_max = Vec3::Zero();
  double source_scale = 1.0;
  std::vector<std::string> constrained_sources;  // "<at>:<direction>" (identify/source_scaling.h)
  std::vector<std::string> kept_declared_sources;
  std::string where;  // "<file>:<line>: key 'fitted_under'"
  bool empty() const { return joint_ranges.empty(); }
};

struct DeclaredModel {
  std::string file;        // the declared-model file
  std::string model_path;  // resolved MJCF/URDF path
  std::string base = "world";
  std::vector<std::string> actuated_joints;
  std::string end_effector;
  std::vector<std::string> observed_frames;
  std::vector<DeclaredSource> sources;
  std::vector<IdentifiedEffect> identified_effects;
  std::vector<DeclaredCoupling> coupled;
  std::vector<DeclaredFramePose> frames;
  std::vector<DeclaredMarkerOffset> marker_offsets;
  FittedUnder fitted_under;  // empty: not an augmented model (or written before it was kept)
  // The offset of an observed frame (zero when it has none).
  Vec3 MarkerOffset(const std::string& frame) const;
};

// Reads and checks the format (not the names: see BuildDeclaredChain). Throws InputError
// naming the file, line and key.
DeclaredModel LoadDeclaredModel(const std::string& path);
// Reads a declared model from a `declared:` block inside another file (e.g. a scenario).
DeclaredModel ParseDeclaredModel(const ConfigNode& node);

// Writes `d` in the format LoadDeclaredModel reads (yaml-cpp's emitter), with `header` as
// leading comment lines. `d.model_path` is written as given: a caller writing the file
// elsewhere makes it relative to that folder. Sources come out as `about_axis_deg` and a full
// `covariance` (the per-axis stds they may have been given as are folded in by then).
// Numbers carry `digits` significant digits (stds and covariances are not known better);
// identified effects' values and coupling coefficients carry every digit, since they are the
// model (re-scoring it on its own rows reproduces the fit's errors).
std::string EmitDeclaredModel(const DeclaredModel& d, const std::string& header, int digits = 6);

}  // namespace flexbench::sim
