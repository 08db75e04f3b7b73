// Closing the loop on measured data: the residual of a declared model, the effects that explain
// it, their fitted parameters, and the error before and after.
//
// Observations are rows of joint angles with one of
//   - a measured point position in the base frame (a tracker, a probe), or
//   - a group: rows whose end-effector point sits at one unknown fixed point (a ball in a
//     socket, a fingertip on a mark); pairs of groups may have a known distance.
// The unknown group points are nuisance parameters fitted with the effects.
//
// Selection is forward stepwise with the Bayesian information criterion,
//   BIC = N ln(RSS / N) + k ln N   (N residuals, k fitted parameters incl. group points),
// accepting the candidate with the lowest BIC while it lowers BIC by more than 10 ("very
// strong" evidence on Kass & Raftery's scale). A candidate whose sensitivity lies (to 1e-3) in
// the span of the ones already chosen and the group points is unidentifiable and never fitted.
// When the best candidate and another one differ by less than 2 in BIC and the sensitivities
// (with the chosen ones projected out) of the one with fewer parameters lie in the span of the
// other's (to a cosine of 0.999, every direction), the data cannot tell them
// apart: they are reported by name, and the correction is kept as one effect named by all of
// them ("a | b"), so no single cause is claimed.
#pragma once
#include <Eigen/Core>
#include <string>
#include <vector>

#include "estimators/lie/se3.h"
#include "scenarios/identify/effect_model.h"

namespace flexbench::identify {

enum class ObservationType { kPoint, kGroup, kPose, kPixel };

struct Observation {
  Eigen::VectorXd q;  // declared joint order
  ObservationType type = ObservationType::kPoint;
  int group = -1;                                // kGroup: index into DataSet::groups
  Vec3 p_base = Vec3::Zero();                    // kPoint, kPose: measured point, base frame
  Mat3 R_base = Mat3::Identity();                // kPose: measured orientation of the point frame
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();  // kPixel: the point seen by DataSet::camera
  Eigen::VectorXd motion_sign;  // optional, per joint: +1/-1 last motion direction, 0 unknown
  int set = 0;                  // index into DataSet::sets (a placement, a session)
  std::string where;            // "<file>:<line>" for messages
};

struct GroupDistance {
  int a = 0;
  int b = 0;
  double distance_m = 0.0;
};

// A fixed pinhole camera observing the end-effector point (pixel rows).
struct CameraModel {
  bool present = false;
  std::string name = "camera";
  double fx = 0, fy = 0, cx = 0, cy = 0;
  lie::SE3 T_base_cam;  // optical frame: x right, y down, z forward
};

struct DataSet {
  std::vector<Observation> rows;
  CameraModel camera;
  std::vector<std::string> groups;
  std::vector<GroupDistance> distances;
  std::vector<std::string> sets;
};

struct IdentifyOptions {
  double point_std_m = 1e-4;       // noise of a measured or grouped point
  double distance_std_m = 1e-4;    // of a known group distance
  double rotation_std_rad = 1e-3;  // of a measured orientation (pose rows)
  double pixel_std_px = 0.5;       // of a pixel (pixel rows)
  double bic_threshold = 10.0;
  double ambiguity_bic = 2.0;
  double ambiguity_cos = 0.999;
  double rank_tol = 1e-3;  // share of a sensitivity outside the span of the others
  int max_effects = 8;
  int max_iterations = 50;  // Levenberg-Marquardt
};

struct FittedEffect {
  int candidate = -1;
  std::string name;
  std::vector<double> value;
  std::vector<double> std;
  double share = 0.0;  // fraction of the removed sum of squares it accounts for
};

struct Fit {
  std::vector<int> active;
  Eigen::VectorXd theta;
  std::vector<Vec3> group_points;
  double rss = 0.0;  // whitened
  int num_residuals = 0;
  double bic = 0.0;
};

struct IdentifyResult {
  Fit before;  // no effect: group points only
  Fit after;
  std::vector<FittedEffect> effects;
  std::vector<std::string> unidentifiable;                  // candidate names
  std::vector<std::vector<std::string>> indistinguishable;  // groups of names
  std::vector<std::string> steps;                           // selection log lines
  Eigen::MatrixXd theta_cov;
  Eigen::MatrixXd theta_corr;
  double condition_number = 0.0;
};

// Precomputed per-row loads for a data set.
std::vector<ConfigLoads> ComputeLoads(const EffectModel& em, const DataSet& data);

// Fits `active` (plus group points) by Levenberg-Marquardt from `init` (theta; may be empty).
Fit FitEffects(const EffectModel& em, const DataSet& data, const std::vector<ConfigLoads>& loads,
               const std::vector<int>& active, const Eigen::VectorXd& init,
               const IdentifyOptions& options);

// Stepwise selection over `candidates` (indices into em.candidates()).
IdentifyResult Identify(const EffectModel& em, const DataSet& data,
                        const std::vector<ConfigLoads>& loads, const std::vector<int>& candidates,
                        const IdentifyOptions& options);

// Per-row end-effector points of a model with `active` at `theta`.
std::vector<Vec3> PredictAll(const EffectModel& em, const DataSet& data,
                             const std::vector<ConfigLoads>& loads, const std::vector<int>& active,
                             const Eigen::VectorXd& theta);

// Per-row predicted pixel of pixel rows (zero for other rows), with an active camera_offset.
std::vector<Eigen::Vector2d> PredictPixels(const EffectModel& em, const DataSet& data,
                                           const std::vector<ConfigLoads>& loads,
                                           const std::vector<int>& active,
                                           const Eigen::VectorXd& theta);

// Mean point of each group's rows (zero for a group without rows).
std::vector<Vec3> GroupMeans(const DataSet& data, const std::vector<Vec3>& points);

// Error of each row in its own unit: metres to its measured point (point and pose rows, the
// position part) or to its group's mean (re-estimated from the rows themselves, as the MUKCa
// authors score consistency); pixels for pixel rows (`pixels` from PredictPixels).
std::vector<double> RowErrors(const DataSet& data, const std::vector<Vec3>& points,
                              const std::vector<Eigen::Vector2d>& pixels = {});

// The MUKCa authors' metric over the rows in metres: per set, the count-weighted mean over its
// groups of the mean row error; then the mean over sets. 0 when there are no such rows.
double ConsistencyError(const DataSet& data, const std::vector<double>& row_errors);

// Mean error of the pixel rows (px); 0 when there are none.
double PixelError(const DataSet& data, const std::vector<double>& row_errors);

}  // namespace flexbench::identify
