// FLEXBENCH_TARGET_CLONES marks a hot function to be compiled twice on x86-64 with GCC, for
// x86-64-v3 (AVX2, FMA) and for the baseline; glibc's ifunc picks one when the program loads.
// Loops and GCC vector-extension code inside (and everything inlined into it) then run 4-wide
// where the CPU allows, the binary still runs on any x86-64, and struct layouts (Eigen's
// alignment) stay those of the baseline build because only function bodies differ. Results are
// bit-identical between the two: the build pins -ffp-contract=off (no fused multiply-adds) and
// GCC does not reorder floating-point arithmetic without -ffast-math. Sanitizer builds, other
// compilers and -DFLEXBENCH_NO_TARGET_CLONES get the baseline only.
//
// FLEXBENCH_MULTIVERSION (same conditions) is for code that needs a different algorithm per
// CPU rather than the same source compiled twice: it dispatches by hand with
// __builtin_cpu_supports("x86-64-v3") (ForwardKinematicsWithCovariance: 4-wide transports on
// x86-64-v3, 2-wide SSE2 ones on the baseline, where GCC's split of the 4-wide code went through
// memory for the lane shuffles). The baseline's 2-wide code does every element's operations in
// its 4-wide lane's order, so it keeps the same bits (tested), close enough to the x86-64-v3
// path in speed (bench_kinematics) that no variant with other bits is needed.
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && \
    !defined(__SANITIZE_ADDRESS__) && !defined(FLEXBENCH_NO_TARGET_CLONES)
#define FLEXBENCH_TARGET_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#define FLEXBENCH_MULTIVERSION 1
#else
#define FLEXBENCH_TARGET_CLONES
#define FLEXBENCH_MULTIVERSION 0
#endif
