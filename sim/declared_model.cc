#include "sim/declared_model.h"

#include <yaml-cpp/yaml.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cctype>
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

// `covariance: [36 numbers]`, row-major, [rho; theta] order.
Mat6 ReadCovariance(const ConfigNode& cov) {
  const std::vector<double> v = cov.AsDoubleList();
  if (v.size() != 36) cov.Fail("expected 36 numbers (a 6x6 matrix, row-major)");
  Mat6 m;
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) m(r, c) = v[6 * r + c];
  }
  const double max_rot = std::pow(kMaxStdDeg * M_PI / 180.0, 2);
  for (int k = 0; k < 6; ++k) {
    const double max = k < 3 ? kMaxStdM * kMaxStdM : max_rot;  // [rho; theta]
    if (!(m(k, k) >= 0.0) || m(k, k) > max) {
      cov.Fail("diagonal entry " + std::to_string(k) +
               " must be >= 0 and at most (10 m)^2 (translation) or (90 deg)^2 (rotation)");
    }
  }
  if (!m.isApprox(m.transpose(), 1e-9) && !m.isZero()) cov.Fail("covariance must be symmetric");
  return m;
}

// One `sources:` entry [PPOE eq. 16]. The rotation std about a joint's own axis is a separate
// quantity (applied once the axis is known), so it may come with a full covariance; the
// per-axis standard deviations may not (they would say the same thing twice).
DeclaredSource ReadSource(const ConfigNode& s) {
  DeclaredSource src;
  src.where = s.Where();
  src.at = s.GetString("at");
  const auto cov = s.Optional("covariance");
  if (cov) src.cov = ReadCovariance(*cov);
  const auto rot = s.Optional("std_rot_deg");
  const auto trans = s.Optional("std_trans_m");
  const auto axis = s.Optional("about_axis_deg");
  if (cov && (rot || trans)) cov->Fail("give either 'covariance' or standard deviations, not both");
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
  return src;
}

IdentifiedEffect ReadIdentifiedEffect(const ConfigNode& e) {
  IdentifiedEffect ie;
  ie.where = e.Where();
  ie.effect = e.GetString("effect");
  if (const auto eq = e.Optional("equivalent")) ie.equivalent = ReadNames(*eq);
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
  return ie;
}

// A fitted covariance: `n` x `n` row-major numbers, finite, symmetric and positive definite.
Eigen::MatrixXd ReadPdMatrix(const ConfigNode& node, int n) {
  const std::vector<double> v = node.AsDoubleList();
  if (static_cast<int>(v.size()) != n * n) {
    node.Fail("expected " + std::to_string(n * n) + " numbers (a " + std::to_string(n) + "x" +
              std::to_string(n) + " matrix, row-major)");
  }
  for (double x : v) {
    if (!std::isfinite(x)) node.Fail("must hold finite numbers (no NaN or inf)");
  }
  const Eigen::MatrixXd m = Eigen::Map<const Eigen::MatrixXd>(v.data(), n, n).transpose();
  if (!m.isApprox(m.transpose(), 1e-9)) node.Fail("covariance must be symmetric");
  if (m.llt().info() != Eigen::Success || !(m.diagonal().minCoeff() > 0.0)) {
    node.Fail("covariance must be positive definite");
  }
  return m;
}

std::vector<double> ReadFinite(const ConfigNode& node, size_t n, const char* form) {
  const std::vector<double> v = node.AsDoubleList();
  if (v.size() != n) node.Fail(std::string("expected ") + form);
  for (double x : v) {
    if (!std::isfinite(x) || std::abs(x) > 1000.0) {
      node.Fail("must hold finite numbers within 1000 (no NaN or inf)");
    }
  }
  return v;
}

bool IsIdentifier(const std::string& s) {
  if (s.empty() || std::isdigit(static_cast<unsigned char>(s[0]))) return false;
  for (char c : s) {
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_' && c != '-') return false;
  }
  return true;
}

