// FLEXBENCH_PARTICLE_LOOP marks a function whose loops run over all particles: compiled for
// x86-64-v3 and the baseline, picked at load time (see estimators/target_clones.h). The AVX2
// clone gives the baseline's bits (bench_pf measures what it gains).
#pragma once

#include "estimators/target_clones.h"

#define FLEXBENCH_PARTICLE_LOOP FLEXBENCH_TARGET_CLONES
