#!/usr/bin/env bash
# The main job: sets up, builds and runs every scenario in scenarios/ with its gates, then every
# sweep at the top of scenarios/sweeps/ (not its subfolders: converged/), writing
# results/<scenario>/{summary.json, report.html, *.csv, frames/*.png, log.txt} and
# results/sweeps/<sweep>/ (each run's summary.json and report.html: --run-files summary).
# Prints one line per scenario as it ends (name, gates passed of total, time, folder) and a
# table at the end (`flexbench summary`); each run's full output is its folder's log.txt.
# Usage: scripts/run_all.sh [--summary | --verbose] [--no-build] [--only GLOB] [output folder]
#   --verbose   the runs' own output on the console instead of one line each
#   --no-build  use the build/ there is (no set-up, no build)
#   --only GLOB only the scenarios and sweeps whose name matches (shell pattern, e.g. 'rover*')
#   output folder: default results
# FLEXBENCH_BIN names another flexbench binary (default build/bin/flexbench).
set -uo pipefail
cd "$(dirname "$0")/.."

verbose=0
build=1
only='*'
while [ $# -gt 0 ]; do
  case "$1" in
    --verbose) verbose=1 ;;
    --summary) verbose=0 ;;
    --no-build) build=0 ;;
    --only)
      [ $# -ge 2 ] || { echo "run_all.sh: --only needs a pattern" >&2; exit 2; }
      only=$2
      shift
      ;;
    -*) echo "run_all.sh: unknown option '$1' (see the usage at the top of the script)" >&2; exit 2 ;;
    *) break ;;
  esac
  shift
done
out=${1:-results}
bin=${FLEXBENCH_BIN:-build/bin/flexbench}
mkdir -p "$out" || exit 2

# Set-up and build output go to a file unless asked for; their last lines when they fail.
quiet_step() {
  local log=$1
  shift
  if [ $verbose -eq 1 ]; then
    "$@"
    return
  fi
  if ! "$@" >>"$log" 2>&1; then
    tail -n 20 "$log"
    echo "failed: $* (full output: $log)"
    return 1
  fi
}
if [ $build -eq 1 ]; then
  [ $verbose -eq 1 ] || echo "setting up and building (output: $out/build_log.txt)"
  : >"$out/build_log.txt"
  quiet_step "$out/build_log.txt" bash scripts/setup.sh || exit 1
  # The runner and its libraries only: scripts/test.sh builds the tests and benchmarks.
  quiet_step "$out/build_log.txt" bash scripts/build.sh --target flexbench || exit 1
fi

failed=()
folders=()
# Runs a command with its output in DIR/log.txt (or on the console with --verbose), then
# prints the one line: name, gates passed of total, wall time, folder.
run_one() {
  local name=$1 dir=$2
  shift 2
  local log="$out/.$name.log.tmp" stamp="$out/.$name.start" start=$SECONDS rc
  # A result older than this run (one that failed before writing its own) is not this run's.
  : >"$stamp"
  if [ $verbose -eq 1 ]; then
    echo "== $name"
    "$@"
    rc=$?
  else
    "$@" >"$log" 2>&1
    rc=$?
  fi
  local took=$((SECONDS - start)) gates="no result"
  if [ "$dir/summary.json" -nt "$stamp" ] || [ "$dir/aggregate.json" -nt "$stamp" ]; then
    folders+=("$dir")
    local tsv
    tsv=$("$bin" summary --tsv "$dir" 2>/dev/null) &&
      gates="gates $(cut -f2 <<<"$tsv")/$(cut -f3 <<<"$tsv")"
    [ $verbose -eq 1 ] || mv -f "$log" "$dir/log.txt"
  fi
  rm -f "$stamp"
  [ $rc -eq 0 ] || failed+=("$name (exit $rc)")
  if [ $verbose -eq 0 ]; then
    local where="$dir"
    if [ -f "$log" ]; then
      mv -f "$log" "$out/$name.log.txt"
      where="$out/$name.log.txt: $(tail -n 1 "$out/$name.log.txt")"
    fi
    printf '%-36s %-12s %5d s  %s%s\n' "$name" "$gates" "$took" "$where" \
      "$([ $rc -eq 0 ] || echo "  (exit $rc)")"
  fi
}

for scenario in scenarios/*.yaml; do
  name=$(basename "$scenario" .yaml)
  # shellcheck disable=SC2053
  [[ $name == $only ]] || continue
  # Real measured data is read from ../shared at run time and never copied here.
  if grep -q "shared/data/" "$scenario" && [ ! -d ../shared/data ]; then
    printf '%-36s skipped: measured data not found under ../shared/data\n' "$name"
    continue
  fi
  run_one "$name" "$out/$name" "$bin" run "$scenario" --out "$out/$name" --check-gates
done

# The paper claims over seeds (scenarios/sweeps/), all of them; ctest runs a subset.
for sweep in scenarios/sweeps/*.yaml; do
  name=$(basename "$sweep" .yaml)
  # shellcheck disable=SC2053
  [[ $name == $only ]] || continue
  mkdir -p "$out/sweeps"
  rm -rf "${out:?}/sweeps/$name"
  # Each run keeps its summary.json and report.html; the sweep's table, aggregate and figures are
  # the same as with every run's CSVs and trajectories (`flexbench sweep` alone keeps those).
  run_one "sweep_$name" "$out/sweeps/$name" "$bin" sweep "$sweep" \
    --out "$out/sweeps/$name" -j "$(nproc 2>/dev/null || echo 2)" --run-files summary
done

echo
[ ${#folders[@]} -eq 0 ] || "$bin" summary "${folders[@]}"
echo
if [ ${#failed[@]} -eq 0 ]; then
  echo "all scenarios passed their gates; results in $out/ (each run's output: its log.txt)"
else
  echo "failed: ${failed[*]}"
  exit 1
fi
