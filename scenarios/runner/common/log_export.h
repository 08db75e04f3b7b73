// Writing a simulated run's readings as a recorded log (--export-log; sim/recorded_log.h), for
// the kinds that export: the chain's joints, one row per step, the truth, and the declared model
// beside them, so that a replay builds the run's chain to the last bit.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "estimators/measurement.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {

// An empty log of the chain's joints (names, which are slides), its truth the declared end
// effector, the robot named after the MJCF, the declared model in declared.yaml.
sim::RecordedLog LogOfChain(const sim::DeclaredModel& declared, const sim::DeclaredChain& chain);

// One step: its joint row at joints.t and the truth there.
void AddStepToLog(const estimators::JointReading& joints, const lie::SE3& T_base_ee,
                  sim::RecordedLog* log);

// Writes `log` into the new folder `dir` with `declared` as declared.yaml (17 digits, its MJCF
// by absolute path) and `files` (sim::WriteRecordedLog's).
void WriteLogWithDeclared(const sim::RecordedLog& log, const sim::DeclaredModel& declared,
                          const std::string& dir,
                          std::vector<std::pair<std::string, std::string>> files = {});

// Several logs, each in `dir`/<name> (a folder per effect column, per seed), with `declared`
// beside each; `dir` appears whole or not at all.
void WriteLogsWithDeclared(const std::vector<std::pair<std::string, sim::RecordedLog>>& logs,
                           const sim::DeclaredModel& declared, const std::string& dir);

}  // namespace flexbench::scenarios