// `frames:` name -> {T_base_frame, covariance}.
std::vector<DeclaredFramePose> ReadFramePoses(const ConfigNode& node) {
  if (!node.IsMap()) node.Fail("expected a map: frame -> {T_base_frame, covariance}");
  std::vector<DeclaredFramePose> out;
  for (const std::string& name : node.Keys()) {
    const ConfigNode f = node.Child(name);
    if (!IsIdentifier(name) || name == "base") {
      f.Fail("a measurement frame's name is an identifier other than 'base'");
    }
    DeclaredFramePose fp;
    fp.name = name;
    fp.where = f.WhereKey();
    const ConfigNode pose = f.Child("T_base_frame");
    const std::vector<double> v = ReadFinite(pose, 7, "[x, y, z, qw, qx, qy, qz]");
    const Quat q = QuatFromWxyz(v.data() + 3);
    if (std::abs(q.norm() - 1.0) > 1e-6) pose.Fail("quaternion is not of unit length");
    fp.T_base_frame = lie::SE3(q.normalized().toRotationMatrix(), Vec3(v[0], v[1], v[2]));
    if (const auto cov = f.Optional("covariance")) fp.cov = ReadPdMatrix(*cov, 6);
    out.push_back(std::move(fp));
  }
  return out;
}

// `marker_offsets:` frame -> {offset_m, covariance}; each the end effector or an observed frame.
std::vector<DeclaredMarkerOffset> ReadMarkerOffsets(const ConfigNode& node,
                                                    const DeclaredModel& d) {
  if (!node.IsMap()) node.Fail("expected a map: observed frame -> {offset_m, covariance}");
  std::vector<DeclaredMarkerOffset> out;
  for (const std::string& name : node.Keys()) {
    const ConfigNode m = node.Child(name);
    if (name != d.end_effector && std::find(d.observed_frames.begin(), d.observed_frames.end(),
                                            name) == d.observed_frames.end()) {
      m.Fail("'" + CapForMessage(name) +
             "' is neither the end effector nor one of observed_frames");
    }
    DeclaredMarkerOffset mo;
    mo.frame = name;
    mo.where = m.WhereKey();
    const std::vector<double> v = ReadFinite(m.Child("offset_m"), 3, "[dx, dy, dz] in metres");
    mo.offset_m = Vec3(v[0], v[1], v[2]);
    if (const auto cov = m.Optional("covariance")) mo.cov = ReadPdMatrix(*cov, 3);
    out.push_back(std::move(mo));
  }
  return out;
}

// `fitted_under:` {joint_range_deg: {joint: [min, max]}, source_scale, constrained_sources,
// kept_declared_sources}. The joints' names are checked where a run compares its own.
FittedUnder ReadFittedUnder(const ConfigNode& node) {
  FittedUnder f;
  f.where = node.WhereKey();
  for (const bool slide : {false, true}) {
    const auto ranges = node.Optional(slide ? "joint_range_m" : "joint_range_deg");
    if (!ranges) continue;
    const char* unit = slide ? "metres" : "degrees";
    if (!ranges->IsMap())
      ranges->Fail(std::string("expected a map: joint -> [min, max] in ") + unit);
    for (const std::string& joint : ranges->Keys()) {
      const ConfigNode r = ranges->Child(joint);
      const std::vector<double> v =
          ReadFinite(r, 2, slide ? "[min, max] in metres" : "[min, max] in degrees");
      if (v[0] > v[1]) r.Fail("min must not exceed max");
      const double k = slide ? 1.0 : M_PI / 180.0;
      f.joint_ranges.push_back({joint, v[0] * k, v[1] * k, slide});
    }
  }
  if (f.joint_ranges.empty()) node.Fail("needs joint_range_deg or joint_range_m");
  if (const auto torques = node.Optional("gravity_torque_nm")) {
    if (!torques->IsMap()) torques->Fail("expected a map: joint -> [min, max] in N m");
    for (const std::string& joint : torques->Keys()) {
      const ConfigNode r = torques->Child(joint);
      const std::vector<double> v = ReadFinite(r, 2, "[min, max] in N m");
      if (v[0] > v[1]) r.Fail("min must not exceed max");
      f.gravity_torques.push_back({joint, v[0], v[1]});
    }
  }
  if (const auto box = node.Optional("end_effector_box_m")) {
    const std::vector<double> lo = ReadFinite(box->Child("min"), 3, "[x, y, z] in metres");
    const std::vector<double> hi = ReadFinite(box->Child("max"), 3, "[x, y, z] in metres");
    for (int i = 0; i < 3; ++i) {
      if (lo[i] > hi[i]) box->Child("max").Fail("must not be below min in any coordinate");
      f.box_min[i] = lo[i];
      f.box_max[i] = hi[i];
    }
    f.has_box = true;
  }
  const ConfigNode scale = node.Child("source_scale");
  f.source_scale = scale.AsDouble();
  if (!(std::isfinite(f.source_scale) && f.source_scale > 0.0)) {
    scale.Fail("must be a positive finite number");
  }
  if (const auto c = node.Optional("constrained_sources")) f.constrained_sources = ReadNames(*c);
  if (const auto k = node.Optional("kept_declared_sources")) {
    f.kept_declared_sources = ReadNames(*k);
  }
  return f;
}

}  // namespace

