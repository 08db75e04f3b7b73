// Closing the loop on measured data: the residual of a declared model, the effects that explain
// it, their fitted parameters, what the data cannot tell apart, what is left, and the error
// before and after.
//
// Observations are rows of joint angles with one of
//   - a measured point position in the base frame (a tracker, a probe), or
//   - a group: rows whose end-effector point sits at one unknown fixed point (a ball in a
//     socket, a fingertip on a mark); pairs of groups may have a known distance, or
//   - a measured pixel of a point seen by a fixed camera, or
//   - a measured up direction in a point's frame (gravity rows: an IMU at rest).
// The unknown group points are nuisance parameters fitted with the effects. Point and pose rows
// may be measured in an external frame (a tracker, DataSet::frames) whose pose in the base frame
// is unknown or known with a prior: 6 more nuisance parameters per frame, fitted with the
// effects (measurement_frames.h).
//
// Identify runs in stages, each in its own file:
//   outliers (FindOutliers, below)  rows far from the rest under the declared model
//   problem.h                       residuals and the Levenberg-Marquardt fit
//   selection.h                     forward selection screened by BIC, checked by
//                                   cross-validation (cross_validation.h), physical bounds
//   diagnostics.h                   structure left in the residual; candidates that need
//                                   evidence (periodic, stiffening) enter only when it points
//                                   at them; then complete geometry (joint_origin) last
//   equivalence.h                   equivalence sets, observable parts, unidentifiable
//   report (here)                   covariance, near-singular directions, shares, verdict
#pragma once
#include <Eigen/Core>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "estimators/camera/pinhole.h"
#include "estimators/lie/se3.h"
#include "scenarios/identify/effect_model.h"

namespace flexbench::identify {

enum class ObservationType { kPoint, kGroup, kPose, kPixel, kGravity };

// The unit a row's error is in: metres (point and group rows, a pose row's position), pixels
// (pixel rows), radians (gravity rows: the angle between the measured and the predicted up).
enum class RowUnit { kMetres, kPixels, kRadians };
inline RowUnit UnitOf(ObservationType type) {
  return type == ObservationType::kPixel     ? RowUnit::kPixels
         : type == ObservationType::kGravity ? RowUnit::kRadians
                                             : RowUnit::kMetres;
}

// An external measuring frame (a laser tracker, a motion-capture system) whose pose in the
// declared base frame, T_base_frame = T_ref Exp(xi), is fitted with the effects (xi: 6 nuisance
// parameters, [rho; theta]). T_ref is the user's guess, the prior's mean, or a registration of
// the measured points against the declared model (RegisterFrames, measurement_frames.h).
struct MeasurementFrame {
  std::string name;
  lie::SE3 T_ref;              // the reference xi is measured from
  bool has_guess = false;      // T_ref given by the user (else RegisterFrames sets it)
  bool has_prior = false;      // xi ~ N(0, diag(std_m^2 I3, std_rad^2 I3)): known within a prior
  double prior_std_m = 0.0;    // of rho
  double prior_std_rad = 0.0;  // of theta
  std::string where;           // where it was declared ("<file>:<line>"), for messages
};

// A pose row's measured orientation, held apart from the row so that point rows (most rows of a
// large data set) carry 8 bytes for it instead of a matrix: the identity until set.
class RowRotation {
 public:
  RowRotation() = default;
  RowRotation(const RowRotation& o) { *this = o; }
  RowRotation(RowRotation&&) = default;
  RowRotation& operator=(const RowRotation& o) {
    R_ = o.R_ ? std::make_unique<Mat3>(*o.R_) : nullptr;
    return *this;
  }
  RowRotation& operator=(RowRotation&&) = default;
  RowRotation& operator=(const Mat3& R) {
    R_ = std::make_unique<Mat3>(R);
    return *this;
  }
  const Mat3& get() const { return R_ ? *R_ : Identity(); }
  void setIdentity() { R_.reset(); }

