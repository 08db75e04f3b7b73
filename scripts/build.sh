#!/usr/bin/env bash
# Configures and builds flexbench. Usage: scripts/build.sh [--sanitize] [extra cmake args]
# Release build in build/, or an ASan+UBSan build in build-asan/ with --sanitize.
set -euo pipefail
cd "$(dirname "$0")/.."

build_dir=build
args=(-DCMAKE_BUILD_TYPE=Release)
if [ "${1:-}" = "--sanitize" ]; then
  shift
  build_dir=build-asan
  args=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DFLEXBENCH_SANITIZE=ON)
fi
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B "$build_dir" "${args[@]}" "$@" >/dev/null
cmake --build "$build_dir" -j "$jobs"
