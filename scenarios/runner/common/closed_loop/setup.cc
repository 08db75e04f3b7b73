#include "scenarios/runner/common/closed_loop/setup.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <type_traits>

#include "estimators/conventions.h"
#include "estimators/error.h"
#include "estimators/format.h"
#include "estimators/kinematics/effect_table.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/runner/common/closed_loop/heldout_replay.h"
#include "scenarios/runner/common/closed_loop/sources.h"
#include "scenarios/runner/common/closed_loop/truth.h"
#include "scenarios/runner/common/model_config.h"
#include "scenarios/runner/common/render_config.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

// True when two files are one or hold the same bytes: "validating" on the calibration rows
// reports the fit, not a held-out error.
bool SameRows(const std::string& a, const std::string& b) {
  std::error_code ec;
  if (fs::equivalent(a, b, ec)) return true;
  const std::uintmax_t size_a = fs::file_size(a, ec);
  if (ec) return false;
  const std::uintmax_t size_b = fs::file_size(b, ec);
  if (ec || size_a != size_b) return false;
  std::ifstream fa(a, std::ios::binary), fb(b, std::ios::binary);
  return fa && fb &&
         std::equal(std::istreambuf_iterator<char>(fa), std::istreambuf_iterator<char>(),
                    std::istreambuf_iterator<char>(fb), std::istreambuf_iterator<char>());
}

// `tracker`: simulated data are tracker rows (truth.tracker), not sockets.
Source ParseSource(const ConfigNode& n, bool tracker) {
  Source s;
  s.where = n.Where();
  if (const auto m = n.Optional("mukca")) {
    s.type = Source::Type::kMukca;
    s.path = m->ResolvePath(m->GetString("dir"));
    for (const ConfigNode& p : m->Child("placements").Items()) s.placements.push_back(p.AsString());
    s.socket_distance_m = m->GetDouble("socket_distance_m", 0.05);
  } else if (const auto c = n.Optional("csv")) {
    s.type = Source::Type::kCsv;
    s.path = c->ResolvePath(c->AsString());
    s.path_where = c->WhereKey();
    if (const auto d = n.Optional("distances")) {
      for (const ConfigNode& e : d->Items()) {
        const std::vector<ConfigNode> it = e.Items();
        if (it.size() != 3) e.Fail("expected [group_a, group_b, metres]");
        const double m = it[2].AsDouble();
        // As MUKCa's socket_distance_m (a negative distance was fitted silently).
        if (!(std::isfinite(m) && m > 0.0 && m <= 10.0)) {
          it[2].Fail("a distance must be > 0 and at most 10 m");
        }
        if (it[0].AsString() == it[1].AsString()) e.Fail("a distance needs two different groups");
        s.distances.emplace_back(it[0].AsString(), it[1].AsString(), m);
      }
    }
  } else if (const auto sim = n.Optional("simulate")) {
    s.type = Source::Type::kSimulate;
    s.seed = sim->GetInt("seed", 0);
    if (tracker) {
      s.postures = sim->GetInt("postures");
      if (s.postures < 3 || s.postures > 100000) sim->Child("postures").Fail("need 3 to 100000");
      return s;
    }
    s.sim_placements = sim->GetInt("placements", 3);
    s.per_socket = sim->GetInt("configurations_per_socket", 20);
    if (s.sim_placements < 1 || s.per_socket < 2) sim->Fail("need placements >= 1 and >= 2 rows");
  } else if (const auto log = n.Optional("log")) {
    s.type = Source::Type::kLog;
    s.path = log->ResolvePath(log->GetString("dir"));
    s.path_where = log->Child("dir").WhereKey();
    s.from_s = log->GetDouble("from_s", s.from_s);
    s.to_s = log->GetDouble("to_s", s.to_s);
    s.frame = log->GetString("frame", "");
    if (!(s.from_s < s.to_s) || std::isnan(s.from_s) || std::isnan(s.to_s)) {
      log->Fail("needs from_s < to_s (seconds on the log's clock)");
    }
    if (const auto st = log->Optional("streams")) {
      s.streams.clear();
      s.streams_named = true;
      for (const ConfigNode& e : st->Items()) {
        const std::string v = e.AsString();
        if (v != "truth" && v != "tags" && v != "imu") e.Fail("expected truth, tags or imu");
        if (!s.streams.insert(v).second) e.Fail("'" + v + "' twice");
      }
      if (s.streams.empty()) st->Fail("names no stream");
    }
    if (const auto st = log->Optional("static")) {
      if (!s.streams.count("imu"))
        st->Fail("applies to the imu stream, which `streams` leaves out");
      identify::StaticWindowOptions& w = s.still;
      for (auto [key, value] : {std::pair{"min_s", &w.min_s},
                                {"gyro_max_rad_s", &w.gyro_max_rad_s},
                                {"joint_span_rad", &w.joint_span_rad}}) {
        *value = st->GetDouble(key, *value);
        if (!(*value > 0.0 && *value < 1e6)) st->Child(key).Fail("must be > 0 and below 1e6");
      }
    }
  } else {
    n.Fail("expected one of mukca, csv, simulate, log");
  }
  return s;
}

