#include "scenarios/runner/common/model_config.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "estimators/format.h"

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

void Warn(const RunContext& ctx, const std::string& line) {
  std::cerr << "[flexbench] warning: " << line << "\n";
  Json& warnings = (*ctx.summary)["warnings"];
  if (!warnings.is_array()) warnings = Json::array();
  warnings.push_back(line);
}

FittedRangeCheck::FittedRangeCheck(const sim::DeclaredModel& d,
                                   const std::vector<std::string>& q_joints, const mjModel* nominal,
                                   const sim::DeclaredChain* chain)
    : fitted_(d.fitted_under), file_(d.file) {
  for (const sim::FittedUnder::JointRange& r : d.fitted_under.joint_ranges) {
    const auto it = std::find(q_joints.begin(), q_joints.end(), r.joint);
    if (it == q_joints.end()) continue;  // not a joint of this run's chain
    joints_.push_back({r, static_cast<int>(it - q_joints.begin())});
  }
  if (!nominal || !chain) return;
  if (d.fitted_under.gravity_torques.empty() && !d.fitted_under.has_box) return;
  const std::vector<std::string>& vars = chain->q_joints;
  for (const sim::FittedUnder::TorqueRange& r : d.fitted_under.gravity_torques) {
    const auto it = std::find(vars.begin(), vars.end(), r.joint);
    if (it != vars.end()) torques_.push_back({r, static_cast<int>(it - vars.begin())});
  }
  for (const std::string& j : q_joints) {
    const auto it = std::find(vars.begin(), vars.end(), j);
    chain_of_observed_.push_back(it == vars.end() ? -1 : static_cast<int>(it - vars.begin()));
  }
  chain_ = chain;
  load_ = std::make_unique<sim::PostureLoadEvaluator>(nominal, *chain);
  q_chain_ = Eigen::VectorXd::Zero(chain->model.nq());
}

void FittedRangeCheck::Observe(const double* q, int n) {
  for (Joint& j : joints_) {
    if (j.q_index >= n) continue;
    j.min = std::min(j.min, q[j.q_index]);
    j.max = std::max(j.max, q[j.q_index]);
  }
  if (!load_) return;
  for (int c = 0; c < n && c < static_cast<int>(chain_of_observed_.size()); ++c) {
    if (chain_of_observed_[c] >= 0 && std::isfinite(q[c])) q_chain_[chain_of_observed_[c]] = q[c];
  }
  chain_->ApplyCouplings(&q_chain_);
  load_->Evaluate(q_chain_, &at_);
  for (Torque& t : torques_) {
    t.min = std::min(t.min, at_.gravity_torque[t.chain_index]);
    t.max = std::max(t.max, at_.gravity_torque[t.chain_index]);
  }
  box_min_ = box_min_.cwiseMin(at_.p_base_ee);
  box_max_ = box_max_.cwiseMax(at_.p_base_ee);
}

namespace {

// "name lo..hi unit (fitted lo..hi)" when [lo, hi] leaves [fitted_lo, fitted_hi], else "".
// The fitted bounds were read back from text, widened outward: a tolerance far below any
// joint's resolution covers what remains of the rounding.
std::string Outside(const std::string& name, double lo, double hi, double fitted_lo,
                    double fitted_hi, double k, const char* unit) {
  constexpr double kTol = 1e-9;
  if (lo > hi) return "";  // never observed
  if (lo >= fitted_lo - kTol && hi <= fitted_hi + kTol) return "";
  return name + " " + Fmt("%.4g", lo * k) + ".." + Fmt("%.4g", hi * k) + " " + unit + " (fitted " +
         Fmt("%.4g", fitted_lo * k) + ".." + Fmt("%.4g", fitted_hi * k) + ")";
}

void Append(const std::string& item, std::string* list) {
  if (!item.empty()) *list += (list->empty() ? "" : ", ") + item;
}

}  // namespace

void FittedRangeCheck::Report(const RunContext& ctx) const {
  std::string angles, loads, reach;
  for (const Joint& j : joints_) {
    Append(Outside(j.fitted.joint, j.min, j.max, j.fitted.min, j.fitted.max,
                   j.fitted.slide ? 1.0 : 180.0 / M_PI, j.fitted.slide ? "m" : "deg"),
           &angles);
  }
  for (const Torque& t : torques_) {
    // A slide joint holds a force.
    const bool slide = std::any_of(fitted_.joint_ranges.begin(), fitted_.joint_ranges.end(),
                                   [&](const sim::FittedUnder::JointRange& r) {
                                     return r.joint == t.fitted.joint && r.slide;
                                   });
    Append(
        Outside(t.fitted.joint, t.min, t.max, t.fitted.min, t.fitted.max, 1.0, slide ? "N" : "N m"),
        &loads);
  }
  if (fitted_.has_box) {
    for (int i = 0; i < 3; ++i) {
      Append(Outside(std::string(1, "xyz"[i]), box_min_[i], box_max_[i], fitted_.box_min[i],
                     fitted_.box_max[i], 1.0, "m"),
             &reach);
    }
  }
  std::string outside;
  if (!angles.empty()) outside = "joint ranges: " + angles;
  if (!loads.empty()) outside += (outside.empty() ? "" : "; ") + ("gravity torques: " + loads);
  if (!reach.empty()) {
    outside += (outside.empty() ? "" : "; ") + ("end-effector position: " + reach);
  }
  if (outside.empty()) return;
  Warn(ctx, "the run leaves the conditions " + std::filesystem::path(file_).filename().string() +
                " was fitted under (fitted_under): " + outside +
                "; its effects and source sizes were measured elsewhere");
}

}  // namespace flexbench::scenarios
