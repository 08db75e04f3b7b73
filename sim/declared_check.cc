#include "sim/declared_check.h"

#include <filesystem>
#include <set>

#include "sim/config.h"
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

}  // namespace

DeclaredCheckSummary CheckDeclaredFile(const std::string& path) {
  const ConfigNode root = ConfigNode::LoadFile(path);
  DeclaredCheckSummary s;
  s.file = path;
  const ConfigNode model_node = root.Child("model");
  s.model_path = model_node.ResolvePath(model_node.AsString());
  if (!std::filesystem::is_regular_file(s.model_path)) {
    model_node.Fail("model file '" + s.model_path + "' not found");
  }
  const MjModelPtr model = LoadModel(s.model_path);
  const mjModel* m = model.get();
  const std::string mname = std::filesystem::path(s.model_path).filename().string();
  const auto missing = [&](const ConfigNode& n, const std::string& what, const std::string& name) {
    n.Fail(mname + " has no " + what + " named '" + name + "'");
  };

  s.base = "world";
  if (const auto base = root.Optional("base")) {
    s.base = base->AsString();
    if (mj_name2id(m, mjOBJ_BODY, s.base.c_str()) < 0) missing(*base, "body", s.base);
  }
  std::set<std::string> seen;
  for (const ConfigNode& item : StringItems(root.Child("actuated_joints"))) {
    const std::string name = item.AsString();
    const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
    if (j < 0 || (m->jnt_type[j] != mjJNT_HINGE && m->jnt_type[j] != mjJNT_SLIDE)) {
      missing(item, "hinge or slide joint", name);
    }
    if (!seen.insert(name).second) item.Fail("joint '" + name + "' listed twice");
    s.actuated_joints.push_back(name);
  }
  const ConfigNode ee = root.Child("end_effector");
  s.end_effector = ee.AsString();
  if (mj_name2id(m, mjOBJ_SITE, s.end_effector.c_str()) < 0 &&
      mj_name2id(m, mjOBJ_BODY, s.end_effector.c_str()) < 0) {
    missing(ee, "site or body", s.end_effector);
  }
  if (const auto frames = root.Optional("observed_frames")) {
    for (const ConfigNode& item : StringItems(*frames)) {
      const std::string name = item.AsString();
      if (mj_name2id(m, mjOBJ_SITE, name.c_str()) < 0 &&
          mj_name2id(m, mjOBJ_CAMERA, name.c_str()) < 0 &&
          mj_name2id(m, mjOBJ_GEOM, name.c_str()) < 0 &&
          mj_name2id(m, mjOBJ_BODY, name.c_str()) < 0) {
        missing(item, "site, camera, geom or body", name);
      }
      s.observed_frames.push_back(name);
    }
  }
  if (const auto sources = root.Optional("sources")) {
    if (!sources->IsSequence()) sources->Fail("expected a list of {at, std_rot_deg, ...}");
    for (const ConfigNode& src : sources->Items()) {
      const ConfigNode at = src.Child("at");
      DeclaredCheckSource d;
      d.at = at.AsString();
      if (mj_name2id(m, mjOBJ_JOINT, d.at.c_str()) >= 0) {
        d.at_kind = "joint";
      } else if (mj_name2id(m, mjOBJ_BODY, d.at.c_str()) >= 0) {
        d.at_kind = "body";
      } else {
        missing(at, "joint or body", d.at);
      }
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
        if (d.at_kind != "joint")
          a->Fail("about_axis_deg needs a joint ('" + d.at + "' is a body)");
        if (a->AsDouble() < 0) a->Fail("standard deviations must be >= 0");
        any = true;
      }
      if (const auto c = src.Optional("covariance")) {
        if (c->AsDoubleList().size() != 36) c->Fail("expected 36 numbers (a 6x6 covariance)");
        any = true;
      }
      if (!any) {
        src.Fail("a source needs std_rot_deg, std_trans_m, about_axis_deg or covariance");
      }
      s.sources.push_back(d);
    }
  }
  root.CheckNoUnknownKeys();
  return s;
}

}  // namespace flexbench::sim
