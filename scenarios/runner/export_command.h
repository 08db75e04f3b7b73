// `flexbench export`: the calibrated model (a declared file with its identified effects) written
// as MJCF and URDF for other tools (sim/export_model.h). `flexbench convert`: a URDF written as
// the MJCF with position servos the truth loads it as.
#pragma once

#include <string>

namespace flexbench::scenarios {

struct ExportCliOptions {
  std::string declared;  // the declared-model YAML (e.g. a run's declared_augmented.yaml)
  std::string mjcf;      // output MJCF path ("" none)
  std::string urdf;      // output URDF path ("" none)
  bool force = false;    // replace an existing output file
};

// Writes the files; effects a format cannot hold are named in one warning line on stderr.
// Returns an exit code (2: bad input, an existing output without --force).
int ExportCommand(const ExportCliOptions& options);

struct ConvertCliOptions {
  std::string urdf;       // the input URDF
  std::string actuators;  // the servos to add: "position"
  std::string kp;         // servo stiffness as typed ("" default: sim::kDefaultServoKp)
  std::string out;        // output MJCF ("" : the URDF's path with .xml)
  bool force = false;     // replace an existing output file
};

// Writes the MJCF (sim::UrdfToMjcf); the URDF's import warnings and the joints left without a
// servo go to stderr, one line each. Returns an exit code (2: bad input, an existing output
// without --force).
int ConvertCommand(const ConvertCliOptions& options);

}  // namespace flexbench::scenarios