Vec3 DeclaredModel::MarkerOffset(const std::string& frame) const {
  for (const DeclaredMarkerOffset& m : marker_offsets) {
    if (m.frame == frame) return m.offset_m;
  }
  return Vec3::Zero();
}

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
    for (const ConfigNode& s : sources->Items()) d.sources.push_back(ReadSource(s));
  }
  if (const auto fx = node.Optional("identified_effects")) {
    for (const ConfigNode& e : fx->Items()) d.identified_effects.push_back(ReadIdentifiedEffect(e));
  }
  if (const auto coupled = node.Optional("coupled")) d.coupled = ReadCouplings(*coupled);
  if (const auto frames = node.Optional("frames")) d.frames = ReadFramePoses(*frames);
  if (const auto mo = node.Optional("marker_offsets")) d.marker_offsets = ReadMarkerOffsets(*mo, d);
  if (const auto fu = node.Optional("fitted_under")) d.fitted_under = ReadFittedUnder(*fu);
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

namespace {

// The reader refuses NaN and inf: refuse them here rather than write a file nothing can load.
void CheckFinite(const DeclaredModel& d) {
  const auto fail = [&](const std::string& what) {
    throw InputError("declared model from " + CapForMessage(d.file) + ": " + what +
                     " is not finite; nothing written");
  };
  for (const DeclaredSource& s : d.sources) {
    if (!s.cov.allFinite() || !std::isfinite(s.about_axis_rad)) fail("source at '" + s.at + "'");
  }
  for (const IdentifiedEffect& e : d.identified_effects) {
    for (const std::vector<double>* v : {&e.value, &e.std}) {
      for (double x : *v) {
        if (!std::isfinite(x)) fail("identified effect '" + e.effect + "'");
      }
    }
  }
  for (const DeclaredCoupling& c : d.coupled) {
    for (const auto& [driver, coef] : c.drivers) {
      if (!std::isfinite(coef)) fail("coupling of '" + c.joint + "'");
    }
  }
  for (const DeclaredFramePose& f : d.frames) {
    if (!f.T_base_frame.Matrix().allFinite() || !f.cov.allFinite()) fail("frame '" + f.name + "'");
  }
  for (const DeclaredMarkerOffset& m : d.marker_offsets) {
    if (!m.offset_m.allFinite() || !m.cov.allFinite()) fail("marker offset of '" + m.frame + "'");
  }
}

void EmitNames(YAML::Emitter& y, const char* key, const std::vector<std::string>& names) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << names;
}

// Every digit: these numbers are the model.
void EmitExact(YAML::Emitter& y, const char* key, const std::vector<double>& v) {
  y << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (double x : v) y << YAML::DoublePrecision(17) << x;
  y << YAML::EndSeq;
}

