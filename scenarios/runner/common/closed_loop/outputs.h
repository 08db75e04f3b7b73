// What a closed_loop run reports: its metrics and identification in summary.json, the augmented
// declared model and its MJCF/URDF export (when the verdict ships it), the residual CSVs and the
// figures.
#pragma once

#include "scenarios/identify/run.h"
#include "scenarios/runner/common/closed_loop/setup.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

// The declared file's identified effects the identification applies, and those it cannot (they
// move none of the measured points), never silently.
void LogBaseEffects(const ClosedLoopSetup& cl, RunContext& ctx);

// The rows left out and, with the readings' noise stated, where the fit's covariance comes from
// (summary.json's metrics, written first).
void WriteFitMetrics(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m);

// Errors before and after, diagnostics, verdict and NEES (summary.json's metrics).
void WriteMetrics(const ClosedLoopSetup& cl, const identify::Report& rep, Json* m);

// summary.json's identification: the selection, the effects, correlations, alternatives,
// equivalence sets, frames and marker offsets.
void WriteIdentification(const ClosedLoopSetup& cl, const identify::Report& rep, Json* id);

// declared_augmented.yaml and calibrated_model.{xml,urdf} (when the verdict ships the model),
// the residual CSVs, residual_structure.png and residual_before_after.png.
void WriteIdentificationFiles(const ClosedLoopSetup& cl, RunContext& ctx, const identify::Job& job,
                              const identify::Report& rep);

}  // namespace flexbench::scenarios
