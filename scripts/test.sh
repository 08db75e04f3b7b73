#!/usr/bin/env bash
# Sets up, builds and runs every test (unit, integration, accuracy) through ctest.
# Usage: scripts/test.sh [--sanitize] [ctest args, e.g. -L unit]
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh
build_dir=build
build_args=()
if [ "${1:-}" = "--sanitize" ]; then
  shift
  build_dir=build-asan
  build_args=(--sanitize)
  # Mesa's llvmpipe keeps driver allocations until exit; those are not ours.
  export LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp:print_suppressions=0"
  export ASAN_OPTIONS="detect_leaks=1:abort_on_error=0"
fi
bash scripts/build.sh "${build_args[@]}"
jobs=$(nproc 2>/dev/null || echo 2)
cd "$build_dir"
ctest --output-on-failure -j "$jobs" "$@"