void EmitCouplings(YAML::Emitter& y, const std::vector<DeclaredCoupling>& coupled) {
  y << YAML::Key << "coupled" << YAML::Value << YAML::BeginMap;
  for (const DeclaredCoupling& c : coupled) {
    y << YAML::Key << c.joint << YAML::Value;
    if (c.from_mjcf) {
      y << "mjcf";
      continue;
    }
    y << YAML::Flow << YAML::BeginMap;
    for (const auto& [driver, coef] : c.drivers) {
      y << YAML::Key << driver << YAML::Value << YAML::DoublePrecision(17) << coef;
    }
    y << YAML::EndMap;
  }
  y << YAML::EndMap;
}

void EmitSources(YAML::Emitter& y, const std::vector<DeclaredSource>& sources) {
  y << YAML::Key << "sources" << YAML::Value << YAML::BeginSeq;
  for (const DeclaredSource& s : sources) {
    y << YAML::BeginMap << YAML::Key << "at" << YAML::Value << s.at;
    // Exactly zero, not Eigen's isZero: a source scaled down to 1e-13 still says something.
    const bool has_cov = (s.cov.array() != 0.0).any();
    // A source of zero is still a source: the reader needs one of its keys.
    if (s.about_axis_rad > 0 || !has_cov) {
      y << YAML::Key << "about_axis_deg" << YAML::Value << s.about_axis_rad / (M_PI / 180.0);
    }
    if (has_cov) {
      std::vector<double> rows(36);
      for (int k = 0; k < 36; ++k) rows[k] = s.cov(k / 6, k % 6);
      y << YAML::Key << "covariance" << YAML::Value << YAML::Flow << rows;
    }
    y << YAML::EndMap;
  }
  y << YAML::EndSeq;
}

void EmitIdentifiedEffects(YAML::Emitter& y, const std::vector<IdentifiedEffect>& effects) {
  y << YAML::Key << "identified_effects" << YAML::Value << YAML::BeginSeq;
  for (const IdentifiedEffect& e : effects) {
    y << YAML::BeginMap << YAML::Key << "effect" << YAML::Value << e.effect;
    if (!e.equivalent.empty()) EmitNames(y, "equivalent", e.equivalent);
    // Every digit: the values are the model (re-scoring it reproduces the fit's errors).
    EmitExact(y, "value", e.value);
    y << YAML::Key << "std" << YAML::Value << YAML::Flow << e.std;
    y << YAML::Key << "unit" << YAML::Value << e.unit << YAML::EndMap;
  }
  y << YAML::EndSeq;
}

// Every digit for what places a frame (it is the model); `digits` for the covariance. A
// covariance that is not positive definite (a direction the fit could not determine) is left
// out: the reader refuses it.
template <int N>
void EmitPoseCovariance(YAML::Emitter& y, const Eigen::Matrix<double, N, N>& cov) {
  if (cov.isZero(0.0) || cov.llt().info() != Eigen::Success) return;
  std::vector<double> rows(N * N);
  for (int k = 0; k < N * N; ++k) rows[k] = cov(k / N, k % N);
  y << YAML::Key << "covariance" << YAML::Value << YAML::Flow << rows;
}

void EmitFramePoses(YAML::Emitter& y, const std::vector<DeclaredFramePose>& frames) {
  y << YAML::Key << "frames" << YAML::Value << YAML::BeginMap;
  for (const DeclaredFramePose& f : frames) {
    const Vec3& t = f.T_base_frame.translation();
    const Quat q(f.T_base_frame.rotation());
    y << YAML::Key << f.name << YAML::Value << YAML::BeginMap;
    EmitExact(y, "T_base_frame", {t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z()});
    EmitPoseCovariance<6>(y, f.cov);
    y << YAML::EndMap;
  }
  y << YAML::EndMap;
}

void EmitMarkerOffsets(YAML::Emitter& y, const std::vector<DeclaredMarkerOffset>& offsets) {
  y << YAML::Key << "marker_offsets" << YAML::Value << YAML::BeginMap;
  for (const DeclaredMarkerOffset& m : offsets) {
    y << YAML::Key << m.frame << YAML::Value << YAML::BeginMap;
    EmitExact(y, "offset_m", {m.offset_m.x(), m.offset_m.y(), m.offset_m.z()});
    EmitPoseCovariance<3>(y, m.cov);
    y << YAML::EndMap;
  }
  y << YAML::EndMap;
}

