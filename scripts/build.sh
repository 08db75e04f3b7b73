#!/usr/bin/env bash
# Configures and builds flexbench. Usage: scripts/build.sh [--sanitize] [--target T]
#   [extra cmake args]
# Release build in build/, or an ASan+UBSan build in build-asan/ with --sanitize; every target
# (tests, benchmarks, the Python module), or only T and what it needs with --target.
set -euo pipefail
cd "$(dirname "$0")/.."

build_dir=build
args=(-DCMAKE_BUILD_TYPE=Release)
if [ "${1:-}" = "--sanitize" ]; then
  shift
  build_dir=build-asan
  args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DFLEXBENCH_SANITIZE=ON)
fi
targets=()
if [ "${1:-}" = "--target" ]; then
  targets=(--target "$2")
  shift 2
fi
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$build_dir" "${args[@]}" "$@" >/dev/null
cmake --build "$build_dir" -j "$jobs" "${targets[@]}"
