#include "sim/declared_model.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

namespace flexbench::sim {
namespace {

// Standard deviations of a perturbation source are small: beyond these the PPOE linearisation
// means nothing and covariance compounding overflows (NaN metrics).
constexpr double kMaxStdDeg = 90.0;
constexpr double kMaxStdM = 10.0;

Vec3 ReadVec3(const ConfigNode& node, double max) {
  const std::vector<double> v = node.AsDoubleList();
  if (v.size() != 3) node.Fail("expected 3 numbers [x, y, z]");
  for (double x : v) {
    if (x < 0.0) node.Fail("a standard deviation must be >= 0");
    if (x > max) {
      char b[32];
      std::snprintf(b, sizeof(b), "%g", max);
      node.Fail(std::string("a standard deviation must be at most ") + b);
    }
  }
  return Vec3(v[0], v[1], v[2]);
}

std::vector<std::string> ReadNames(const ConfigNode& node) {
  std::vector<std::string> names;
  for (const ConfigNode& item : node.Items()) names.push_back(item.AsString());
  return names;
}

// `coupled:`, a map joint -> {driver: coefficient, ...} or `mjcf`. Only the format here: the
// names and cycles need the model (BuildDeclaredChain).
std::vector<DeclaredCoupling> ReadCouplings(const ConfigNode& node) {
  if (!node.IsMap()) node.Fail("expected a map: coupled joint -> {driver: coefficient} or mjcf");
  std::vector<DeclaredCoupling> out;
  for (const std::string& joint : node.Keys()) {
    const ConfigNode entry = node.Child(joint);
    DeclaredCoupling c;
    c.joint = joint;
    c.where = entry.WhereKey();
    if (entry.IsScalar()) {
      if (entry.AsString() != "mjcf") {
        entry.Fail("expected mjcf (the model's <equality><joint>) or {driver: coefficient}");
      }
      c.from_mjcf = true;
    } else if (entry.IsMap()) {
      for (const std::string& driver : entry.Keys()) {
        const ConfigNode coef = entry.Child(driver);
        const double v = coef.AsDouble();
        if (!std::isfinite(v)) coef.Fail("a coefficient must be a finite number");
        c.drivers.emplace_back(driver, v);
        c.driver_where.push_back(coef.WhereKey());
      }
      if (c.drivers.empty()) entry.Fail("a coupled joint needs at least one driver");
    } else {
      entry.Fail("expected mjcf (the model's <equality><joint>) or {driver: coefficient}");
    }
    out.push_back(std::move(c));
  }
  return out;
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
        const double max_rot = std::pow(kMaxStdDeg * M_PI / 180.0, 2);
        for (int k = 0; k < 6; ++k) {
          const double max = k < 3 ? kMaxStdM * kMaxStdM : max_rot;  // [rho; theta]
          if (!(src.cov(k, k) >= 0.0) || src.cov(k, k) > max) {
            cov->Fail("diagonal entry " + std::to_string(k) +
                      " must be >= 0 and at most (10 m)^2 (translation) or (90 deg)^2 (rotation)");
          }
        }
        if (!src.cov.isApprox(src.cov.transpose(), 1e-9) && !src.cov.isZero()) {
          cov->Fail("covariance must be symmetric");
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
        const Vec3 sd = ReadVec3(*trans, kMaxStdM);
        src.cov.block<3, 3>(kTransIdx, kTransIdx) = sd.cwiseAbs2().asDiagonal();
      }
      if (rot) {
        const Vec3 sd = ReadVec3(*rot, kMaxStdDeg) * (M_PI / 180.0);
        src.cov.block<3, 3>(kRotIdx, kRotIdx) = sd.cwiseAbs2().asDiagonal();
      }
      if (axis) {
        const double deg = axis->AsDouble();
        if (deg < 0.0) axis->Fail("a standard deviation must be >= 0");
        if (deg > kMaxStdDeg) axis->Fail("a standard deviation must be at most 90 deg");
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
      for (const char* key : {"value", "std"}) {
        const std::vector<double>& v = key[0] == 'v' ? ie.value : ie.std;
        for (double x : v) {
          if (!std::isfinite(x)) e.Child(key).Fail("must hold finite numbers (no NaN or inf)");
        }
      }
      if (!ie.std.empty() && ie.std.size() != ie.value.size()) {
        e.Child("std").Fail("needs as many numbers as 'value'");
      }
      d.identified_effects.push_back(ie);
    }
  }
  if (const auto coupled = node.Optional("coupled")) d.coupled = ReadCouplings(*coupled);
  // Checked last, so format errors come first. (In a scenario's inline `declared:` block the
  // scenario's own `model` is what is loaded; a path here that names nothing is still an error.)
  std::error_code ec;
  if (!std::filesystem::is_regular_file(d.model_path, ec)) {
    model.Fail("model file " + CapForMessage(d.model_path) + " not found");
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