// Ranges in degrees at `digits` digits, widened outward by one unit of the last digit kept, so
// the rows the ranges were taken from stay inside them when read back.
void EmitFittedUnder(YAML::Emitter& y, const FittedUnder& f, int digits) {
  y << YAML::Key << "fitted_under" << YAML::Value << YAML::BeginMap;
  const auto outward = [digits](double x, double dir) {
    if (x == 0.0) return 0.0;
    const double ulp = std::pow(10.0, std::floor(std::log10(std::abs(x))) - digits + 1);
    return (dir > 0 ? std::ceil(x / ulp) : std::floor(x / ulp)) * ulp;
  };
  for (const bool slide : {false, true}) {
    const double k = slide ? 1.0 : 180.0 / M_PI;
    bool open = false;
    for (const FittedUnder::JointRange& r : f.joint_ranges) {
      if (r.slide != slide) continue;
      if (!open) {
        y << YAML::Key << (slide ? "joint_range_m" : "joint_range_deg") << YAML::Value
          << YAML::BeginMap;
        open = true;
      }
      y << YAML::Key << r.joint << YAML::Value << YAML::Flow << YAML::BeginSeq
        << outward(r.min * k, -1.0) << outward(r.max * k, 1.0) << YAML::EndSeq;
    }
    if (open) y << YAML::EndMap;
  }
  if (!f.gravity_torques.empty()) {
    y << YAML::Key << "gravity_torque_nm" << YAML::Value << YAML::BeginMap;
    for (const FittedUnder::TorqueRange& r : f.gravity_torques) {
      y << YAML::Key << r.joint << YAML::Value << YAML::Flow << YAML::BeginSeq
        << outward(r.min, -1.0) << outward(r.max, 1.0) << YAML::EndSeq;
    }
    y << YAML::EndMap;
  }
  if (f.has_box) {
    y << YAML::Key << "end_effector_box_m" << YAML::Value << YAML::BeginMap;
    for (const bool upper : {false, true}) {
      y << YAML::Key << (upper ? "max" : "min") << YAML::Value << YAML::Flow << YAML::BeginSeq;
      for (int i = 0; i < 3; ++i) {
        y << outward(upper ? f.box_max[i] : f.box_min[i], upper ? 1.0 : -1.0);
      }
      y << YAML::EndSeq;
    }
    y << YAML::EndMap;
  }
  y << YAML::Key << "source_scale" << YAML::Value << f.source_scale;
  EmitNames(y, "constrained_sources", f.constrained_sources);
  EmitNames(y, "kept_declared_sources", f.kept_declared_sources);
  y << YAML::EndMap;
}

}  // namespace

std::string EmitDeclaredModel(const DeclaredModel& d, const std::string& header, int digits) {
  CheckFinite(d);
  YAML::Emitter y;
  y.SetDoublePrecision(digits);
  if (!header.empty()) y << YAML::Comment(header);
  y << YAML::BeginMap;
  y << YAML::Key << "model" << YAML::Value << d.model_path;
  y << YAML::Key << "base" << YAML::Value << d.base;
  EmitNames(y, "actuated_joints", d.actuated_joints);
  y << YAML::Key << "end_effector" << YAML::Value << d.end_effector;
  if (!d.observed_frames.empty()) EmitNames(y, "observed_frames", d.observed_frames);
  if (!d.coupled.empty()) EmitCouplings(y, d.coupled);
  if (!d.sources.empty()) EmitSources(y, d.sources);
  if (!d.identified_effects.empty()) EmitIdentifiedEffects(y, d.identified_effects);
  if (!d.frames.empty()) EmitFramePoses(y, d.frames);
  if (!d.marker_offsets.empty()) EmitMarkerOffsets(y, d.marker_offsets);
  if (!d.fitted_under.empty()) EmitFittedUnder(y, d.fitted_under, digits);
  y << YAML::EndMap;
  return std::string(y.c_str()) + "\n";
}

}  // namespace flexbench::sim
