// FLEXBENCH_PARTICLE_LOOP marks a function whose loops run over all particles: compiled for
// x86-64-v3 and the baseline, picked at load time (see estimators/target_clones.h). The PF step
// is about 1.5x faster on this machine with the AVX2 clone, bit-identical to the baseline.
#pragma once

#include "estimators/target_clones.h"

#define FLEXBENCH_PARTICLE_LOOP FLEXBENCH_TARGET_CLONES
