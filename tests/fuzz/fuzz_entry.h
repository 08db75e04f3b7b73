// Fuzz entry points: one function per loader that feeds arbitrary bytes through the
// real reader, the way `flexbench` reads a user's file. Each returns normally on success
// (nullopt) or on an InputError (its message: the runner's exit 2), and lets anything else
// escape, so that libFuzzer (tests/fuzz/fuzz_main.cc) or the replay test
// (tests/unit/fuzz_replay/) sees it.
//
// The readers name files, so the bytes are written to files in a private work folder
// (WorkDir(), made on first use, removed at exit). Every message of a bad input names a file
// under that folder (the scenario's models/ is a link to the repository's models/), or the
// option an input that is no file stands for (Target::also_named).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace flexbench::fuzz {

using Entry = std::optional<std::string> (*)(const std::uint8_t* data, std::size_t size);

struct Target {
  const char* name;  // tests/fuzz/corpus/<name>/, build/bin/fuzz_<name>
  Entry entry;
  // Besides a file under the work folder, what a rejection's message may name instead: the
  // input of an entry that is not a file ("--set" for an override); nullptr: a file only.
  const char* also_named = nullptr;
};

// Makes the work folder and installs MuJoCo's handlers (idempotent; every entry calls it).
void Init();
// The work folder: /tmp/flexbench-fuzz-XXXXXX (or under $TMPDIR).
const std::string& WorkDir();

// A scenario file (<work>/scenarios/fuzz.yaml) loaded and checked as `flexbench sweep` checks
// it: name, seed, gates, the kind its `kind` key names configured (every kind's Configure is
// reachable; nothing is simulated), unknown keys.
std::optional<std::string> Scenario(const std::uint8_t* data, std::size_t size);
// A declared-model file (<work>/declared/fuzz.declared.yaml) through LoadDeclaredModel, then
// BuildDeclaredChain (couplings resolved) on a fixed MJCF: the models/ model its `model` key names
// by file name (planar3, jsk_arm, rover_arm, humanoid_upper; loaded once), planar3 otherwise. The
// folder holds links to the files of models/, so the reader's existence check passes.
std::optional<std::string> DeclaredModel(const std::uint8_t* data, std::size_t size);
// A calibration CSV (<work>/calibration/data.csv) through ReadCalibrationCsv for joints j1,
// j2 with a camera present (pixel rows allowed).
std::optional<std::string> CalibrationCsv(const std::uint8_t* data, std::size_t size);
// A MUKCa placement folder (<work>/mukca/front/): the bytes up to the first line "----" are
// hole_0.csv, the rest hole_1.csv (without the line, both files get all bytes); read by
// ReadMukcaPlacement for 7 joints, 0.05 m apart.
std::optional<std::string> Mukca(const std::uint8_t* data, std::size_t size);
// A YAML file (<work>/gates/gates.yaml) through ParseGates and the unknown-key check, then
// the gates evaluated against a fixed summary and their metrics checked.
std::optional<std::string> Gates(const std::uint8_t* data, std::size_t size);
// MJCF text (<work>/mjcf/model.xml) through LoadModel (MuJoCo's parser and compiler).
std::optional<std::string> Mjcf(const std::uint8_t* data, std::size_t size);
// A sweep file (<work>/repo/sweeps/fuzz.yaml) checked as `flexbench sweep` checks it before
// running anything: LoadSweep, the points and runs expanded, and the scenario configured with
// the first points' overrides (CheckScenario). <work>/repo/ holds links to the repository's
// scenario files, so `scenario: ../smoke.yaml` (the repository's sweeps' form) resolves.
std::optional<std::string> Sweep(const std::uint8_t* data, std::size_t size);
// `--set` arguments applied to a fixed valid scenario (<work>/set/base.yaml, the smoke
// scenario): the bytes split at NUL bytes (which no command-line argument can hold) are the
// arguments, each through ParseOverride and all through CheckScenario as `flexbench run` loads
// them (ConfigNode with overrides, the kind configured).
std::optional<std::string> SetOverride(const std::uint8_t* data, std::size_t size);
// `flexbench report` on a run's and on a sweep's folder: the bytes are written as
// <work>/report/run/summary.json and as <work>/report/sweep/aggregate.json, and WriteReport
// renders each (reading the JSON, writing report.html).
std::optional<std::string> Report(const std::uint8_t* data, std::size_t size);

// A recorded-log folder (<work>/log/) through ReadRecordedLog: the bytes split at lines "----"
// are joints.csv, imu.csv and truth.tum (missing parts: empty files), beside a fixed log.yaml
// naming them, two IMU sensors (imu2, imu3) and the truth.
std::optional<std::string> RecordedLog(const std::uint8_t* data, std::size_t size);

// Every target, in the order above.
const std::vector<Target>& Targets();

}  // namespace flexbench::fuzz
