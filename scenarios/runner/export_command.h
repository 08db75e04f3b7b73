// `flexbench export`: the calibrated model (a declared file with its identified effects) written
// as MJCF and URDF for other tools (sim/export_model.h).
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

}  // namespace flexbench::scenarios
