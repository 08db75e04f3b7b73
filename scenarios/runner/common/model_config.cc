#include "scenarios/runner/common/model_config.h"

namespace flexbench::scenarios {

sim::DeclaredModel ReadModelAndDeclared(const ConfigNode& root, std::string* model_path) {
  const ConfigNode model = root.Child("model");
  *model_path = model.ResolvePath(model.AsString());
  const ConfigNode declared = root.Child("declared");
  sim::DeclaredModel d = declared.IsMap()
                             ? sim::ParseDeclaredModel(declared)
                             : sim::LoadDeclaredModel(declared.ResolvePath(declared.AsString()));
  if (declared.IsMap()) d.model_path = *model_path;
  return d;
}

}  // namespace flexbench::scenarios
