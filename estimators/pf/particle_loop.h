// FLEXBENCH_PARTICLE_LOOP marks a function whose loops run over all particles. On x86-64 with GCC
// it is compiled twice, for x86-64-v3 (AVX2, FMA) and for the baseline, and glibc's ifunc picks
// one when the program loads: the loops vectorise 4-wide where the CPU allows it (the PF step is
// about 1.5x faster on this machine), the binary still runs on any x86-64, and struct layouts
// (Eigen's alignment) stay those of the baseline build because only function bodies differ.
// Results are bit-identical between the two: the build pins -ffp-contract=off (no fused
// multiply-adds) and GCC does not reorder floating-point reductions without -ffast-math.
// Sanitizer builds and other compilers get the baseline only.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && \
    !defined(__SANITIZE_ADDRESS__) && !defined(FLEXBENCH_NO_TARGET_CLONES)
#define FLEXBENCH_PARTICLE_LOOP __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define FLEXBENCH_PARTICLE_LOOP
#endif