// A frame the declared file gives a pose for (`frames:`, a fit's result) starts its fit there
// unless the scenario gives its own guess or prior.
void StartFramesAtDeclaredPoses(ClosedLoopSetup& cl) {
  for (const sim::DeclaredFramePose& fp : cl.declared.frames) {
    const auto it = std::find_if(cl.frames.begin(), cl.frames.end(),
                                 [&](const auto& f) { return f.name == fp.name; });
    if (it == cl.frames.end()) {
      cl.unused_frames.push_back(fp.name);
    } else if (!it->has_guess) {
      it->T_ref = fp.T_base_frame;
      it->has_guess = true;
    }
  }
}

// The identification's settings (noise levels, selection, cross-validation, outliers).
void ParseOptions(ClosedLoopSetup& cl, const ConfigNode& root) {
  identify::IdentifyOptions& o = cl.opt;
  const auto read = [&root](const char* key, auto* value) {
    if (!root.Has(key)) return;
    if constexpr (std::is_same_v<std::remove_pointer_t<decltype(value)>, int>) {
      *value = root.GetInt(key);
    } else {
      *value = root.GetDouble(key);
    }
    CheckIdentifyOption(key, *value, root.Child(key).WhereKey());
  };
  read("point_std_m", &o.point_std_m);
  read("distance_std_m", &o.distance_std_m);
  read("rotation_std_rad", &o.rotation_std_rad);
  read("pixel_std_px", &o.pixel_std_px);
  read("gravity_std_rad", &o.gravity_std_rad);
  read("bic_threshold", &o.bic_threshold);
  // The joint readings' noise, when known (an encoder's resolution): the validation NEES that
  // sizes the augmented model's sources then takes the rows' noise from it (see RowNoise).
  if (root.Has("reading_std_deg")) {
    const double deg = root.GetDouble("reading_std_deg");
    CheckIdentifyOption("reading_std_deg", deg, root.Child("reading_std_deg").WhereKey());
    cl.reading_std_rad = deg * kDeg;
  }
  read("max_effects", &o.max_effects);
  read("time_budget_s", &o.time_budget_s);
  o.cross_validation = root.GetBool("cross_validation", o.cross_validation);
  if (root.Has("folds_by")) {
    o.folds_by = root.GetString("folds_by");
    CheckFoldsBy(o.folds_by, root.Child("folds_by").WhereKey());
  }
  read("cv_min_gain", &o.cv_min_gain);
  // Threads of the identification's row passes (0: one per core); the results' bits do not
  // depend on it.
  read("threads", &o.threads);
  read("outlier_iqr", &o.outlier_iqr);
  read("diagnostic_p", &o.diagnostic_p);
}

// A fixed camera seeing the end-effector point (pixel rows in CSV data).
void ParseCamera(ClosedLoopSetup& cl, const ConfigNode& root) {
  const auto c = root.Optional("camera");
  if (!c) return;
  cl.camera.present = true;
  cl.camera.name = c->GetString("name", "camera");
  cl.camera.intrinsics.fx = c->GetDouble("fx");
  cl.camera.intrinsics.fy = c->GetDouble("fy");
  cl.camera.intrinsics.cx = c->GetDouble("cx");
  cl.camera.intrinsics.cy = c->GetDouble("cy");
  const ConfigNode t = c->Child("T_base_cam");
  const std::vector<double> v = t.AsDoubleList();
  if (v.size() != 7) t.Fail("expected [x, y, z, qw, qx, qy, qz]");
  const Eigen::Quaterniond qt(v[3], v[4], v[5], v[6]);
  if (std::abs(qt.norm() - 1.0) > 1e-6) t.Fail("quaternion is not of unit length");
  cl.camera.T_base_cam = lie::SE3(qt.normalized().toRotationMatrix(), Vec3(v[0], v[1], v[2]));
}

