#include "scenarios/runner/common/truth_rig.h"

#include <utility>

namespace flexbench::scenarios {

std::unique_ptr<estimators::Estimator> DeclaredRig::MakeEstimator(const EstimatorSpec& spec,
                                                                  std::uint64_t seed) const {
  return MakeEstimatorOf(spec, setup, seed);
}

DeclaredRig BuildDeclaredRig(const mjModel* nominal, sim::DeclaredModel declared) {
  DeclaredRig rig;
  rig.declared = std::move(declared);
  rig.chain = std::make_unique<sim::DeclaredChain>(sim::BuildDeclaredChain(nominal, rig.declared));
  rig.setup.model = &rig.chain->model;
  rig.setup.effects = rig.chain->effects_or_null();
  rig.setup.end_effector = rig.chain->end_effector;
  return rig;
}

TruthRig LoadTruthRig(const std::string& model_path, const sim::EffectList& effects,
                      sim::DeclaredModel declared) {
  TruthRig rig;
  rig.sim = sim::Simulation::Load(model_path, effects);
  static_cast<DeclaredRig&>(rig) = BuildDeclaredRig(rig.sim->nominal_model(), std::move(declared));
  return rig;
}

}  // namespace flexbench::scenarios
