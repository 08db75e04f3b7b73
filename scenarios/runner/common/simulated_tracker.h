// Tracker data simulated from the truth: an external tracker (motion capture, a laser
// tracker) set up near a nominal pose sees markers on the robot over random postures. The truth
// (MuJoCo with its effects) settles under gravity at each commanded posture (sim::Simulation's
// static equilibrium); a row is the encoder readings and one marker's position in the tracker
// frame, with noise. The closed_loop kind's `truth.tracker` block:
//
//   truth:
//     tracker:
//       frame: tracker                  # a measurement frame of the scenario's `frames:`
//       T_base_tracker: [x, y, z, qw, qx, qy, qz]   # where it was set up (declared base frame)
//       pose_std_m: 0.05                # the true pose: T_base_tracker Exp(xi), xi ~ N(0, std^2)
//       pose_std_deg: 5                 #   per axis, drawn once per run from the seed
//       noise_std_m: 1.5e-4             # per axis and reading
//       markers: [right_marker, left_marker]   # observed frames of the declared model
//       postures_deg: {default: [-30, 30], shoulder_pitch: [-100, 0]}  # command ranges
//       marker_offsets_mm: {right_marker: [x, y, z]}   # optional: where a marker really sits,
//                                       # off the declared site, in its frame (mm)
//
// Coupled joints of the declared model (its `coupled:`) are never commanded nor read: the truth's
// own linkage moves them, and each row's q takes them from its readings (ApplyCouplings), as
// identification reads a CSV.
#pragma once
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "estimators/lie/se3.h"
#include "scenarios/identify/identify.h"
#include "sim/config.h"
#include "sim/declared_chain.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {

struct TrackerTruth {
  std::string frame;  // the measurement frame's name
  lie::SE3 T_nominal;
  double pose_std_m = 0.0;
  double pose_std_rad = 0.0;
  double noise_std_m = 0.0;
  std::vector<std::string> markers;
  std::pair<double, double> default_range{0.0, 0.0};                      // rad
  std::vector<std::pair<std::string, std::pair<double, double>>> ranges;  // joint, rad
  std::vector<Vec3> marker_offsets;  // per marker: the true marker in its site's frame (m)
  // Where each key was given (file, line, key), for messages.
  std::string frame_where, markers_where, postures_where;
};

// Throws InputError (file, key, line) on a missing key, a non-positive noise, a negative pose
// spread, an empty or reversed range.
TrackerTruth ParseTrackerTruth(const ConfigNode& n);

// The tracker's true pose for a run: T_nominal Exp(xi), xi drawn from the run's seed.
lie::SE3 DrawTrackerPose(const TrackerTruth& t, std::uint64_t seed);

// Per declared joint (chain order): its actuator's index in the truth's command vector and its
// command range (rad); -1 for a coupled joint. InputError naming postures_deg when a range names
// no declared joint or a coupled one, or a declared read joint is not actuated in the truth.
struct PostureSpace {
  std::vector<int> actuator;
  std::vector<std::pair<double, double>> range;
};
PostureSpace ResolvePostures(const TrackerTruth& t, const sim::Simulation& sim,
                             const sim::DeclaredChain& chain);

// What SimulateTrackerRows needs besides the truth.
struct TrackerRowsSetup {
  sim::Simulation* sim = nullptr;
  const sim::DeclaredChain* chain = nullptr;
  std::string base_body;           // the declared base (a body of the truth)
  std::vector<int> marker_points;  // per TrackerTruth::markers, its index in DataSet::points
  int frame_index = 0;             // the tracker's index in DataSet::frames
  lie::SE3 T_base_tracker;         // the true pose
  double encoder_noise_rad = 0.0;
};

// Appends `postures` settled postures to `d`, one row per marker each, in set `set`; the
// random streams are named after `stream` (same seed, same rows). Bad input as ResolvePostures.
// `truth_errors` (if given) receives per appended row the distance of the measured point from
// the true one: the tracker's noise, the floor any model's error stays above.
void SimulateTrackerRows(const TrackerTruth& t, const TrackerRowsSetup& s, int postures,
                         std::uint64_t seed, const std::string& stream, const std::string& set,
                         identify::DataSet* d, std::vector<double>* truth_errors = nullptr);

}  // namespace flexbench::scenarios
