// Factories of the scenario kinds; registry.cc lists them.
#pragma once

#include <memory>

#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

std::unique_ptr<ScenarioKind> MakeSmokeKind();

}  // namespace flexbench::scenarios
