#include "sim/truth_model.h"

#include <cmath>

#include "estimators/error.h"
#include "sim/export_model.h"
#include "sim/model_catalog.h"

namespace flexbench::sim {

MjModelPtr LoadTruthModel(const std::string& path, std::vector<std::string>* warnings) {
  if (!IsUrdfPath(path)) return LoadModel(path, warnings);
  ConvertedUrdf mjcf = UrdfToMjcf(path);
  if (warnings) warnings->insert(warnings->end(), mjcf.warnings.begin(), mjcf.warnings.end());
  return LoadModelFromString(mjcf.text, path, warnings);
}

DeclaredModel DeclaredModelOfRobot(const std::string& path) {
  const MjModelPtr model = LoadTruthModel(path);
  const mjModel* m = model.get();
  const ModelCatalog catalog = ModelCatalog::Build(m, path);
  if (catalog.actuated.empty()) {
    throw InputError(CapForMessage(path) +
                     ": no joint has a <position> servo, so none is actuated; write a "
                     "declared-model YAML naming the joints (README: declared models)");
  }
  DeclaredModel d;
  d.file = path;
  d.model_path = path;
  for (int j : catalog.actuated) {
    const std::string name = catalog.Joint(j).name;
    d.actuated_joints.push_back(name);
    DeclaredSource s;
    s.at = name;
    s.about_axis_rad = kDefaultSourceDeg * M_PI / 180.0;
    s.where = path;
    d.sources.push_back(s);
  }
  // From the deepest commanded joint: an MJCF's <actuator> list need not follow the chain.
  const auto depth = [m](int b) {
    int d = 0;
    for (; b > 0; b = m->body_parentid[b]) ++d;
    return d;
  };
  int body = m->jnt_bodyid[catalog.actuated.front()];
  for (int j : catalog.actuated) {
    if (depth(m->jnt_bodyid[j]) > depth(body)) body = m->jnt_bodyid[j];
  }
  for (;;) {
    int only_child = -1, children = 0;
    for (int b = body + 1; b < m->nbody; ++b) {
      if (m->body_parentid[b] == body) only_child = b, ++children;
    }
    if (children != 1) break;
    body = only_child;
  }
  d.end_effector = ObjectName(m, mjOBJ_BODY, body);
  if (d.end_effector.empty()) {
    throw InputError(CapForMessage(path) + ": the end body (body " + std::to_string(body) +
                     ") has no name; write a declared-model YAML naming the end effector");
  }
  return d;
}

}  // namespace flexbench::sim
