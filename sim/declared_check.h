// A minimal validator of declared-model files (models/<name>.declared.yaml) against their MJCF:
// every key known, every name present in the model with the right kind (end effector: a site
// or body; observed frames: sites, cameras, geoms or bodies; sources: joints or bodies). The
// full parser into a PPOE chain lives elsewhere (sim/declared_model.*); this only answers "is
// the file consistent with the model", for `flexbench inspect` and the tests.
#pragma once

#include <string>
#include <vector>

namespace flexbench::sim {

struct DeclaredCheckSource {
  std::string at;
  std::string at_kind;  // "joint" or "body"
};

struct DeclaredCheckSummary {
  std::string file;
  std::string model_path;  // resolved
  std::string base;
  std::vector<std::string> actuated_joints;
  std::string end_effector;
  std::vector<std::string> observed_frames;
  std::vector<DeclaredCheckSource> sources;
};

// Throws InputError "<file>:<line>: key '<key>': <model> has no ... named '<name>'" (or the
// YAML/MJCF error) for the first problem found.
DeclaredCheckSummary CheckDeclaredFile(const std::string& path);

}  // namespace flexbench::sim
