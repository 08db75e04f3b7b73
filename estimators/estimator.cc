#include "estimators/estimator.h"

#include "estimators/error.h"

namespace flexbench::estimators {

namespace {
std::string Prefix(const std::string& where) { return where.empty() ? "" : where + ": "; }
}  // namespace

double Params::Scalar(const std::string& key) const { return List(key, 1)[0]; }

double Params::Scalar(const std::string& key, double fallback) const {
  return Has(key) ? Scalar(key) : fallback;
}

std::vector<double> Params::List(const std::string& key, size_t size) const {
  const auto it = values_.find(key);
  if (it == values_.end()) throw InputError(Prefix(where_) + "missing parameter '" + key + "'");
  used_.insert(key);
  if (size > 0 && it->second.size() != size) {
    throw InputError(Prefix(where_) + "parameter '" + key + "' needs " + std::to_string(size) +
                     " value(s), got " + std::to_string(it->second.size()));
  }
  return it->second;
}

std::vector<double> Params::List(const std::string& key,
                                 const std::vector<double>& fallback) const {
  if (!Has(key)) return fallback;
  return List(key, fallback.empty() ? 0 : fallback.size());
}

void Params::CheckAllUsed(const std::string& estimator) const {
  for (const auto& [key, value] : values_) {
    if (!used_.count(key)) {
      throw InputError(Prefix(where_) + "unknown parameter '" + key + "' for estimator '" +
                       estimator + "'");
    }
  }
}

const char* ToString(UpdateStatus s) {
  switch (s) {
    case UpdateStatus::kAccepted:
      return "accepted";
    case UpdateStatus::kIgnored:
      return "ignored";
    case UpdateStatus::kRejectedNonFinite:
      return "rejected_non_finite";
    case UpdateStatus::kRejectedOutside:
      return "rejected_outside";
    case UpdateStatus::kRejectedGating:
      return "rejected_gating";
  }
  return "unknown";
}

std::unique_ptr<Estimator> MakeEstimator(const std::string& name, const EstimatorSetup& setup) {
  std::string known;
  for (const EstimatorEntry& e : EstimatorRegistry()) {
    if (name == e.name) return e.make(setup);
    known += std::string(known.empty() ? "" : ", ") + e.name;
  }
  throw InputError("unknown estimator '" + name + "' (known: " + known + ")");
}

bool ReadingNoiseFlag(const Params& params, const std::string& estimator, FrameId reference) {
  const double v = params.Scalar("reading_noise", 0.0);
  if (v != 0.0 && v != 1.0) throw InputError(estimator + ": reading_noise must be 0 or 1");
  if (v == 1.0 && reference != kinematics::kBaseFrame) {
    throw InputError(estimator + ": reading_noise is only available in the base frame");
  }
  return v == 1.0;
}

}  // namespace flexbench::estimators
