// What a closed_loop run is set up with: the declared side identification works on, the two data
// sources, the recorded logs they read, and (for simulated data) the truth. Read from a
// scenario's keys (ReadClosedLoopSetup); the parts of the run (sources.h, truth.h,
// heldout_replay.h, outputs.h) read it, and identify::Run gets its Job from it.
#pragma once

#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "render/tag_detector.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/log_gravity.h"
#include "scenarios/identify/run.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/simulated_tracker.h"
#include "sim/config.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {

using NamedNode = std::pair<std::string, std::string>;  // a name and where it was given

// One data source (`calibration` or `validation`).
struct Source {
  enum class Type { kMukca, kCsv, kSimulate, kLog } type = Type::kCsv;
  std::string path;
  std::vector<std::string> placements;
  double socket_distance_m = 0.05;
  std::vector<std::tuple<std::string, std::string, double>> distances;
  int sim_placements = 3;
  int per_socket = 20;
  int postures = 0;  // tracker rows: settled postures
  int seed = 0;
  double from_s = -std::numeric_limits<double>::infinity();  // a log's time span
  double to_s = std::numeric_limits<double>::infinity();
  std::string frame;  // a log's points measured in this one of `frames` ("": the base frame)
  // A log's streams that become rows: truth (points), tags (pixels), imu (gravity).
  std::set<std::string> streams = {"truth", "tags", "imu"};
  bool streams_named = false;           // `streams` given (else: all the log has)
  identify::StaticWindowOptions still;  // when a log's IMU is at rest
  std::string where;
  std::string path_where;  // where the file was named (a line, or the --set that named it)
};

// A log source's time span, for messages.
std::string Span(const Source& s);

// The `truth` block: the simulated robot the rows of `simulate:` sources come from.
struct SimulatedTruth {
  bool present = false;
  sim::EffectList effects;
  std::optional<TrackerTruth> tracker;    // simulated tracker rows instead of sockets
  int tracker_frame = -1;                 // its index in the setup's frames
  std::vector<int> tracker_points;        // its markers' indices in the setup's points
  lie::SE3 T_true_tracker;                // drawn per run
  std::map<std::string, double> row_err;  // simulated tracker rows' own error, by `where`
  double socket_distance_m = 0.05;
  double encoder_noise_rad = 0.0;
  Vec3 ws_center = Vec3::Zero();
  Vec3 ws_half = Vec3::Zero();
  std::unique_ptr<sim::Simulation> sim;
};

struct ClosedLoopSetup {
  // The declared side.
  std::string model_path;
  sim::DeclaredModel declared;
  sim::MjModelPtr mj;
  std::unique_ptr<sim::DeclaredChain> chain;
  std::unique_ptr<identify::EffectModel> em;
  std::vector<NamedNode> candidate_specs;
  std::vector<int> candidates;  // into em->candidates()
  bool gravity_tilt = false;
  identify::IdentifyOptions opt;
  double reading_std_rad = 0.0;
  identify::CameraModel camera;
  std::vector<identify::MeasurementFrame> frames;
  std::vector<NamedNode> marker_nodes;
  std::vector<std::string> points;  // measured frames: end effector, then the markers
  std::vector<NamedNode> unknown_offset_nodes;
  std::vector<char> offset_unknown;           // per points entry
  std::vector<std::string> base_not_applied;  // identified effects of declared em lacks
  std::vector<std::string> unused_frames;     // declared.frames no row is measured in
  // The data.
  Source calibration, validation;
  std::vector<std::string> truth_names;  // the truth's or `expected_effects`
  std::vector<NamedNode> expected_nodes;
  render::DetectorSettings detector;             // for a log's images
  std::map<std::string, sim::RecordedLog> logs;  // by folder (Source::path)
  std::map<const Source*, std::vector<identify::StaticWindow>> still_windows;  // ImuFromLogs
  std::set<std::string> centred_tag_frames;  // log tag frames at their tags' centres
  std::vector<std::string> log_notes;        // said when the run starts
  std::vector<EstimatorSpec> replay_specs;   // a held-out log span's replay
  bool replay_held_out = false;
  SimulatedTruth truth;
};

// Reads a closed_loop scenario: every key checked, the model, chain and candidates built, the
// logs read and checked, so that bad input fails before any work.
void ReadClosedLoopSetup(const ConfigNode& root, ClosedLoopSetup* cl);

// Its two halves, for a caller that sets the declared model (and, with sources false, the
// calibration and validation sources) itself, as the identify command does from its options:
// the keys present in root are read over what cl holds; then the model, chain and candidates
// are built and checked.
void ReadClosedLoopKeys(const ConfigNode& root, ClosedLoopSetup* cl, bool sources);
void BuildClosedLoopSetup(const ConfigNode& root, ClosedLoopSetup* cl);

// The identification options' conditions, one place for a scenario's keys and the identify
// command's options: InputError "<where>: <what>" when `key`'s value breaks them.
void CheckIdentifyOption(const std::string& key, double value, const std::string& where);
void CheckFoldsBy(const std::string& value, const std::string& where);

// The job identify::Run takes for these rows.
identify::Job MakeJob(const ClosedLoopSetup& s, identify::DataSet cal, identify::DataSet val);

}  // namespace flexbench::scenarios
