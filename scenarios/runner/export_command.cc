#include "scenarios/runner/export_command.h"

#include <cmath>
#include <filesystem>
#include <iostream>

#include "estimators/error.h"
#include "scenarios/runner/output.h"
#include "scenarios/runner/runner.h"
#include "sim/declared_model.h"
#include "sim/export_model.h"
#include "sim/mujoco_model.h"

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
    throw InputError(option + " " + CapForMessage(path) + ": the file exists; --force replaces it");
  }
}

// Writes one format's file and names in one warning line what it cannot hold.
void WriteOne(const std::string& path, const char* format, const sim::ExportedModel& model) {
  WriteFileAtomic(path, model.text);
  if (!model.skipped.empty()) {
    std::string names;
    for (const std::string& s : model.skipped) names += (names.empty() ? "" : ", ") + s;
    std::cerr << "[flexbench] warning: not in " << path << " (" << format
              << " has no form for them): " << names << "\n";
  }
  std::cout << "wrote " << path << "\n";
}

// --kp as typed: a positive number, all of the text.
double ParseKp(const std::string& text) {
  if (text.empty()) return sim::kDefaultServoKp;
  double kp = 0.0;
  size_t used = 0;
  try {
    kp = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !(kp > 0.0) || !std::isfinite(kp)) {
    throw InputError("convert: --kp '" + CapForMessage(text) +
                     "': expected a positive number (N m/rad)");
  }
  return kp;
}

}  // namespace

int ConvertCommand(const ConvertCliOptions& o) {
  try {
    if (o.actuators != "position") {
      throw InputError("convert: --actuators '" + CapForMessage(o.actuators) +
                       "': give --actuators position (a <position> servo per joint)");
    }
    const double kp = ParseKp(o.kp);
    if (!sim::IsUrdfPath(o.urdf)) {
      throw InputError("convert: " + CapForMessage(o.urdf) + ": expected a URDF file (.urdf)");
    }
    const std::string out =
        o.out.empty() ? std::filesystem::path(o.urdf).replace_extension(".xml").string() : o.out;
    std::error_code ec;
    if (std::filesystem::equivalent(out, o.urdf, ec)) {
      throw InputError("convert: -o " + CapForMessage(out) +
                       ": is the input URDF; name another file");
    }
    CheckOutput(o.out.empty() ? "output" : "-o", out, o.force);
    const sim::ConvertedUrdf mjcf = sim::UrdfToMjcf(o.urdf, kp);
    for (const std::string& w : mjcf.warnings) std::cerr << "[flexbench] warning: " << w << "\n";
    if (!mjcf.skipped.empty()) {
      std::string names;
      for (const std::string& s : mjcf.skipped) names += (names.empty() ? "" : ", ") + s;
      std::cerr << "[flexbench] warning: no servo on " << names << "\n";
    }
    WriteFileAtomic(out, mjcf.text);
    std::cout << "wrote " << out << " (" << mjcf.servoed.size() << " position servos, kp " << kp
              << ")\n";
    return kExitOk;
  } catch (const InputError& e) {
    return ReportError(e);
  } catch (const std::filesystem::filesystem_error& e) {
    return ReportError(e);
  }
}

int ExportCommand(const ExportCliOptions& o) {
  try {
    if (o.mjcf.empty() && o.urdf.empty()) {
      throw InputError("export: name an output with --mjcf OUT.xml and/or --urdf OUT.urdf");
    }
    if (!o.mjcf.empty()) CheckOutput("--mjcf", o.mjcf, o.force);
    if (!o.urdf.empty()) CheckOutput("--urdf", o.urdf, o.force);
    const sim::DeclaredModel declared = sim::LoadDeclaredModel(o.declared);
    // Both built before either is written: bad input leaves no file behind.
    const sim::ExportedModel mjcf =
        o.mjcf.empty() ? sim::ExportedModel{} : sim::ExportMjcf(declared);
    const sim::ExportedModel urdf =
        o.urdf.empty() ? sim::ExportedModel{} : sim::ExportUrdf(declared);
    if (!o.mjcf.empty()) WriteOne(o.mjcf, "MJCF", mjcf);
    if (!o.urdf.empty()) WriteOne(o.urdf, "URDF", urdf);
    return kExitOk;
  } catch (const InputError& e) {
    return ReportError(e);
  } catch (const std::filesystem::filesystem_error& e) {
    return ReportError(e);
  }
}

}  // namespace flexbench::scenarios