 private:
  static const Mat3& Identity() {
    static const Mat3 I = Mat3::Identity();
    return I;
  }
  std::unique_ptr<Mat3> R_;  // null: the identity
};

struct Observation {
  Eigen::VectorXd q;  // declared joint order
  ObservationType type = ObservationType::kPoint;
  int group = -1;  // kGroup: index into DataSet::groups
  // kPoint, kPose measured in DataSet::frames[frame] (>= 0; -1: in the base frame, p_base and
  // R_base): the point and orientation in that frame, p_frame and R_frame. InBase maps them to
  // p_base, R_base.
  int frame = -1;
  int set = 0;  // index into DataSet::sets (a placement, a session)
  // The posture the row was measured in (index into DataSet::poses, the CSV's `pose` labels;
  // -1: none given): rows of one posture (two markers seen at once) share their readings'
  // errors, so cross-validation keeps them together.
  int pose = -1;
  int point = 0;  // the measured frame: index into DataSet::points (EffectModel::points())
  Vec3 p_base = Vec3::Zero();  // kPoint, kPose: measured point, base frame
  RowRotation R_base;          // kPose: measured orientation of the point frame
  Vec3 p_frame = Vec3::Zero();
  RowRotation R_frame;
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();  // kPixel: the point seen by DataSet::camera
  // kGravity: the up direction (a unit vector, -g) measured in the point's frame: a resting
  // accelerometer's mean specific force, normalised. The row compares it with the base frame's
  // up (MuJoCo's gravity, turned by gravity_tilt) seen from the predicted frame. Held in p_frame
  // (a gravity row is in no measurement frame; a row stays within 192 bytes).
  Vec3& up() { return p_frame; }
  const Vec3& up() const { return p_frame; }
  Eigen::VectorXd motion_sign;  // optional, per joint: +1/-1 last motion direction, 0 unknown
  std::string where;            // "<file>:<line>" for messages
};

struct GroupDistance {
  int a = 0;
  int b = 0;
  double distance_m = 0.0;
};

// A fixed camera that observes the end-effector point in pixels (pixel rows): the estimators'
// pinhole model (its pixel convention, estimators/camera/pinhole.h) at a pose in the declared
// base frame.
struct CameraModel {
  bool present = false;
  std::string name = "camera";
  PinholeCamera intrinsics;  // fx, fy, cx, cy (width, height unused here)
  lie::SE3 T_base_cam;       // optical frame: x right, y down, z forward
};

struct DataSet {
  std::vector<Observation> rows;
  CameraModel camera;
  std::vector<std::string> groups;
  std::vector<GroupDistance> distances;
  std::vector<std::string> sets;
  std::vector<std::string> poses;  // `pose` labels (Subset keeps the rows' indices, not these)
  std::vector<MeasurementFrame> frames;  // external frames rows may be measured in
  // Names of the frames of the declared model rows may measure (CSV `marker`), in the order of
  // EffectModel::points(); the first is the end effector. Empty: the end effector only.
  std::vector<std::string> points;
  // Per points entry: 1 when the marker's offset on its link is unknown (3 nuisance parameters
  // in the measured frame's coordinates, fitted with the effects); empty or 0: as declared.
  std::vector<char> offset_unknown;
};

// The most the rows' cached nominal poses may take (ComputeLoads): beyond, a row's loads keep
// none and predictions compute them.
inline constexpr double kNominalPoseCacheBytes = 16.0 * (1 << 20);
// The most the rows' kept loads may take (RowLoads): beyond, a pass computes a row's loads
// where it needs them.
inline constexpr double kLoadsCacheBytes = 128.0 * (1 << 20);

// Heap and struct bytes of one row's loads.
size_t LoadsBytes(const ConfigLoads& L);

// The rows' loads for the predictions of (active, theta) (EffectModel::LoadsFor at each row's
// readings, with its motion signs). The first rows' are kept, as many as kLoadsCacheBytes hold;
// a pass computes the others' where it needs them, into its workspace (the same bits, more
// time; a row's loads take ~1.3 KB on planar3, otherwise the largest part of identification's
// memory per row).
class RowLoads {
 public:
  RowLoads() = default;
  // Every row's loads as given, all kept.
  explicit RowLoads(std::vector<ConfigLoads> loads);
  RowLoads(const EffectModel& em, const DataSet& data, std::vector<int> active = {},
           Eigen::VectorXd theta = Eigen::VectorXd(), double max_bytes = kLoadsCacheBytes);

  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  size_t num_kept() const { return kept_.size(); }
  const ConfigLoads& kept(size_t r) const { return kept_[r]; }
  // Row r's loads (o: its observation): kept, or computed into ws.row_loads.
  const ConfigLoads& At(size_t r, const Observation& o, EffectModel::Workspace& ws) const {
    return r < kept_.size() ? kept_[r] : Compute(o, ws);
  }
  // The loads of `subset` (the rows `rows` of the data these are of).
  RowLoads Subset(const DataSet& subset, const std::vector<int>& rows) const;

