// The rows of a closed_loop run's data sources: MUKCa recordings, calibration CSVs, recorded
// logs (truth.tum as points, a fixed camera's tags as pixels, IMUs at rest as gravity rows) and
// simulated sockets or trackers (truth.h). Simulated and log rows are also written as the CSVs a
// user brings (`flexbench identify --calibration`).
#pragma once

#include <string>

#include "scenarios/runner/common/closed_loop/setup.h"
#include "scenarios/runner/scenario_kind.h"

namespace flexbench::scenarios {

// The rows of source s (`what`: "calibration" or "validation"); InputError when there are none.
identify::DataSet LoadRows(ClosedLoopSetup& cl, const Source& s, RunContext& ctx,
                           const std::string& what);

// The log a source reads, read once (calibration and validation on one log share it), checked
// against the streams the source names.
const sim::RecordedLog& Log(ClosedLoopSetup& cl, const Source& s);

// Index in cl.frames of the frame a log source's points are measured in (-1: the base frame).
int LogFrame(const ClosedLoopSetup& cl, const Source& s);

// The declared model for identification: a frame only a log's tag detections measure, whose
// tag's centre is off its origin, moved to the tag's centre (a marker offset known exactly).
sim::DeclaredModel WithTagCentres(ClosedLoopSetup& cl);

// The first log source's camera that sees tags, when fixed on the declared model, becomes the
// identification's camera (when the scenario names none).
void CameraFromLogs(ClosedLoopSetup& cl, const ConfigNode& root);

// A log's IMUs at rest measure the up direction in their frames: gravity rows, their noise
// level and the gravity_tilt candidate.
void ImuFromLogs(ClosedLoopSetup& cl, const ConfigNode& root);

}  // namespace flexbench::scenarios
