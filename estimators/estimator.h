// The runtime interface of every estimator and the explicit registry (docs/design.md).
//
// An estimator knows only its declared PPOE model, the sensors' set-up (camera intrinsics and
// frames, IMU frames) and its parameters; it sees typed measurements (measurement.h) and
// returns beliefs. It never sees ground truth, MuJoCo, images or YAML: the scenario layer
// parses parameters into `Params` and the estimator validates them.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "estimators/camera/pinhole.h"
#include "estimators/kinematics/model_effects.h"
#include "estimators/kinematics/ppoe_model.h"
#include "estimators/measurement.h"

namespace flexbench::pf {
struct ParticleSummary;
}  // namespace flexbench::pf

namespace flexbench::estimators {

// Named numeric parameters from the scenario file (scalars are 1-element lists).
class Params {
 public:
  Params() = default;
  explicit Params(std::map<std::string, std::vector<double>> values, std::string where = "")
      : values_(std::move(values)), where_(std::move(where)) {}

  // Throws InputError naming the parameter (and where it came from) when missing or of the
  // wrong length.
  double Scalar(const std::string& key) const;
  double Scalar(const std::string& key, double fallback) const;
  std::vector<double> List(const std::string& key, size_t size) const;
  std::vector<double> List(const std::string& key, const std::vector<double>& fallback) const;
  bool Has(const std::string& key) const { return values_.count(key) > 0; }
  // Throws InputError for the first parameter nothing read (a typo must not pass silently).
  void CheckAllUsed(const std::string& estimator) const;

 private:
  std::map<std::string, std::vector<double>> values_;
  std::string where_;
  mutable std::set<std::string> used_;
};

struct CameraSetup {
  PinholeCamera intrinsics;
  FrameId frame = -1;  // the camera's optical frame in the declared model
};

struct ImuSetup {
  FrameId frame = -1;  // the IMU's frame in the declared model
  // Its orientation filter (imu/imu_orientations.h), for the estimators that turn its raw
  // readings (ImuReading) into orientations: Madgwick's gain (rad/s), and its orientation in the
  // base frame at its first reading when known (a calibrated yaw; otherwise the first
  // accelerometer reading's, yaw 0 about the base's vertical).
  double filter_beta = 0.05;
  bool has_initial = false;
  Quat q_base_frame_initial = Quat::Identity();
};

struct EstimatorSetup {
  const kinematics::PpoeModel* model = nullptr;
  // Effects identified from data for this model (an augmented declared file), or nullptr: every
  // estimator then predicts with the corrected model at each joint reading
  // (kinematics::EffectiveChain). Owned by the caller, like `model`.
  const kinematics::ModelEffects* effects = nullptr;
  FrameId end_effector = -1;
  std::vector<CameraSetup> cameras;
  std::vector<ImuSetup> imus;
  // The frame the estimate is made in ([PPOE eq. 25]: X is the end effector in the camera
  // frame). Default: the model's base. When set, Belief::T_base_ee is T_ref_ee, its prior
  // covariance counts only the sources not shared by ref and end effector
  // (kinematics::RelativeCovariance, 2nd order), and poses carried by measurements
  // (PlaneContact::T_base_plane, PositionReading::p_base, PoseReading::T_base_frame) are in ref.
  FrameId reference_frame = kinematics::kBaseFrame;
  Params params;
  std::uint64_t seed = 0;
};

// What an estimator believes: the end-effector pose in the base frame (or in
// EstimatorSetup::reference_frame) with a covariance in its local tangent space, and optionally
// the joint angles.
struct Belief {
  double t = 0.0;
  lie::SE3 T_base_ee;
  Mat6 cov = Mat6::Zero();
  bool has_joints = false;
  JointVector q;
  JointVector q_std;
};

enum class UpdateStatus {
  kAccepted,
  kIgnored,            // a measurement type this estimator does not use
  kRejectedNonFinite,  // NaN or infinite values
  kRejectedOutside,    // e.g. pixels outside the image, behind the camera
  kRejectedGating,     // failed an innovation gate
};
const char* ToString(UpdateStatus s);

class Estimator {
 public:
  virtual ~Estimator() = default;
  // Back to the prior (no measurement seen).
  virtual void Reset() = 0;
  // Propagates the belief to time t (static-state estimators: nothing to do).
  virtual void Predict(double t) = 0;
  virtual UpdateStatus Update(const Measurement& z) = 0;
  virtual Belief Estimate() const = 0;
  // How many priors or covariances this estimator has repaired (not positive semi-definite
  // beyond rounding) since it was made; scenarios report it next to the update counts.
  virtual int covariance_repairs() const { return 0; }
  // Readings it accepted but refused later on its own (a particle filter's IMU orientation
  // term, applied at the step's joint reading, that was not finite or not a unit quaternion)
  // since it was made; scenarios count them with the readings Update refused.
  virtual int deferred_rejections() const { return 0; }

  // What a scenario may ask beyond the Belief, to choose what it reports and draws (never the
  // estimator's name). Whether readings other than the joints' move its estimate (fk's never
  // do: it is the declared model at the joint readings).
  virtual bool FusesExternalMeasurements() const { return true; }
  // Whether its prior is the configuration-dependent PPOE covariance [PPOE eq. 18] (ppoe_ekf,
  // fk) rather than a static or diagonal one (the naive baselines, the particle filters).
  virtual bool HasConfigurationPrior() const { return false; }
  // Its particles' summary (weights, effective sample size) after the last step; nullptr for
  // an estimator without particles.
  virtual const pf::ParticleSummary* Particles() const { return nullptr; }
};

struct EstimatorEntry {
  const char* name;
  const char* description;
  std::unique_ptr<Estimator> (*make)(const EstimatorSetup& setup);
};

// The `reading_noise` parameter (0 or 1, default 0) of the estimators with a kinematic prior:
// 1 adds the joint readings' noise (JointReading::std) to it, to first order. Only in the base
// frame. Throws InputError naming the estimator.
bool ReadingNoiseFlag(const Params& params, const std::string& estimator, FrameId reference);

// The explicit list of estimators (registry.cc), one line each.
const std::vector<EstimatorEntry>& EstimatorRegistry();

// Throws InputError naming the unknown estimator and the known ones.
std::unique_ptr<Estimator> MakeEstimator(const std::string& name, const EstimatorSetup& setup);

}  // namespace flexbench::estimators
