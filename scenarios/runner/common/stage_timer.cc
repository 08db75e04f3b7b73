#include "scenarios/runner/common/stage_timer.h"

namespace flexbench::scenarios {

double StageTimer::Seconds(const std::string& stage) const {
  const auto it = seconds_.find(stage);
  return it == seconds_.end() ? 0.0 : it->second;
}

double StageTimer::TotalSeconds() const {
  double total = 0.0;
  for (const auto& [stage, s] : seconds_) total += s;
  return total;
}

void StageTimer::Write(Json* timing, const std::string& unit, int count) const {
  if (count <= 0) return;
  for (const auto& [stage, s] : seconds_) {
    (*timing)[stage + "_ms_per_" + unit] = 1e3 * s / count;
  }
  const double total = TotalSeconds();
  if (total > 0.0) (*timing)["pipeline_" + unit + "s_per_s"] = count / total;
}

}  // namespace flexbench::scenarios
