// Readings of the truth for a declared model, shared by the fusion scenarios.
#pragma once

#include <vector>

#include "estimators/measurement.h"
#include "sim/declared_chain.h"
#include "sim/simulation.h"

namespace flexbench::scenarios {

// The encoders of the declared actuated joints, in the declared q order: the motor-side angle
// (what a motor encoder sees through an elastic or backlashed gear) plus any encoder offset the
// truth carries, relative to MuJoCo's reference qpos0. Noise-free: std = 0.
estimators::JointReading EncoderReading(const sim::Simulation& sim, const sim::DeclaredChain& chain,
                                        double t);

// Where each declared joint (chain.q_joints, in q order) sits among the truth's actuated joints
// (the command vector's order); -1 for one the truth does not actuate (the caller says where).
std::vector<int> ActuatorIndices(const sim::Simulation& sim, const sim::DeclaredChain& chain);

}  // namespace flexbench::scenarios
