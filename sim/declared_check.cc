#include "sim/declared_check.h"

#include <filesystem>
#include <set>

#include "sim/config.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"

namespace flexbench::sim {
namespace {

std::vector<ConfigNode> StringItems(const ConfigNode& list) {
  if (!list.IsSequence()) list.Fail("expected a list of names");
  return list.Items();
}

void CheckStds(const ConfigNode& node) {
  const std::vector<double> v = node.AsDoubleList();
  if (v.size() != 3) node.Fail("expected 3 numbers (about / along x, y, z)");
  for (double x : v) {
    if (x < 0) node.Fail("standard deviations must be >= 0");
  }
}

// The model a declared file names, for "<model> has no <kind> named '<name>'" messages.
struct CheckedModel {
  const mjModel* m;
  std::string file_name;

  bool Has(mjtObj type, const std::string& name) const {
    return mj_name2id(m, type, name.c_str()) >= 0;
  }
  [[noreturn]] void Missing(const ConfigNode& n, const std::string& what,
                            const std::string& name) const {
    n.Fail(file_name + " has no " + what + " named '" + name + "'");
  }
};

std::string ModelPath(const ConfigNode& root) {
  const ConfigNode model_node = root.Child("model");
  const std::string path = model_node.ResolvePath(model_node.AsString());
  if (!std::filesystem::is_regular_file(path)) {
    model_node.Fail("model file '" + path + "' not found");
  }
  return path;
}

std::string CheckBase(const ConfigNode& root, const CheckedModel& model) {
  std::string base = "world";
  if (const auto node = root.Optional("base")) {
    base = node->AsString();
    if (!model.Has(mjOBJ_BODY, base)) model.Missing(*node, "body", base);
  }
  return base;
}

std::vector<std::string> CheckActuatedJoints(const ConfigNode& list, const CheckedModel& model) {
  const mjModel* m = model.m;
  std::vector<std::string> names;
  std::set<std::string> seen;
  for (const ConfigNode& item : StringItems(list)) {
    const std::string name = item.AsString();
    const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    if (j < 0 || (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)) {
      model.Missing(item, "hinge or slide joint", name);
    }
    if (!seen.insert(name).second) item.Fail("joint '" + name + "' listed twice");
    names.push_back(name);
  }
  return names;
}

std::string CheckEndEffector(const ConfigNode& ee, const CheckedModel& model) {
  const std::string name = ee.AsString();
  if (!model.Has(mjOBJ_SITE, name) && !model.Has(mjOBJ_BODY, name)) {
    model.Missing(ee, "site or body", name);
  }
  return name;
}

std::vector<std::string> CheckObservedFrames(const ConfigNode& frames, const CheckedModel& model) {
  std::vector<std::string> names;
  for (const ConfigNode& item : StringItems(frames)) {
    const std::string name = item.AsString();
    if (!model.Has(mjOBJ_SITE, name) && !model.Has(mjOBJ_CAMERA, name) &&
        !model.Has(mjOBJ_GEOM, name) && !model.Has(mjOBJ_BODY, name)) {
      model.Missing(item, "site, camera, geom or body", name);
    }
    names.push_back(name);
  }
  return names;
}

// Returns whether the source gives any uncertainty.
bool CheckSourceUncertainty(const ConfigNode& src, const DeclaredCheckSource& d) {
  bool any = false;
  if (const auto r = src.Optional("std_rot_deg")) {
    CheckStds(*r);
    any = true;
  }
  if (const auto t = src.Optional("std_trans_m")) {
    CheckStds(*t);
    any = true;
  }
  if (const auto a = src.Optional("about_axis_deg")) {
    if (d.at_kind != "joint") a->Fail("about_axis_deg needs a joint ('" + d.at + "' is a body)");
    if (a->AsDouble() < 0) a->Fail("standard deviations must be >= 0");
    any = true;
  }
  if (const auto c = src.Optional("covariance")) {
    if (c->AsDoubleList().size() != 36) c->Fail("expected 36 numbers (a 6x6 covariance)");
    any = true;
  }
  return any;
}

DeclaredCheckSource CheckSource(const ConfigNode& src, const CheckedModel& model) {
  const ConfigNode at = src.Child("at");
  DeclaredCheckSource d;
  d.at = at.AsString();
  if (model.Has(mjOBJ_JOINT, d.at)) {
    d.at_kind = "joint";
  } else if (model.Has(mjOBJ_BODY, d.at)) {
    d.at_kind = "body";
  } else {
    model.Missing(at, "joint or body", d.at);
  }
  if (!CheckSourceUncertainty(src, d)) {
    src.Fail("a source needs std_rot_deg, std_trans_m, about_axis_deg or covariance");
  }
  return d;
}

std::vector<DeclaredCheckSource> CheckSources(const ConfigNode& sources,
                                              const CheckedModel& model) {
  if (!sources.IsSequence()) sources.Fail("expected a list of {at, std_rot_deg, ...}");
  std::vector<DeclaredCheckSource> out;
  for (const ConfigNode& src : sources.Items()) out.push_back(CheckSource(src, model));
  return out;
}

}  // namespace

DeclaredCheckSummary CheckDeclaredFile(const std::string& path) {
  const ConfigNode root = ConfigNode::LoadFile(path);
  // The format is the reader's (every key it knows, identified effects and couplings included,
  // with its limits); what follows checks the names against the model.
  ParseDeclaredModel(root);
  DeclaredCheckSummary s;
  s.file = path;
  s.model_path = ModelPath(root);
  const MjModelPtr model = LoadModel(s.model_path);
  const CheckedModel checked{model.get(), std::filesystem::path(s.model_path).filename().string()};
  s.base = CheckBase(root, checked);
  s.actuated_joints = CheckActuatedJoints(root.Child("actuated_joints"), checked);
  s.end_effector = CheckEndEffector(root.Child("end_effector"), checked);
  if (const auto frames = root.Optional("observed_frames")) {
    s.observed_frames = CheckObservedFrames(*frames, checked);
  }
  if (const auto sources = root.Optional("sources")) {
    s.sources = CheckSources(*sources, checked);
  }
  root.CheckNoUnknownKeys();
  return s;
}

}  // namespace flexbench::sim
