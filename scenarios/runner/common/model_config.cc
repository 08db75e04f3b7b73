#include "scenarios/runner/common/model_config.h"

#include <filesystem>

namespace flexbench::scenarios {

sim::DeclaredModel ReadModelAndDeclared(const ConfigNode& root, std::string* model_path) {
  const ConfigNode model = root.Child("model");
  *model_path = model.ResolvePath(model.AsString());
  const ConfigNode declared = root.Child("declared");
  sim::DeclaredModel d = declared.IsMap()
                             ? sim::ParseDeclaredModel(declared)
                             : sim::LoadDeclaredModel(declared.ResolvePath(declared.AsString()));
  if (declared.IsMap()) {
    // An inline block describes the scenario's model: its own `model:` must name that file
    // (another model there was ignored without a word).
    std::error_code ec;
    // (A scenario model that is missing is reported when it is loaded, naming its own key.)
    if (!std::filesystem::equivalent(d.model_path, *model_path, ec) && !ec) {
      declared.Child("model").Fail("names " + CapForMessage(d.model_path) +
                                   ", not the scenario's model " + CapForMessage(*model_path) +
                                   "; an inline declared block describes the scenario's model: "
                                   "name the same file");
    }
    d.model_path = *model_path;
  }
  return d;
}

}  // namespace flexbench::scenarios
