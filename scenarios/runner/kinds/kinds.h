// Factories of the scenario kinds; registry.cc lists them.
#pragma once

#include <memory>

#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

std::unique_ptr<ScenarioKind> MakeSmokeKind();
std::unique_ptr<ScenarioKind> MakeRoverDeflectionKind();
std::unique_ptr<ScenarioKind> MakePpoeCovarianceKind();
std::unique_ptr<ScenarioKind> MakeTagFusionKind();
std::unique_ptr<ScenarioKind> MakeContactFusionKind();
std::unique_ptr<ScenarioKind> MakeTagDetectionSweepKind();
std::unique_ptr<ScenarioKind> MakeJskSimDeflectionKind();
std::unique_ptr<ScenarioKind> MakeJskFlexibleArmKind();
std::unique_ptr<ScenarioKind> MakeJskImuYawDriftKind();
std::unique_ptr<ScenarioKind> MakeJskDirectFusionKind();
std::unique_ptr<ScenarioKind> MakeJskParticleSweepKind();
std::unique_ptr<ScenarioKind> MakeClosedLoopKind();
// A closed_loop run set up already (the identify command's, from its options): its Configure
// reads nothing.
struct ClosedLoopSetup;
std::unique_ptr<ScenarioKind> MakeClosedLoopKind(std::unique_ptr<ClosedLoopSetup> setup);
std::unique_ptr<ScenarioKind> MakeClosedLoopEstimatorsKind();
std::unique_ptr<ScenarioKind> MakeMismatchMatrixKind();
std::unique_ptr<ScenarioKind> MakeReplayKind();
std::unique_ptr<ScenarioKind> MakeClosedLoopDynamicKind();

}  // namespace flexbench::scenarios
