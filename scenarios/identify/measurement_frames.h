// External measurement frames (a laser tracker, motion capture): rows whose points or poses are
// given in a frame whose pose in the declared base frame is unknown (6 nuisance parameters,
// fitted with the effects in the same least-squares problem, problem.h) or known within a
// prior. The scenario declares them (`frames:`), the CSV's `frame` column names them per row.
//
//   frames:
//     tracker: {}                                   # unknown; registration initialises it
//     tracker_b:
//       T_base_frame: [x, y, z, qw, qx, qy, qz]     # a rough guess (unknown) or the prior's mean
//       prior_std_m: 0.005                          # known within (with prior_std_deg): a prior
//       prior_std_deg: 0.5                          #   xi ~ N(0, diag(std^2)) at T_base_frame
#pragma once
#include <string>
#include <vector>

#include "scenarios/identify/identify.h"
#include "sim/config.h"

namespace flexbench::identify {

// A pose [x, y, z, qw, qx, qy, qz] (m; a unit quaternion, finite values within 1000). Throws
// InputError naming the key and line.
lie::SE3 ParseFramePose(const ConfigNode& n);

// A measurement frame's name is an identifier and not `base` (the CSV's `frame` column names
// the base frame so); InputError "<where>: ..." otherwise.
void CheckFrameName(const std::string& name, const std::string& where);

// The `frames` map of a scenario. Throws InputError (file, key, line) on a name that is not an
// identifier or is `base`, a prior without a pose or with a non-positive or non-finite
// standard deviation, a pose that is not [x, y, z, qw, qx, qy, qz] with a unit quaternion.
std::vector<MeasurementFrame> ParseMeasurementFrames(const ConfigNode& node);

// InputError naming the frame's declaration when a frame of `data` has no row measured in it
// (`what`: "calibration", "validation").
void CheckFramesUsed(const DataSet& data, const std::string& what);

// Sets T_ref of each frame the user gave no guess for: the rigid registration (Umeyama, no
// scale) of its rows' measured points onto the declared model's predictions (loads: the
// data's). The effects are then fitted jointly with the frame from there. Throws InputError
// when a frame has fewer than 3 rows or their points lie on a line.
void RegisterFrames(const EffectModel& em, const RowLoads& loads, DataSet* data);

// Each frame's T_ref (the state before any fit).
std::vector<lie::SE3> ReferencePoses(const DataSet& data);

// `data` with the rows measured in frames mapped into the base frame (p_base = T_base_frame
// p_frame, R_base likewise; frame -1): what the error metrics compare predictions with. The
// distance to the prediction is the same as in the tracker frame (a rigid map).
DataSet InBase(const DataSet& data, const std::vector<lie::SE3>& T_base_frames);

// Covariance of each frame's xi (T_base_frame = T_ref Exp(xi), [rho; theta], m and rad) at the
// fit, jointly with the effects and group points: the block of (J^T J)^+ scaled by the
// residual variance rss / (N - k), as the effects' covariance (identify.cc Report).
// `offset_cov` (optional): likewise each marker's offset (zero where declared).
std::vector<Mat6> FrameCovariances(const EffectModel& em, const DataSet& data,
                                   const RowLoads& loads, const Fit& fit,
                                   const IdentifyOptions& opt,
                                   std::vector<Mat3>* offset_cov = nullptr);

// PredictAll of `fit`'s model with its marker offsets: each row's marker in the base frame.
std::vector<Vec3> PredictMarkers(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                                 const Fit& fit);

}  // namespace flexbench::identify
