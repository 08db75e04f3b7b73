#include "sim/declared_model.h"

#include <cmath>

namespace flexbench::sim {
namespace {

Vec3 ReadVec3(const ConfigNode& node) {
  const std::vector<double> v = node.AsDoubleList();
  if (v.size() != 3) node.Fail("expected 3 numbers [x, y, z]");
  for (double x : v) {
    if (x < 0.0) node.Fail("a standard deviation must be >= 0");
  }
  return Vec3(v[0], v[1], v[2]);
}

std::vector<std::string> ReadNames(const ConfigNode& node) {
  std::vector<std::string> names;
  for (const ConfigNode& item : node.Items()) names.push_back(item.AsString());
  return names;
}

}  // namespace

DeclaredModel ParseDeclaredModel(const ConfigNode& node) {
  DeclaredModel d;
  d.file = node.file();
  const ConfigNode model = node.Child("model");
  d.model_path = model.ResolvePath(model.AsString());
  d.base = node.GetString("base", "world");
  d.actuated_joints = ReadNames(node.Child("actuated_joints"));
  d.end_effector = node.GetString("end_effector");
  if (const auto obs = node.Optional("observed_frames")) d.observed_frames = ReadNames(*obs);
  if (const auto sources = node.Optional("sources")) {
    for (const ConfigNode& s : sources->Items()) {
      DeclaredSource src;
      src.where = s.Where();
      src.at = s.GetString("at");
      const auto cov = s.Optional("covariance");
      if (cov) {
        const std::vector<double> v = cov->AsDoubleList();
        if (v.size() != 36) cov->Fail("expected 36 numbers (a 6x6 matrix, row-major)");
        for (int r = 0; r < 6; ++r) {
          for (int c = 0; c < 6; ++c) src.cov(r, c) = v[6 * r + c];
        }
      }
      const auto rot = s.Optional("std_rot_deg");
      const auto trans = s.Optional("std_trans_m");
      const auto axis = s.Optional("about_axis_deg");
      if (cov && (rot || trans || axis)) {
        cov->Fail("give either 'covariance' or standard deviations, not both");
      }
      if (!cov && !rot && !trans && !axis) {
        s.Fail("a source needs std_rot_deg, std_trans_m, about_axis_deg or covariance");
      }
      if (trans) {
        const Vec3 sd = ReadVec3(*trans);
        src.cov.block<3, 3>(kTransIdx, kTransIdx) = sd.cwiseAbs2().asDiagonal();
      }
      if (rot) {
        const Vec3 sd = ReadVec3(*rot) * (M_PI / 180.0);
        src.cov.block<3, 3>(kRotIdx, kRotIdx) = sd.cwiseAbs2().asDiagonal();
      }
      if (axis) {
        const double deg = axis->AsDouble();
        if (deg < 0.0) axis->Fail("a standard deviation must be >= 0");
        src.about_axis_rad = deg * M_PI / 180.0;
      }
      d.sources.push_back(src);
    }
  }
  if (const auto fx = node.Optional("identified_effects")) {
    for (const ConfigNode& e : fx->Items()) {
      IdentifiedEffect ie;
      ie.where = e.Where();
      ie.effect = e.GetString("effect");
      ie.value = e.Child("value").AsDoubleList();
      if (const auto sd = e.Optional("std")) ie.std = sd->AsDoubleList();
      ie.unit = e.GetString("unit", "");
      if (ie.value.empty()) e.Child("value").Fail("needs at least one number");
      if (!ie.std.empty() && ie.std.size() != ie.value.size()) {
        e.Child("std").Fail("needs as many numbers as 'value'");
      }
      d.identified_effects.push_back(ie);
    }
  }
  return d;
}

DeclaredModel LoadDeclaredModel(const std::string& path) {
  const ConfigNode root = ConfigNode::LoadFile(path);
  DeclaredModel d = ParseDeclaredModel(root);
  root.CheckNoUnknownKeys();
  return d;
}

}  // namespace flexbench::sim
