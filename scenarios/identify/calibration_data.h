// Measured calibration data: a user's own CSV, and the MUKCa Panda recordings.
//
// CSV ("bring your own robot and data", README): one header row naming the columns, then one
// row per configuration; '#' starts a comment line.
//   - one column per actuated joint of the declared model, named as the joint (rad, or m for
//     slides); every actuated joint must be present;
//   - `group`: a label; rows with the same label share one unknown fixed end-effector point
//     (a ball in a socket), or
//   - `x`, `y`, `z`: the end-effector point measured in the declared base frame (m), with
//     optionally `qw`, `qx`, `qy`, `qz`: its frame's measured orientation (a full pose), or
//   - `u`, `v`: the end-effector point seen in pixels by the data set's camera (set
//     DataSet::camera first; the scenario's `camera` key), or
//   - `up_x`, `up_y`, `up_z`: the up direction (unit, -g) measured in the marker's frame by a
//     resting accelerometer or an inclinometer (gravity rows; no `frame` column);
//   - optional `motion_<joint>`: -1, 0 or +1, the direction the joint last moved in before the
//     reading (which flank of a backlash it rests on; 0 unknown);
//   - optional `set`: a label for the placement or session the row belongs to (errors are
//     averaged per set, then over sets);
//   - optional `pose`: a label for the posture the row was measured in (one row per marker seen
//     at it); cross-validation keeps a posture's rows in one fold (rows without it: those with
//     identical readings in one set);
//   - optional `frame`: `base`, or the name of a measurement frame (set DataSet::frames first;
//     the scenario's `frames` key) in which the row's x, y, z (and quaternion) were measured,
//     e.g. a laser tracker's own frame (measurement_frames.h);
//   - optional `marker`: which frame of the declared model the row measures, one of
//     DataSet::points (the end effector and the scenario's `markers`); default the end effector.
// Rows must have the header's column count; empty cells, NaN and infinities are errors, as are
// column names that are neither a joint of the model nor one of the above.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "scenarios/identify/identify.h"
#include "scenarios/identify/log_gravity.h"
#include "sim/recorded_log.h"

namespace flexbench::identify {

// The largest calibration CSV read (bigger is bad input, refused before reading).
constexpr std::uintmax_t kMaxCalibrationCsvBytes = 512u << 20;

// Memory the identification takes per calibration row (the Observation, the residual vectors;
// the loads are kept only up to kLoadsCacheBytes, and from two row blocks on no stage holds a
// Jacobian of every row), and the most one file's rows may take. Measured on 1,000,000 planar3
// point rows (3 joints): one offset planted, `flexbench identify` 1.18 GB resident; joint-origin
// errors planted (the complete-geometry block kept, 7 effects), 1.22 GB resident (0.66 KB a row
// of heap). The estimate (1 KB + 0.19 KB a joint: 1.6 KB a row for 3 joints) is 1.3 times the
// larger, and grows with the joints as rover_arm's (8 joints) figures do. A file whose line
// count times CalibrationBytesPerRow exceeds the budget is refused before any row is read ("N
// rows need about X GB; the limit is Y GB").
constexpr std::uintmax_t kCalibrationBytesPerRow = 1024;
constexpr std::uintmax_t kCalibrationBytesPerJoint = 192;
constexpr std::uintmax_t kMaxCalibrationMemoryBytes = 2000000000;
std::uintmax_t CalibrationBytesPerRow(size_t num_joints);

// Appends the file's rows to `data` (groups and sets are matched by label; pixel rows need
// data->camera). `coupled`: joints of `joints` driven by others (sim::DeclaredChain::couplings):
// they have no column (one is bad input), their entries of q are left 0 for the caller to set.
// Throws InputError "<file>:<line>: ..." on malformed input.
void ReadCalibrationCsv(const std::string& path, const std::vector<std::string>& joints,
                        DataSet* data, const std::vector<std::string>& coupled = {});

// The rows of `data` as a CSV that ReadCalibrationCsv reads back into the same rows (numbers
// with 17 significant digits): one column per joint of `joints` but the `coupled` ones, then
// `set`, `pose` (when rows carry one), `frame` and `marker` (when the data has measurement
// frames or more than one measured frame) and the measurement: group, or x, y, z (qw, qx, qy,
// qz), or u, v; `motion_<joint>` where the rows record it. Every row must be of one type
// (the reader takes the type from the header); throws InputError naming the first row that is
// not.
std::string FormatCalibrationCsv(const DataSet& data, const std::vector<std::string>& joints,
                                 const std::vector<std::string>& coupled = {});

// One MUKCa tool placement: `dir`/hole_0.csv and hole_1.csv (7 joint angles per row, no
// header) become groups "<set>/hole_0" and "<set>/hole_1", 0.050 m apart.
void ReadMukcaPlacement(const std::string& dir, const std::string& set, int num_joints,
                        double socket_distance_m, DataSet* data);

// A recorded log's truth.tum (sim/recorded_log.h) read as a tracker's measurements: each of its
// rows with t_from <= t <= t_to and inside the joints' span becomes a point row of
// data->points[point] (the log's truth frame) in the base frame, at the joint readings linear
// between the rows around its time (`column`: sim::JointColumns). Their set is the log's folder,
// `where` "<truth file> t=<time>", and their `pose` one of `time_blocks` equal spans of
// [t_from, t_to] within the joints' span ("span<k>", the same spans for every kind of row of
// the log): cross-validation then holds out stretches of time, not rows interleaved with
// their neighbours, which a moving arm makes all but equal. `frame` >= 0: the points are measured
// in data->frames[frame] (a tracker's own frame), not in the base frame. Returns the rows
// appended.
int AppendLogPoints(const sim::RecordedLog& log, const std::vector<int>& column, double t_from,
                    double t_to, int point, DataSet* data, int frame = -1, int time_blocks = 5);

// A recorded log's tag detections by one fixed camera (log.cameras[camera], the data's
// DataSet::camera) read as pixel rows: each row of tags.csv in [t_from, t_to] and inside the
// joints' span whose tag has a point (`tag_points[tag]`: its index in data->points, the tag's
// frame, whose origin is the tag's centre; -1: not a row) becomes the pixel of that point, the
// centre the log gives (sim::LogTagRow::centre: libapriltag's, or where the corners' diagonals
// cross; a row without one gives none), at the joint readings of its time. Set, `where` and
// time-span `pose` labels as AppendLogPoints'. Returns the rows appended.
int AppendLogPixels(const sim::RecordedLog& log, const std::vector<int>& column, double t_from,
                    double t_to, int camera, const std::vector<int>& tag_points, DataSet* data,
                    int time_blocks = 5);

// A log's static IMU windows in [t_from, t_to] (FindStaticWindows) as gravity rows of the
// points `imu_points[sensor]` (index into data->points, the IMU's frame; -1: no row): q and up
// as the window has them, set and time-span `pose` labels (of the windows' mid times) as
// AppendLogPoints', `where` "<imu file> t=<begin>..<end>". Returns the rows appended.
int AppendLogGravity(const sim::RecordedLog& log, const std::vector<StaticWindow>& windows,
                     double t_from, double t_to, const std::vector<int>& imu_points, DataSet* data,
                     int time_blocks = 5);

// Index of `label` in `labels`, appended when new.
int LabelIndex(std::vector<std::string>* labels, const std::string& label);

}  // namespace flexbench::identify
