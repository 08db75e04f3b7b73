#include "scenarios/runner/common/model_config.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

namespace flexbench::scenarios {

sim::DeclaredModel ReadModelAndDeclared(const ConfigNode& root, std::string* model_path) {
  const ConfigNode model = root.Child("model");
  *model_path = model.ResolvePath(model.AsString());
  const ConfigNode declared = root.Child("declared");
  sim::DeclaredModel d = declared.IsMap()
                             ? sim::ParseDeclaredModel(declared)
                             : sim::LoadDeclaredModel(declared.ResolvePath(declared.AsString()));
  if (declared.IsMap()) {
    // An inline block describes the scenario's model: its own `model:` must name that file
    // (another model there was ignored without a word).
    std::error_code ec;
    // (A scenario model that is missing is reported when it is loaded, naming its own key.)
    if (!std::filesystem::equivalent(d.model_path, *model_path, ec) && !ec) {
      declared.Child("model").Fail("names " + CapForMessage(d.model_path) +
                                   ", not the scenario's model " + CapForMessage(*model_path) +
                                   "; an inline declared block describes the scenario's model: "
                                   "name the same file");
    }
    d.model_path = *model_path;
  }
  return d;
}

void Warn(RunContext& ctx, const std::string& line) {
  std::cerr << "[flexbench] warning: " << line << "\n";
  Json& warnings = (*ctx.summary)["warnings"];
  if (!warnings.is_array()) warnings = Json::array();
  warnings.push_back(line);
}

FittedRangeCheck::FittedRangeCheck(const sim::DeclaredModel& d,
                                   const std::vector<std::string>& q_joints)
    : file_(d.file) {
  for (const sim::FittedUnder::JointRange& r : d.fitted_under.joint_ranges) {
    const auto it = std::find(q_joints.begin(), q_joints.end(), r.joint);
    if (it == q_joints.end()) continue;  // not a joint of this run's chain
    joints_.push_back({r, static_cast<int>(it - q_joints.begin())});
  }
}

void FittedRangeCheck::Observe(const double* q, int n) {
  for (Joint& j : joints_) {
    if (j.q_index >= n) continue;
    j.min = std::min(j.min, q[j.q_index]);
    j.max = std::max(j.max, q[j.q_index]);
  }
}

void FittedRangeCheck::Report(RunContext& ctx) const {
  std::string outside;
  for (const Joint& j : joints_) {
    // The fitted bounds were read back from text: a tolerance far below any joint's resolution.
    constexpr double kTol = 1e-9;
    if (j.min >= j.fitted.min - kTol && j.max <= j.fitted.max + kTol) continue;
    if (j.min > j.max) continue;  // never observed
    const double k = j.fitted.slide ? 1.0 : 180.0 / M_PI;
    const auto num = [k](double x) {
      char b[32];
      std::snprintf(b, sizeof(b), "%.4g", x * k);
      return std::string(b);
    };
    outside += (outside.empty() ? "" : ", ") + j.fitted.joint + " " + num(j.min) + ".." +
               num(j.max) + (j.fitted.slide ? " m" : " deg") + " (fitted " + num(j.fitted.min) +
               ".." + num(j.fitted.max) + ")";
  }
  if (outside.empty()) return;
  Warn(ctx, "the run leaves the joint ranges " + std::filesystem::path(file_).filename().string() +
                " was fitted under (fitted_under): " + outside +
                "; its effects and source sizes were measured elsewhere");
}

}  // namespace flexbench::scenarios
