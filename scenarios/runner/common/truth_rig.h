// What every kind with estimators builds the same way: the declared model's PPOE chain on a
// nominal MuJoCo model with the estimators' set-up on it (DeclaredRig), and with a truth
// simulation (TruthRig). A kind adds its sensors to the set-up (cameras, IMUs, the reference
// frame) before it makes its estimators.
#pragma once

#include <mujoco/mujoco.h>

#include <cstdint>
#include <memory>
#include <string>

#include "estimators/estimator.h"
#include "scenarios/runner/common/estimator_config.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/effects/effect.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {

struct DeclaredRig {
  sim::DeclaredModel declared;
  std::unique_ptr<sim::DeclaredChain> chain;
  // The chain's model, identified effects and end effector; a kind adds its sensors.
  estimators::EstimatorSetup setup;

  // The estimator of `spec` on `setup` with the spec's parameters and `seed`; bad parameters
  // name the entry's file and line (MakeEstimatorOf).
  std::unique_ptr<estimators::Estimator> MakeEstimator(const EstimatorSpec& spec,
                                                       std::uint64_t seed = 0) const;
};

// The chain of `declared` on `nominal` (sim::BuildDeclaredChain; InputError naming the declared
// file for names the model lacks) and the set-up on it. `nominal` need not outlive the rig.
DeclaredRig BuildDeclaredRig(const mjModel* nominal, sim::DeclaredModel declared);

// The declared rig on the truth's nominal model (its MJCF without the truth's effects).
struct TruthRig : DeclaredRig {
  std::unique_ptr<sim::Simulation> sim;
};

// The truth of `model_path` with `effects`, and `declared` on its nominal model.
TruthRig LoadTruthRig(const std::string& model_path, const sim::EffectList& effects,
                      sim::DeclaredModel declared);

}  // namespace flexbench::scenarios