// An effect or candidate name ("gravity_tilt", "gravity_tilt@base") of the base's tilt.
bool IsGravityTilt(const std::string& name) {
  const kinematics::EffectRow* row = kinematics::FindEffect(name.substr(0, name.find('@')));
  return row != nullptr && row->kind == kinematics::EffectKind::kGravityTilt;
}

// External measurement frames, the gravity-tilt candidate, markers and their offsets.
void ParseFramesAndMarkers(ClosedLoopSetup& cl, const ConfigNode& root) {
  // External measurement frames (a tracker) the CSV's `frame` column may name.
  // Frames set already (the identify command's --frame) keep their place; a key of the same
  // name (--set frames.<name>...) is read over one.
  if (const auto f = root.Optional("frames")) {
    std::vector<identify::MeasurementFrame> keyed = identify::ParseMeasurementFrames(*f);
    for (identify::MeasurementFrame& frame : cl.frames) {
      const auto same = std::find_if(keyed.begin(), keyed.end(),
                                     [&](const auto& k) { return k.name == frame.name; });
      if (same == keyed.end()) continue;
      frame = *same;
      keyed.erase(same);
    }
    cl.frames.insert(cl.frames.end(), keyed.begin(), keyed.end());
  }
  StartFramesAtDeclaredPoses(cl);
  // The gravity direction (a base mounted tilted) as a candidate: by default with data in an
  // external frame, whose fitted pose leaves the base's tilt to be seen through the loads
  // alone; else when asked for, by this key or by name in `candidates`.
  cl.gravity_tilt = root.GetBool("gravity_tilt", !cl.frames.empty());
  // A tilt the declared file already carries is applied (EffectModel::SetBaseEffects).
  for (const sim::IdentifiedEffect& e : cl.declared.identified_effects) {
    cl.gravity_tilt |= IsGravityTilt(e.effect);
  }
  for (const auto& spec : cl.candidate_specs) {
    if (IsGravityTilt(spec.first) && !root.Has("gravity_tilt")) cl.gravity_tilt = true;
  }
  // A key replaces the list set already (the command's --marker, --unknown-marker-offset).
  if (const auto mk = root.Optional("markers")) {
    cl.marker_nodes.clear();
    for (const ConfigNode& n : mk->Items()) cl.marker_nodes.push_back({n.AsString(), n.Where()});
  }
  if (const auto u = root.Optional("unknown_marker_offsets")) {
    cl.unknown_offset_nodes.clear();
    for (const ConfigNode& n : u->Items()) {
      cl.unknown_offset_nodes.push_back({n.AsString(), n.Where()});
    }
  }
}

// calibration and validation data sources, checked against the truth block.
// `sources`: read them from the keys (else they are set already: the identify command's).
void ParseSources(ClosedLoopSetup& cl, const ConfigNode& root, bool sources) {
  if (sources) {
    cl.calibration = ParseSource(root.Child("calibration"), cl.truth.tracker.has_value());
    cl.validation = ParseSource(root.Child("validation"), cl.truth.tracker.has_value());
  }
  if ((cl.calibration.type == Source::Type::kSimulate ||
       cl.validation.type == Source::Type::kSimulate) &&
      !cl.truth.present) {
    root.Fail("simulated data needs a 'truth' block (effects, expected, workspace)");
  }
  if (cl.truth.tracker && cl.calibration.type != Source::Type::kSimulate) {
    root.Child("truth").Child("tracker").Fail(
        "simulates tracker rows: needs simulated calibration");
  }
  if (cl.calibration.type == Source::Type::kCsv && cl.validation.type == Source::Type::kCsv &&
      SameRows(cl.calibration.path, cl.validation.path)) {
    throw InputError(cl.validation.path_where + ": " + CapForMessage(cl.validation.path) +
                     " holds the same rows as the calibration file; validate on other data");
  }
  if (cl.calibration.type == Source::Type::kLog && cl.validation.type == Source::Type::kLog &&
      fs::weakly_canonical(cl.calibration.path) == fs::weakly_canonical(cl.validation.path) &&
      cl.calibration.from_s <= cl.validation.to_s && cl.validation.from_s <= cl.calibration.to_s) {
    throw InputError(cl.validation.where + ": the time span " + Span(cl.validation) +
                     " overlaps the calibration's, " + Span(cl.calibration) +
                     ", of the same log; validate on a held-out span (from_s, to_s)");
  }
  if (cl.validation.type == Source::Type::kLog) {
    cl.replay_specs =
        root.Has("replay_estimators")
            ? ParseEstimators(root.Child("replay_estimators"), EstimatorLabels::kAllowed)
            : std::vector<EstimatorSpec>{{"fk", {}, "fk", ""}};
  } else if (root.Has("replay_estimators")) {
    root.Child("replay_estimators")
        .Fail("replays a held-out log span: needs validation: {log: ...}");
  }
  if (const auto e = root.Optional("expected_effects")) {
    if (cl.truth.present) e->Fail("the truth block's `expected` names them already");
    for (const ConfigNode& n : e->Items()) {
      cl.truth_names.push_back(n.AsString());
      cl.expected_nodes.push_back({n.AsString(), n.Where()});
    }
  }
  for (const Source* s : {&cl.calibration, &cl.validation}) {
    if (s->type == Source::Type::kMukca && !fs::exists(s->path)) {
      throw InputError(s->where + ": MUKCa recordings not found at " + s->path +
                       " (read from ../shared/data/mukca; see its SOURCE.md)");
    }
  }
}