 private:
  const ConfigLoads& Compute(const Observation& o, EffectModel::Workspace& ws) const;
  const EffectModel* em_ = nullptr;  // null: every row kept
  std::vector<int> active_;
  Eigen::VectorXd theta_;
  double max_bytes_ = kLoadsCacheBytes;
  std::vector<ConfigLoads> kept_;
  size_t size_ = 0;
};

// Rows a pass over many rows takes at a time (Problem::ForEachRowBlock).
inline constexpr int kRowBlock = 16384;

struct IdentifyOptions {
  bool cross_validation = true;    // selection checked on held-out folds (cross_validation.h)
  std::string folds_by = "auto";   // "auto", or insist on "set", "group" or "row" folds
  double cv_min_gain = 0.02;       // share the held-out error must drop by to keep an effect
  int cv_trials = 3;               // best-BIC candidates cross-validated per round
  double outlier_iqr = 3.0;        // rows beyond Q3 + k IQR of the declared model's errors; 0: off
  double diagnostic_p = 1e-6;      // significance of a residual finding (lets families in)
  double explained_p = 1e-3;       // a finding this strong still forbids "explained"
  double ambiguity_cv = 0.25;      // an alternative within this share of the held-out error is
                                   // as good an explanation
  double singular_tol = 1e-10;     // smallest / largest eigenvalue of the normalised information
  double point_std_m = 1e-4;       // noise of a measured or grouped point
  double distance_std_m = 1e-4;    // of a known group distance
  double rotation_std_rad = 1e-3;  // of a measured orientation (pose rows)
  double pixel_std_px = 0.5;       // of a pixel (pixel rows)
  double gravity_std_rad = 1e-3;   // of a measured up direction about each axis normal to it
  double bic_threshold = 10.0;
  double ambiguity_bic = 2.0;
  double ambiguity_cos = 0.999;
  double rank_tol = 1e-3;  // share of a sensitivity outside the span of the others
  // Most effects to choose; -1: no cap, selection stops where the held-out error (or, without
  // cross-validation, BIC) stops falling. A cap that stops a selection the data would continue
  // is reported (IdentifyResult::stopped_by) and keeps the verdict from "explained".
  int max_effects = -1;
  // Wall-clock budget of the selection in seconds; 0: none. A budget that ends the selection is
  // reported as a cap is (stopped_by "time_budget"). With a budget the result depends on the
  // machine's speed: the same seed no longer gives the same bytes.
  double time_budget_s = 0.0;
  // Called with each line of the selection log (IdentifyResult::steps) soon after it is written:
  // after every selection round and stage, so a long identification shows its progress. Null:
  // none.
  std::function<void(const std::string&)> on_step;
  int max_iterations = 50;  // Levenberg-Marquardt
  // Threads of a pass over the rows (0: one per core; parallel.h); any number, the same bits.
  int threads = 0;
  // From two blocks of this many rows on, passes go by row blocks, so that their memory is
  // bounded by a block's, not by the rows (the same results to rounding; tests make it small to
  // check the block paths against whole ones).
  int row_block = kRowBlock;
};

struct FittedEffect {
  int candidate = -1;
  std::string name;                  // all members of its equivalence set, "a | b"
  std::vector<std::string> members;  // the same names, one by one
  std::vector<double> value;         // the observable part (minimum norm over unseen directions)
  std::vector<double> std;           // of the observable part; 0 along unseen directions
  std::vector<std::vector<double>> unobservable;  // parameter directions the data does not see
  double share = 0.0;  // fraction of the removed sum of squares it accounts for
};

struct Fit {
  std::vector<int> active;
  std::vector<Eigen::MatrixXd> basis;  // per active effect: fitted directions (empty: all)
  Eigen::VectorXd theta;               // full parameters of the active candidates
  std::vector<Vec3> group_points;
  std::vector<lie::SE3> T_base_frames;  // per DataSet::frames entry: its fitted pose
  std::vector<Vec3> marker_offsets;     // per DataSet::points entry: fitted offset (0: declared)
  double rss = 0.0;                     // whitened
  int num_residuals = 0;
  int num_params = 0;  // fitted unknowns (effect directions + group points + frame poses)
  double bic = 0.0;
};

// A candidate that makes the same correction as a chosen effect on this data.
struct EquivalentMember {
  int candidate = -1;
  std::string name;
  std::vector<double> value;                      // minimum-norm parameters of the correction
  std::vector<std::vector<double>> unobservable;  // its parameter directions the data cannot see
};

struct EquivalenceSet {
  int effect = -1;   // index into IdentifyResult::effects
  std::string name;  // members joined by " | ", the chosen one first
  std::vector<EquivalentMember> members;
  double correction_rms = 0.0;  // whitened RMS of the correction it makes
};

// The best model selection finds when one chosen effect is banned. Complexity is the number of
// effect parameters a model fits (its effects' observable directions; the nuisance parameters
// are the same for every model of the data), counted rather than scored by BIC because the
// held-out error already weighs the fit. An alternative that reaches about the same held-out
// error (within ambiguity_cv) with no more parameters than the chosen model means the data does
// not single out the banned effect as the cause. One that needs more parameters and is only as
// good (not better by cv_min_gain) is no evidence against the simpler chosen cause: it is
// reported as also fitting (IdentifyResult::also_fits), and the attribution stands; but only
// while the chosen model's held-out error is within what the stated noise leaves (a chi-square
// bound at explained_p). Above it both may stand in for a cause the library lacks, and the
// alternative counts as any close one does.
struct Alternative {
  std::string banned;
  std::vector<std::string> effects;
  double cv = 0.0;        // its held-out error (mean squared whitened residual)
  int num_params = 0;     // effect parameters it fits
  int chosen_params = 0;  // effect parameters of the chosen model it is compared with
};

// Structure left in the residual (diagnostics.h).
struct ResidualFinding {
  bool significant = false;  // p < diagnostic_p
  bool notable = false;      // p < explained_p: too much left to call the data explained
  std::string kind;          // "periodic", "load", "drift" ("" none tested)
  std::string variable;      // joint name, or "row order, x"
  int q_index = -1;
  int cycles = 0;            // periodic: cycles per revolution of the strongest harmonic
  double size = 0.0;         // half the fitted curve's peak-to-peak over the observed variable
  double noise = 0.0;        // the stated noise in the same unit (a joint's: as an angle there)
  bool below_noise = false;  // size < noise: never significant, whatever the p-value
  std::string unit;
  double p_value = 1.0;
  double statistic = 0.0;
  std::string message;
  std::vector<double> coefficients;  // regression [const, ...] for the plot
  std::vector<double> x, z;          // per row: the variable and the projected residual (rad/m)
};

struct IdentifyResult {
  Fit before;  // no effect: group points only
  Fit after;
  std::vector<FittedEffect> effects;
  std::vector<EquivalenceSet> equivalence;                  // one per chosen effect
  std::vector<std::string> unidentifiable;                  // candidate names
  std::vector<std::vector<std::string>> indistinguishable;  // equivalence sets of 2 or more
  std::vector<std::string> steps;                           // selection log lines
  std::vector<std::string> unlocked;  // needs-evidence candidates a finding let in
  ResidualFinding first_finding;      // in the residual of the named effects, before unlocking
  ResidualFinding finding;            // in the final residual
  std::string folds_by;               // cross-validation folds: "set", "group", "row", ""
  int num_folds = 0;
  double cv_before = 0.0, cv_after = 0.0;  // held-out mean squared whitened residual
  // What ended the selection: "held_out" (the held-out error stopped falling), "bic" (without
  // cross-validation), "max_effects" (the cap, while a further effect still passed) or
  // "time_budget" (IdentifyOptions::time_budget_s ran out before the selection ended).
  std::string stopped_by;
  std::vector<Alternative> alternatives;  // one per chosen effect (cross-validation only)
  // Alternatives as good on held-out data as the chosen model but with more parameters, the
  // chosen model's held-out error within the stated noise (Alternative).
  std::vector<Alternative> also_fits;
  // No alternative comes within ambiguity_cv but those in also_fits, and no simpler candidate
  // makes the same correction as several chosen effects.
  bool attribution_unique = true;
  std::vector<std::string> simpler;  // chosen effects that together equal a simpler one
  // |sum of the effects' corrections|^2 / sum of their |correction|^2 (group points projected
  // out): about 1 for independent causes, well below 1 when effects cancel each other.
  double overlap = 1.0;
  bool near_singular = false;  // information matrix near singular
  std::string undetermined;    // the combination it does not determine
  Eigen::MatrixXd theta_cov;
  Eigen::MatrixXd theta_corr;
  std::vector<Mat6> frame_cov;          // per DataSet::frames entry: of its xi at the final fit
  std::vector<Mat3> marker_offset_cov;  // per DataSet::points entry (zero where declared)
  double condition_number = 0.0;
};

// Rows whose declared-model error lies beyond Q3 + opt.outlier_iqr IQR of all rows' (and above
// ten times the stated noise): errors to the coordinate-wise median of their group, to their
// measured point, or in pixels, each kind on its own. Sorted row indices; none when k = 0.
std::vector<int> FindOutliers(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                              const IdentifyOptions& opt);

// `data` without the rows `drop` (sorted), groups and sets kept as they are.
DataSet WithoutRows(const DataSet& data, const std::vector<int>& drop);

// What identification concludes, from the validation error before and after and the findings:
//   "no_effect"         nothing chosen and no structure left in the residual;
//   "unexplained"       nothing chosen, or the chosen effects do not lower the validation error,
//                       while structure (or the error) remains: the model lacks something the
//                       candidate library cannot represent;
//   "partly_explained"  the validation error drops, but structure remains (a finding with
//                       p < explained_p, or more than twice the stated noise);
//   "ambiguous"         the validation error drops and nothing is left, but with one of the
//                       chosen effects banned, other effects with no more parameters do about
//                       as well on held-out data (or chosen effects together equal a simpler
//                       candidate): the correction holds, its cause is not singled out;
//   "explained"         the validation error drops, no significant structure remains, and no
//                       alternative at most as complex explains the held-out data as well (more
//                       complex ones that do are listed in also_fits).
// A fit whose whitened RMS residual exceeds kFarAboveNoise times the stated noise is
// "unexplained" whatever else holds: outliers the rejection missed, wrong units, or a wrong
// noise level, never a model that only needs another effect.
std::string Verdict(const IdentifyResult& result, double val_before, double val_after);
inline constexpr double kFarAboveNoise = 100.0;
// The fit's RMS residual in units of the stated noise (sqrt(rss / dof)).
double NoiseRatio(const Fit& fit);

// Precomputed per-row loads for a data set, the arm at its readings.
RowLoads ComputeLoads(const EffectModel& em, const DataSet& data);
// The same for predictions of (active, theta): the arm where its joint corrections put it
// (EffectModel::LoadsFor); what a fitted model's predictions (validation, residuals) use.
RowLoads ComputeLoads(const EffectModel& em, const DataSet& data, const std::vector<int>& active,
                      const Eigen::VectorXd& theta);

// Fits `active` (all directions, plus group points) by Levenberg-Marquardt from `init` (theta;
// may be empty). problem.h has the form with fitted directions.
Fit FitEffects(const EffectModel& em, const DataSet& data, const RowLoads& loads,
               const std::vector<int>& active, const Eigen::VectorXd& init,
               const IdentifyOptions& options);

// The staged identification over `candidates` (indices into em.candidates()). Throws
// InputError when the data has fewer residuals than unknowns, or cross-validation is asked for
// and the data has fewer than two folds.
IdentifyResult Identify(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                        const std::vector<int>& candidates, const IdentifyOptions& options);

// Per-row end-effector points of a model with `active` at `theta`.
std::vector<Vec3> PredictAll(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const std::vector<int>& active, const Eigen::VectorXd& theta);

// Per-row predicted pixel of pixel rows (zero for other rows), with an active camera_offset.
std::vector<Eigen::Vector2d> PredictPixels(const EffectModel& em, const DataSet& data,
                                           const RowLoads& loads, const std::vector<int>& active,
                                           const Eigen::VectorXd& theta);

// Mean point of each group's rows (zero for a group without rows).
std::vector<Vec3> GroupMeans(const DataSet& data, const std::vector<Vec3>& points);

// Per-row predicted up direction in the frame of gravity rows (zero for other rows): the base
// frame's up (GravityUp, with an active gravity_tilt) turned into the predicted frame.
std::vector<Vec3> PredictUps(const EffectModel& em, const DataSet& data, const RowLoads& loads,
                             const std::vector<int>& active, const Eigen::VectorXd& theta);

// Error of each row in its own unit (UnitOf): metres to its measured point (point and pose rows,
// the position part) or to its group's mean (re-estimated from the rows themselves, as the MUKCa
// authors score consistency); pixels for pixel rows (`pixels` from PredictPixels); radians
// between the measured and the predicted up for gravity rows (`ups` from PredictUps). A row
// whose prediction is not given is NaN.
std::vector<double> RowErrors(const DataSet& data, const std::vector<Vec3>& points,
                              const std::vector<Eigen::Vector2d>& pixels = {},
                              const std::vector<Vec3>& ups = {});

// The MUKCa authors' metric over the rows in metres: per set, the count-weighted mean over its
// groups of the mean row error; then the mean over sets. 0 when there are no such rows.
double ConsistencyError(const DataSet& data, const std::vector<double>& row_errors);

// Mean error of the rows in `unit` (px, rad; metres: prefer ConsistencyError); 0 when there
// are none.
double MeanRowError(const DataSet& data, const std::vector<double>& row_errors, RowUnit unit);

}  // namespace flexbench::identify
