#!/usr/bin/env bash
# The main job: sets up, builds and runs every scenario in scenarios/ with its gates, writing
# results/<scenario>/{summary.json, *.csv, frames/*.png} (plots included).
# Usage: scripts/run_all.sh [output folder, default results]
set -uo pipefail
cd "$(dirname "$0")/.."

bash scripts/setup.sh || exit 1
bash scripts/build.sh || exit 1
out=${1:-results}
mkdir -p "$out"

failed=()
for scenario in scenarios/*.yaml; do
  name=$(basename "$scenario" .yaml)
  echo "== $name"
  # Real measured data is read from ../shared at run time and never copied here.
  if grep -q "shared/data/" "$scenario" && [ ! -d ../shared/data ]; then
    echo "skipped: measured data not found under ../shared/data (see the scenario's comment)"
    continue
  fi
  build/bin/flexbench run "$scenario" --out "$out/$name" --check-gates
  rc=$?
  [ $rc -eq 0 ] || failed+=("$name (exit $rc)")
done

# The paper claims over seeds (scenarios/sweeps/), all of them; ctest runs a subset.
for sweep in scenarios/sweeps/*.yaml; do
  name=$(basename "$sweep" .yaml)
  echo "== sweep $name"
  rm -rf "$out/sweeps/$name"
  build/bin/flexbench sweep "$sweep" --out "$out/sweeps/$name" -j "$(nproc 2>/dev/null || echo 2)"
  rc=$?
  [ $rc -eq 0 ] || failed+=("sweep $name (exit $rc)")
done

echo
if [ ${#failed[@]} -eq 0 ]; then
  echo "all scenarios passed their gates; results in $out/"
else
  echo "failed: ${failed[*]}"
  exit 1
fi