// The candidates named in `candidates` (all when none is named): each must exist.
void SelectCandidates(ClosedLoopSetup& cl) {
  if (cl.candidate_specs.empty()) {
    for (size_t i = 0; i < cl.em->candidates().size(); ++i) cl.candidates.push_back(i);
  }
  for (const auto& [spec, where] : cl.candidate_specs) {
    bool any = false;
    for (size_t i = 0; i < cl.em->candidates().size(); ++i) {
      const identify::Candidate& c = cl.em->candidates()[i];
      if (c.Name() == spec || identify::ToString(c.type) == spec) {
        if (std::find(cl.candidates.begin(), cl.candidates.end(), static_cast<int>(i)) ==
            cl.candidates.end()) {
          cl.candidates.push_back(static_cast<int>(i));
        }
        any = true;
      }
    }
    for (const identify::EffectModel::Skipped& sk : cl.em->skipped()) {
      if (!any && sk.name == spec) {
        throw InputError(where + ": candidate effect '" + spec + "' is not offered: " + sk.reason);
      }
    }
    if (!any) throw InputError(where + ": no candidate effect '" + spec + "' on this chain");
  }
}

// The frames the `markers` key names besides the end effector (observed frames of the
// declared model); cl.points their names, the end effector first.
std::vector<kinematics::FrameId> MarkerFrames(ClosedLoopSetup& cl) {
  std::vector<kinematics::FrameId> out;
  cl.points = {cl.declared.end_effector};
  for (const auto& [name, where] : cl.marker_nodes) {
    if (name == cl.declared.end_effector) continue;
    try {
      out.push_back(cl.chain->ObservedFrame(name));
    } catch (const InputError& e) {
      throw InputError(where + ": markers: '" + name +
                       "' is neither the end effector nor an observed frame of the declared "
                       "model (observed_frames)");
    }
    cl.points.push_back(name);
  }
  return out;
}

// Per marker (cl.points): whether its offset on its link is unknown (`unknown_marker_offsets`).
std::vector<char> UnknownOffsets(const ClosedLoopSetup& cl) {
  std::vector<char> out(cl.points.size(), 0);
  for (const auto& [name, where] : cl.unknown_offset_nodes) {
    const auto it = std::find(cl.points.begin(), cl.points.end(), name);
    if (it == cl.points.end()) {
      throw InputError(
          where + ": unknown_marker_offsets: '" + name +
          "' is neither the end effector nor one of 'markers' (--marker on the command line)");
    }
    out[it - cl.points.begin()] = 1;
  }
  return out;
}

}  // namespace

void ReadClosedLoopKeys(const ConfigNode& root, ClosedLoopSetup* out, bool sources) {
  ClosedLoopSetup& cl = *out;
  if (const auto c = root.Optional("candidates")) {
    cl.candidate_specs.clear();
    for (const ConfigNode& n : c->Items()) cl.candidate_specs.push_back({n.AsString(), n.Where()});
  }
  ParseOptions(cl, root);
  ParseCamera(cl, root);
  ParseFramesAndMarkers(cl, root);
  if (const auto t = root.Optional("truth")) ReadTruth(cl, *t);
  cl.detector = ParseDetectorSettings(root);
  ParseSources(cl, root, sources);
}

