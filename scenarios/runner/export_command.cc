#include "scenarios/runner/export_command.h"

#include <filesystem>
#include <iostream>

#include "estimators/error.h"
#include "scenarios/runner/output.h"
#include "scenarios/runner/runner.h"
#include "sim/declared_model.h"
#include "sim/export_model.h"

namespace flexbench::scenarios {
namespace {

// An output path that is writable: not a folder, not an existing file unless `force`.
void CheckOutput(const std::string& option, const std::string& path, bool force) {
  std::error_code ec;
  if (path.empty()) throw InputError(option + " '': name a file");
  if (std::filesystem::is_directory(path, ec)) {
    throw InputError(option + " " + CapForMessage(path) + ": is a folder; name a file");
  }
  if (std::filesystem::exists(path, ec) && !force) {
    throw InputError(option + " " + CapForMessage(path) +
                     ": the file exists; --force replaces it");
  }
}

}  // namespace

int ExportCommand(const ExportCliOptions& o) {
  try {
    if (o.mjcf.empty()) throw InputError("export: name the output with --mjcf OUT.xml");
    CheckOutput("--mjcf", o.mjcf, o.force);
    const sim::DeclaredModel declared = sim::LoadDeclaredModel(o.declared);
    const sim::ExportedModel mjcf = sim::ExportMjcf(declared);
    WriteFileAtomic(o.mjcf, mjcf.mjcf);
    if (!mjcf.skipped.empty()) {
      std::string names;
      for (const std::string& s : mjcf.skipped) names += (names.empty() ? "" : ", ") + s;
      std::cerr << "[flexbench] warning: not in " << o.mjcf << " (MJCF has no form for them): "
                << names << "\n";
    }
    std::cout << "wrote " << o.mjcf << "\n";
    return kExitOk;
  } catch (const InputError& e) {
    return ReportError(e);
  } catch (const std::filesystem::filesystem_error& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