void BuildClosedLoopSetup(const ConfigNode& root, ClosedLoopSetup* out) {
  ClosedLoopSetup& cl = *out;
  // Model, chain and candidates now: bad names fail before any work.
  cl.mj = sim::LoadModel(cl.declared.model_path);
  cl.chain = std::make_unique<sim::DeclaredChain>(
      sim::BuildDeclaredChain(cl.mj.get(), WithTagCentres(cl), /*with_couplings=*/true));
  if (!cl.camera.present) CameraFromLogs(cl, root);
  ImuFromLogs(cl, root);
  if (cl.validation.type == Source::Type::kLog) CheckHeldOutReplay(cl);
  cl.em = std::make_unique<identify::EffectModel>(cl.mj.get(), *cl.chain, cl.chain->end_effector,
                                                  cl.camera.present ? cl.camera.name : "",
                                                  MarkerFrames(cl), cl.gravity_tilt);
  // The declared file's identified effects are the model identification starts from.
  cl.base_not_applied = cl.em->SetBaseEffects(cl.declared.identified_effects);
  cl.offset_unknown = UnknownOffsets(cl);
  SelectCandidates(cl);
  for (const auto& [name, where] : cl.expected_nodes) {
    if (cl.em->FindCandidate(name) < 0) {
      throw InputError(where + ": expected_effects: '" + name +
                       "' is no candidate effect on this chain");
    }
  }
  if (cl.truth.present) {
    cl.truth.sim = sim::Simulation::Load(cl.model_path, cl.truth.effects);
  }
  if (cl.truth.tracker) CheckTrackerTruth(cl);
}

void ReadClosedLoopSetup(const ConfigNode& root, ClosedLoopSetup* cl) {
  cl->declared = ReadModelAndDeclared(root, &cl->model_path);
  ReadClosedLoopKeys(root, cl, /*sources=*/true);
  BuildClosedLoopSetup(root, cl);
}

void CheckIdentifyOption(const std::string& key, double v, const std::string& where) {
  std::string what;
  if (key == "max_effects") {
    if (!(v >= 0.0)) what = "must be >= 0 (leave it out for no cap)";
  } else if (key == "time_budget_s") {
    if (!(v > 0.0 && v <= 1e6)) what = "must be in (0, 1e6] seconds (leave it out for none)";
  } else if (key == "cv_min_gain") {
    if (!(v >= 0.0 && v < 1.0)) what = "must be in [0, 1)";
  } else if (key == "threads") {
    if (!(v >= 0.0 && v <= 64.0)) what = "must be in [0, 64]";
  } else if (key == "outlier_iqr") {
    if (!(v >= 0.0)) what = "must be >= 0 (0: off)";
  } else if (key == "diagnostic_p") {
    if (!(v > 0.0 && v < 1.0)) what = "must be in (0, 1)";
  } else if (!(v > 0.0)) {  // the noise levels and bic_threshold
    what = "must be > 0";
  }
  if (!what.empty()) throw InputError(where + ": " + what);
}

void CheckFoldsBy(const std::string& v, const std::string& where) {
  if (v != "auto" && v != "set" && v != "group" && v != "row") {
    throw InputError(where + ": expected auto, set, group or row");
  }
}

// A log source's time span, for messages.
std::string Span(const Source& s) {
  const bool from = std::isfinite(s.from_s), to = std::isfinite(s.to_s);
  if (!from && !to) return "the whole log";
  if (!from) return "t <= " + ShortNum(s.to_s) + " s";
  if (!to) return "t >= " + ShortNum(s.from_s) + " s";
  return "[" + ShortNum(s.from_s) + ", " + ShortNum(s.to_s) + "] s";
}

identify::Job MakeJob(const ClosedLoopSetup& cl, identify::DataSet cal, identify::DataSet val) {
  identify::Job job;
  job.declared = &cl.declared;
  job.mj = cl.mj.get();
  job.chain = cl.chain.get();
  job.em = cl.em.get();
  job.cal = std::move(cal);
  job.val = std::move(val);
  job.cal_where = cl.calibration.where;
  job.val_where = cl.validation.where;
  job.candidates = cl.candidates;
  job.opt = cl.opt;
  job.reading_std_rad = cl.reading_std_rad;
  return job;
}

}  // namespace flexbench::scenarios
