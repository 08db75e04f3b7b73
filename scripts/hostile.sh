#!/usr/bin/env bash
# Hostile-user attacks on a built flexbench: the reproducers of the reliability issues (data
# loss, crashes, hangs, unbounded memory, injection, confusing results), each run bounded and
# checked against the promises of docs/reliability.md.
#
# Usage: scripts/hostile.sh [BUILD_DIR]     (default: build; needs BUILD_DIR/bin/flexbench,
#                                            and BUILD_DIR/python for the Python attacks)
#
# Prints one fixed-width row per attack (attack, expected, observed, PASS/FAIL/SKIP), the
# details of every failure, and last the line "hostile: N passed, M failed"; exits 1 when an
# attack failed. Every attack runs in its own folder under one `mktemp -d` folder (removed at
# the end) with `timeout` and `ulimit -v`; nothing outside that folder is written. Attacks run
# two at a time (HOSTILE_JOBS; HOSTILE_TIMEOUT, HOSTILE_MEM_KB change the bounds;
# HOSTILE_ONLY=REGEX runs only the attacks whose name matches).
#
# Adding an attack: make its folder with `fresh NAME`, write its inputs into "$D", then
#   attack NAME EXPECTED_EXIT "CHECK ..." -- CMD ARGS...
# EXPECTED_EXIT: a code or codes joined by '|' (2, 0|2). CHECKS (space-separated, no spaces
# inside one; paths relative to "$D"; RE an extended regex, case-insensitive):
#   1line          one error line on stderr (besides "[flexbench] ..." log lines)
#   err~RE         stderr matches RE
#   noerr~RE       stderr does not match RE          log~RE     stdout or stderr matches RE
#   kept:PATH      PATH still exists                 gone:PATH  PATH does not exist
#   none:GLOB      no file matches GLOB              has:PATH:RE / hasnt:PATH:RE  file content
#   fast:S         finished in under S seconds
# CMD runs with "$D" as working folder and stdin from /dev/null (ATTACK_STDIN=FILE changes it);
# a multi-step attack is `bash -c '...'` (FB, SRC, D, PY are exported). `skip NAME REASON`
# prints a SKIP row (counted in neither total).
set -uo pipefail

SRC=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${1:-build}
[ -d "$BUILD" ] || BUILD="$SRC/$BUILD"
BUILD=$(cd "$BUILD" 2>/dev/null && pwd) || {
  echo "hostile: no build folder ${1:-build}" >&2
  exit 2
}
FB="$BUILD/bin/flexbench"
if [ ! -x "$FB" ]; then
  echo "hostile: $FB is not built (cmake --build $BUILD --target flexbench)" >&2
  exit 2
fi
TIMEOUT=${HOSTILE_TIMEOUT:-20}     # seconds per attack
MEM_KB=${HOSTILE_MEM_KB:-4194304}  # ulimit -v per attack (4 GiB)
PY_BIN=${HOSTILE_PYTHON:-/usr/bin/python3}
PY=""
if compgen -G "$BUILD/python/flexbench*.so" >/dev/null && [ -x "$PY_BIN" ]; then
  PY="$PY_BIN"
fi
W=$(mktemp -d "${TMPDIR:-/tmp}/flexbench-hostile-XXXXXX")
export FB SRC PY W
export PYTHONPATH="$BUILD/python"

cleanup() {
  # A worker that outlived its sweep (an attack's finding) holds the scratch folder in its
  # command line: end those processes (ours), by their ids, before removing the folder.
  local pids
  pids=$(pgrep -f -- "$W/" 2>/dev/null | grep -vx "$$" || true)
  [ -n "$pids" ] && kill -KILL $pids 2>/dev/null
  chmod -R u+rwx "$W" 2>/dev/null
  rm -rf "$W"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

T0=$(date +%s)
FMT="%-36s %-44s %-44s %s\n"

cut_to() {  # cut_to N TEXT: TEXT on one line, at most N characters
  local t=${2//$'\n'/ }
  [ ${#t} -gt "$1" ] && t="${t:0:$(($1 - 3))}..."
  printf '%s' "$t"
}

# fresh NAME: an empty folder for one attack; sets D.
fresh() {
  D="$W/$1"
  mkdir -p "$D"
  export D
}

describe_check() {
  case $1 in
    1line) printf 'one error line' ;;
    err~*) printf 'stderr~%s' "${1#err~}" ;;
    noerr~*) printf 'stderr!~%s' "${1#noerr~}" ;;
    log~*) printf 'output~%s' "${1#log~}" ;;
    kept:*) printf '%s kept' "${1#kept:}" ;;
    gone:*) printf 'no %s' "${1#gone:}" ;;
    none:*) printf 'no %s' "${1#none:}" ;;
    has:*) printf '%s' "${1#has:}" ;;
    hasnt:*) printf 'not %s' "${1#hasnt:}" ;;
    fast:*) printf '<%ss' "${1#fast:}" ;;
    *) printf '%s' "$1" ;;
  esac
}

# run_check CHECK: 0 when it holds; otherwise prints what was seen instead.
run_check() {
  local c=$1 p re n
  case $c in
    1line)
      n=$(grep -cvE '^\[(flexbench|sweep)\] ' "$D/.stderr")
      [ "$n" -eq 1 ] || { printf '%s error lines' "$n"; return 1; } ;;
    err~*)
      grep -qiE -- "${c#err~}" "$D/.stderr" || { printf 'stderr !~ %s' "${c#err~}"; return 1; } ;;
    noerr~*)
      ! grep -qiE -- "${c#noerr~}" "$D/.stderr" || { printf 'stderr ~ %s' "${c#noerr~}"; return 1; } ;;
    log~*)
      cat "$D/.stdout" "$D/.stderr" | grep -qiE -- "${c#log~}" ||
        { printf 'output !~ %s' "${c#log~}"; return 1; } ;;
    kept:*)
      [ -e "$D/${c#kept:}" ] || { printf '%s deleted' "${c#kept:}"; return 1; } ;;
    gone:*)
      [ ! -e "$D/${c#gone:}" ] || { printf '%s exists' "${c#gone:}"; return 1; } ;;
    none:*)
      p=$(cd "$D" && compgen -G "${c#none:}" | head -n 1)
      [ -z "$p" ] || { printf '%s left' "$p"; return 1; } ;;
    has:* | hasnt:*)
      p=${c#*:}
      re=${p#*:}
      p=${p%%:*}
      if [ "${c%%:*}" = has ]; then
        grep -qiE -- "$re" "$D/$p" 2>/dev/null || { printf '%s !~ %s' "$p" "$re"; return 1; }
      else
        ! grep -qiE -- "$re" "$D/$p" 2>/dev/null || { printf '%s ~ %s' "$p" "$re"; return 1; }
      fi ;;
    fast:*)
      [ "$ELAPSED" -lt "${c#fast:}" ] || { printf 'took %ss' "$ELAPSED"; return 1; } ;;
    *)
      printf 'unknown check %s' "$c"
      return 1 ;;
  esac
  return 0
}

row() {  # row NAME EXPECTED OBSERVED RESULT
  printf "$FMT" "$(cut_to 36 "$1")" "$(cut_to 44 "$2")" "$(cut_to 44 "$3")" "$4"
}

# Results go to $W/.results/<index> (RESULT, the row, the details of a failure), so that the
# table keeps the script's order when attacks run side by side (HOSTILE_JOBS).
JOBS=${HOSTILE_JOBS:-2}
INDEX=0
mkdir -p "$W/.results"

# run_attack RESULT_FILE NAME EXPECTED_EXIT CHECKS EXPECTED CMD...: runs and judges one attack.
run_attack() {
  local result=$1 name=$2 expected_exit=$3 checks=$4 expected=$5 rc start observed="" why="" c
  shift 5
  start=$(date +%s)
  (
    cd "$D" || exit 125
    ulimit -v "$MEM_KB"
    exec timeout -k 5 "$TIMEOUT" "$@"
  ) <"${ATTACK_STDIN:-/dev/null}" >"$D/.stdout" 2>"$D/.stderr"
  rc=$?
  ELAPSED=$(($(date +%s) - start))
  if [[ "|$expected_exit|" == *"|$rc|"* ]]; then
    observed="exit $rc (${ELAPSED}s)"
  elif { [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ]; } && [ "$ELAPSED" -ge "$TIMEOUT" ]; then
    observed="timeout after ${TIMEOUT}s"
    why=$observed
  elif [ "$rc" -gt 128 ]; then
    observed="killed by SIG$(kill -l $((rc - 128)) 2>/dev/null || echo "?") (${ELAPSED}s)"
    why=$observed
  else
    observed="exit $rc (${ELAPSED}s)"
    why="exit $rc"
  fi
  if [ -z "$why" ]; then
    for c in $checks; do
      if ! why=$(run_check "$c"); then break; fi
      why=""
    done
  fi
  [ -n "$why" ] && [ "$why" != "$observed" ] && [ "$why" != "exit $rc" ] && observed+="; $why"
  {
    if [ -z "$why" ]; then
      echo PASS
      row "$name" "$expected" "$observed" PASS
    else
      echo FAIL
      row "$name" "$expected" "$observed" FAIL
      echo "  $name: $why; stderr: $(cut_to 240 "$(grep -vE '^\[(flexbench|sweep)\] ' "$D/.stderr" |
        tail -n 2)")$([ -s "$D/.stdout" ] && echo "; stdout: $(cut_to 160 "$(tail -n 1 "$D/.stdout")")")"
    fi
  } >"$result"
}

# attack NAME EXPECTED_EXIT "CHECKS" -- CMD ARGS...
attack() {
  local name=$1 expected_exit=$2 checks=$3 c expected
  shift 3
  [ "${1:-}" = "--" ] && shift
  [[ -n "${HOSTILE_ONLY:-}" && ! "$name" =~ $HOSTILE_ONLY ]] && return 0
  expected="exit $expected_exit"
  for c in $checks; do expected+="; $(describe_check "$c")"; done
  INDEX=$((INDEX + 1))
  while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do wait -n; done
  run_attack "$W/.results/$(printf '%04d' "$INDEX")" "$name" "$expected_exit" "$checks" \
    "$expected" "$@" 2>/dev/null &  # (the shell's own "Segmentation fault" lines)
}

skip() {  # skip NAME REASON
  [[ -n "${HOSTILE_ONLY:-}" && ! "$1" =~ $HOSTILE_ONLY ]] && return 0
  INDEX=$((INDEX + 1))
  { echo SKIP; row "$1" "-" "$2" SKIP; } >"$W/.results/$(printf '%04d' "$INDEX")"
}

# --- inputs -------------------------------------------------------------------------------

# smoke_yaml FILE [EXTRA [MODEL]]: the smoke scenario with absolute paths, fast rendering.
smoke_yaml() {
  local model=${3:-$SRC/models/planar3.xml}
  mkdir -p "$(dirname "$1")"
  cat >"$1" <<EOF
scenario: smoke_copy
kind: smoke
seed: 3
model: $model
camera: overview
configuration: {joint1: 0.35, joint2: -0.6, joint3: 0.5}
render: {mode: fast}
${2:-}
EOF
}

# model_with FILE SED_EXPR: planar3.xml edited by sed.
model_with() {
  sed -e "$2" "$SRC/models/planar3.xml" >"$1"
}

# point_csv FILE ROWS: a point-format calibration CSV for planar3 (not a consistent arm: the
# attacks that use it stop before or do not care about the fit).
point_csv() {
  awk -v n="$2" 'BEGIN { print "joint1,joint2,joint3,x,y,z";
    for (i = 0; i < n; ++i) printf "%.3f,%.3f,%.3f,%.3f,%.3f,0.1\n",
      0.05 * (i % 30), -0.03 * (i % 29), 0.02 * (i % 31), 0.3 - 0.01 * (i % 30), 0.01 * (i % 29) }' >"$1"
}

DECLARED="$SRC/models/planar3.declared.yaml"
export DECLARED

# fake_slurm DIR: sbatch and squeue stand-ins that accept a job without running it, so a sweep
# only writes its job.sh (`--executor slurm --no-wait`).
fake_slurm() {
  mkdir -p "$1"
  printf '#!/bin/sh\necho 4242\n' >"$1/sbatch"
  printf '#!/bin/sh\nexit 1\n' >"$1/squeue"
  chmod +x "$1/sbatch" "$1/squeue"
}

sweep_yaml() {  # sweep_yaml FILE SCENARIO EXTRA
  cat >"$1" <<EOF
sweep: hostile
scenario: $2
${3:-seeds: [1]}
EOF
}

# === Round 3 ==========================================================================

# 1. Folders beside --out that look like temporaries are the user's unless marked as ours.
fresh i35_01_old_sibling_kept
smoke_yaml "$D/s.yaml"
mkdir -p "$D/o/results.old-2024" "$D/o/results.tmp-77777"
echo x >"$D/o/results.old-2024/thesis.tex"
echo y >"$D/o/results.tmp-77777/notes.txt"
attack i35_01_old_sibling_kept 0 "kept:o/results.old-2024/thesis.tex kept:o/results.tmp-77777/notes.txt" \
  -- "$FB" run s.yaml --out o/results --quiet

# 2. A summary.json that is not a flexbench result does not make the folder one.
fresh i35_02_fake_summary_refused
smoke_yaml "$D/s.yaml"
mkdir -p "$D/o/myproj"
echo 'not json' >"$D/o/myproj/summary.json"
echo keep >"$D/o/myproj/notes.txt"
attack i35_02_fake_summary_refused 2 "1line kept:o/myproj/notes.txt" \
  -- "$FB" run s.yaml --out o/myproj

# 3. --force never replaces a folder holding an input the run read (here its model).
fresh i35_03_force_keeps_inputs
mkdir -p "$D/W2/scenarios"
cp -r "$SRC/models" "$D/W2/models"
cp "$SRC/scenarios/smoke.yaml" "$D/W2/scenarios/smoke.yaml"
attack i35_03_force_keeps_inputs 2 "1line kept:W2/models/planar3.xml" \
  -- "$FB" run W2/scenarios/smoke.yaml --out W2/models --force

# 4. Sweep resume reruns runs whose definition changed (scenario bytes, set, point index).
fresh i35_04_resume_after_edit
smoke_yaml "$D/s.yaml"
sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1]"
attack i35_04_resume_after_edit 0 "log~rerun noerr~0.runs.to.do" -- bash -c '
  "$FB" sweep sw.yaml --out sw -j 1 >/dev/null 2>&1 || exit 90
  sed -i "s/joint1: 0.35/joint1: 0.30/" s.yaml
  "$FB" sweep sw.yaml --out sw -j 1'

fresh i35_04_resume_after_set_change
smoke_yaml "$D/s.yaml"
sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1]
set: {configuration.joint2: -0.6}"
attack i35_04_resume_after_set_change 0 "log~rerun noerr~0.runs.to.do" -- bash -c '
  "$FB" sweep sw.yaml --out sw -j 1 >/dev/null 2>&1 || exit 90
  sed -i "s/joint2: -0.6}/joint2: -0.5}/" sw.yaml
  "$FB" sweep sw.yaml --out sw -j 1'

fresh i35_04_resume_index_points
smoke_yaml "$D/s.yaml"
long_a=$(printf 'a%.0s' {1..130})
long_b=$(printf 'b%.0s' {1..130})
long_c=$(printf 'c%.0s' {1..130})
sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1]
grid: {description: [$long_a, $long_c]}"
attack i35_04_resume_index_points 0 "log~rerun" -- bash -c '
  "$FB" sweep sw.yaml --out sw -j 1 >/dev/null 2>&1 || exit 90
  sed -i "s/\[\(a*\), /[\1, '"$long_b"', /" sw.yaml
  "$FB" sweep sw.yaml --out sw -j 1'

# 5-8. The Python module.
py_attack() {  # py_attack NAME CHECKS SCRIPT: the script prints what it saw; exit 0 expected
  fresh "$1"
  if [ -z "$PY" ]; then
    skip "$1" "no Python module in $BUILD/python"
    return
  fi
  smoke_yaml "$D/s.yaml"
  printf 'import sys, os, math, threading\nimport flexbench\n%s\n' "$3" >"$D/attack.py"
  attack "$1" 0 "$2" -- "$PY" attack.py
}
py_attack i35_05_py_recursive_list "log~ValueError" '
l = []
l.append(l)
try:
    flexbench.run_scenario("s.yaml", "out", overrides={"foo": l})
except ValueError as e:
    print("ValueError", e)'
py_attack i35_05_py_recursive_dict "log~ValueError" '
d = {}
d["d"] = d
try:
    flexbench.run_scenario("s.yaml", "out", overrides={"foo": d})
except ValueError as e:
    print("ValueError", e)'

fresh i35_06_shadowsize_cli
model_with "$D/m.xml" 's/shadowsize="2048"/shadowsize="60000"/'
smoke_yaml "$D/s.yaml" "" "$D/m.xml"
attack i35_06_shadowsize_cli 2 "1line err~shadowsize none:o.tmp-* gone:MUJOCO_LOG.TXT" \
  -- "$FB" run s.yaml --out o
py_attack i35_06_shadowsize_python "log~ValueError none:out.tmp-*" '
import re
open("m.xml", "w").write(open(os.environ["SRC"] + "/models/planar3.xml").read()
                         .replace("shadowsize=\"2048\"", "shadowsize=\"60000\""))
open("s2.yaml", "w").write(re.sub(r"model: .*", "model: m.xml", open("s.yaml").read()))
try:
    flexbench.run_scenario("s2.yaml", "out")
except ValueError as e:
    print("ValueError", e)'

py_attack i35_07_py_threads "log~4.of.4.ok" '
ok = []
def go(i):
    try:
        flexbench.run_scenario("s.yaml", "out%d" % i)
        ok.append(i)
    except Exception as e:
        print("thread", i, type(e).__name__, e)
ts = [threading.Thread(target=go, args=(i,)) for i in range(4)]
[t.start() for t in ts]
[t.join() for t in ts]
print("%d of 4 ok" % len(ok))'

py_attack i35_08_py_invalid_noise "log~5.of.5.refused" '
import numpy as np
model = flexbench.DeclaredModel.load(os.environ["SRC"] + "/models/planar3.declared.yaml")
q = np.zeros(model.nq)
refused = 0
for t, std in [(0.0, -1.0), (0.0, 0.0), (0.0, float("nan")), (0.0, float("inf")),
               (float("nan"), 0.01)]:
    ekf = flexbench.make_estimator("ppoe_ekf", model)
    ekf.predict(0.0)
    try:
        r = ekf.update_joints(t, q, std=std)
        print("t", t, "std", std, "->", r)
    except ValueError:
        refused += 1
print("%d of 5 refused" % refused)'

# 9. Files MuJoCo opens get the top-level checks: a FIFO, /dev/stdin, /dev/zero.
fresh i35_09_include_fifo_run
mkfifo "$D/inc.xml"
model_with "$D/m.xml" 's|<mujoco\([^>]*\)>|<mujoco\1><include file="inc.xml"/>|'
smoke_yaml "$D/s.yaml" "" "$D/m.xml"
attack i35_09_include_fifo_run 2 "1line fast:10" -- "$FB" run s.yaml --out o
fresh i35_09_include_fifo_inspect
mkfifo "$D/inc.xml"
model_with "$D/m.xml" 's|<mujoco\([^>]*\)>|<mujoco\1><include file="inc.xml"/>|'
attack i35_09_include_fifo_inspect 2 "1line fast:10" -- "$FB" inspect m.xml
fresh i35_09_include_dev_stdin
ln -s /dev/stdin "$D/inc.xml"
mkfifo "$D/never_written"
model_with "$D/m.xml" 's|<mujoco\([^>]*\)>|<mujoco\1><include file="inc.xml"/>|'
# stdin a pipe that stays open and empty: reading it waits for ever.
attack i35_09_include_dev_stdin 2 "1line fast:10" -- bash -c 'exec 3<>never_written; exec "$FB" inspect m.xml <never_written'
fresh i35_09_obj_mesh_dev_zero
ln -s /dev/zero "$D/zero.obj"
model_with "$D/m.xml" 's|<asset>|<asset><mesh name="zero" file="zero.obj"/>|; s|<worldbody>|<worldbody><geom type="mesh" mesh="zero"/>|'
attack i35_09_obj_mesh_dev_zero 2 "1line fast:10" -- "$FB" inspect m.xml

# 10. Size caps bound memory: many YAML nodes, many CSV rows, a huge summary.json.
fresh i35_10_yaml_15MiB_list
{
  printf 'scenario: big\nkind: smoke\nlist: ['
  yes 0, | tr -d '\n' | head -c 15600000
  printf '0]\n'
} >"$D/big.yaml"
attack i35_10_yaml_15MiB_list 2 "1line err~big.yaml fast:10" -- "$FB" run big.yaml --out o
fresh i35_10_csv_1500k_rows
point_csv "$D/cal.csv" 1500000
point_csv "$D/val.csv" 30
attack i35_10_csv_1500k_rows 2 "1line err~cal.csv fast:10" -- "$FB" identify --declared "$DECLARED" \
  --calibration cal.csv --validation val.csv --out o
fresh i35_10_report_300MB_summary
mkdir -p "$D/r"
{
  printf '{"scenario": "big", "metrics": {"x": ['
  yes 0, | tr -d '\n' | head -c 300000000
  printf '0]}}\n'
} >"$D/r/summary.json"
attack i35_10_report_300MB_summary 2 "1line err~summary.json fast:10" -- "$FB" report r

# 11. Sweeps: run-count overflow, seed overflow, --tasks out of range.
fake_slurm "$W/fakeslurm"
fresh i35_11_grid_64_keys
smoke_yaml "$D/s.yaml"
{
  printf 'sweep: hostile\nscenario: s.yaml\nseeds: [1]\ngrid:\n'
  for k in $(seq 0 63); do printf '  k%d: [0, 1]\n' "$k"; done
} >"$D/sw.yaml"
attack i35_11_grid_64_keys 2 "1line err~sw.yaml fast:10" -- "$FB" sweep sw.yaml --out o
fresh i35_11_seed_range_int_max
smoke_yaml "$D/s.yaml"
sweep_yaml "$D/sw.yaml" s.yaml "seeds: {from: 2147483646, to: 2147483647}"
attack i35_11_seed_range_int_max "0|2" "fast:10" -- env PATH="$W/fakeslurm:$PATH" \
  "$FB" sweep sw.yaml --out o --executor slurm --no-wait
for tasks in 0 -3; do
  fresh "i35_11_tasks_$tasks"
  smoke_yaml "$D/s.yaml"
  sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1, 2]"
  attack "i35_11_tasks_$tasks" 2 "1line err~--tasks" -- env PATH="$W/fakeslurm:$PATH" \
    "$FB" sweep sw.yaml --out o --executor slurm --no-wait --tasks "$tasks"
done

# 12. Nothing from the command line reaches the job script unquoted.
for opt in partition time mem; do
  fresh "i35_12_slurm_$opt"
  smoke_yaml "$D/s.yaml"
  sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1]"
  attack "i35_12_slurm_$opt" 2 "1line err~--$opt none:PWNED hasnt:o/slurm/job.sh:^touch" \
    -- env PATH="$W/fakeslurm:$PATH" "$FB" sweep sw.yaml --out o --executor slurm --no-wait \
    "--$opt" "$(printf '1\ntouch PWNED')"
done
fresh i35_12_slurm_out_space_percent
smoke_yaml "$D/s.yaml"
sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1]"
attack i35_12_slurm_out_space_percent 0 "kept:a_b%j/slurm/job.sh log~job.sh.ok" -- bash -c '
  PATH="$W/fakeslurm:$PATH" "$FB" sweep sw.yaml --out "a b%j" --executor slurm --no-wait || exit
  mv "a b%j" "a_b%j"   # (the check names paths without spaces)
  bash -n "a_b%j/slurm/job.sh" || exit 91
  # Every % in #SBATCH lines is escaped (%%) or one of ours (%a, %A).
  if grep "^#SBATCH" "a_b%j/slurm/job.sh" | sed "s/%%//g; s/%[aA]//g" | grep -q "%"; then
    echo "unescaped % in job.sh"; exit 92; fi
  echo "job.sh ok"'
if timeout 5 sinfo -h >/dev/null 2>&1; then
  fresh i35_12_slurm_real_partition
  smoke_yaml "$D/s.yaml"
  sweep_yaml "$D/sw.yaml" s.yaml "seeds: [1]"
  attack i35_12_slurm_real_partition 2 "1line none:PWNED" -- "$FB" sweep sw.yaml --out o \
    --executor slurm --partition "$(printf 'debug\ntouch PWNED')"
else
  skip i35_12_slurm_real_partition "no Slurm answers sinfo; job.sh rows above"
fi

# 13. --set: a null value, errors naming the --set, non-UTF-8 values.
fresh i35_13_set_null_value
smoke_yaml "$D/s.yaml"
attack i35_13_set_null_value 2 "1line err~--set.model gone:o" -- "$FB" run s.yaml --out o --set model=
fresh i35_13_set_error_names_set
smoke_yaml "$D/s.yaml"
attack i35_13_set_error_names_set 2 "1line err~--set.configuration noerr~s.yaml:[0-9]" \
  -- "$FB" run s.yaml --out o --set 'configuration=[1, 2]'
fresh i35_13_set_not_utf8
smoke_yaml "$D/s.yaml"
attack i35_13_set_not_utf8 2 "1line err~--set.description gone:o" \
  -- "$FB" run s.yaml --out o --set "$(printf 'description=caf\xe9')"

fresh i35_13_set_null_optional_key
smoke_yaml "$D/s.yaml" "detector: {family: tag36h11, decimate: 2.0}"
attack i35_13_set_null_optional_key 2 "1line err~--set.detector gone:o" -- "$FB" run s.yaml --out o --set detector=

# 14. identify's --set cannot swap the model or reuse the calibration rows; Python keys.
fresh i35_14_identify_set_model
point_csv "$D/cal.csv" 30
point_csv "$D/val.csv" 31
attack i35_14_identify_set_model 2 "1line err~model gone:o" -- "$FB" identify --declared "$DECLARED" \
  --calibration cal.csv --validation val.csv --out o --set "model=$SRC/models/rover_arm.xml"
fresh i35_14_identify_set_validation
point_csv "$D/cal.csv" 30
point_csv "$D/val.csv" 31
attack i35_14_identify_set_validation 2 "1line err~--set.validation.csv gone:o" -- "$FB" identify \
  --declared "$DECLARED" --calibration cal.csv --validation val.csv --out o \
  --set validation.csv=cal.csv
py_attack i35_14_py_override_key_yaml "log~3.of.3.refused" '
refused = 0
for o in [{"configuration.joint1: 9, x": 1},
          {"configuration": {"joint1: 0.2, joint2": -0.6, "joint3": 0.5}},
          {"configuration": {"joint1,joint2": -0.6, "joint3": 0.5}}]:
    try:
        flexbench.run_scenario("s.yaml", "out", overrides=o, force=True)
        print("accepted", o)
    except ValueError:
        refused += 1
print("%d of 3 refused" % refused)'
# What fuzz_python_overrides found: a lone surrogate, overrides that are not a mapping or list, a
# value repeating one object 2^40 times, an int too long for Python to print.
py_attack fuzz_py_overrides_found "log~4.of.4.refused" '
import functools
refused = 0
for o in [{"render.mode": ["\udcff"]}, 5, {"configuration": functools.reduce(lambda a, _: [a, a], range(40), 0)},
          {"seed": 10**5000}]:
    try:
        flexbench.run_scenario("s.yaml", "out", overrides=o, force=True)
        print("accepted", type(o))
    except ValueError:
        refused += 1
print("%d of 4 refused" % refused)'

# 15. Absurd finite values are bad input, not null metrics with exit 0.
fresh i35_15_set_joint_1e300
smoke_yaml "$D/s.yaml"
attack i35_15_set_joint_1e300 2 "1line gone:o" -- "$FB" run s.yaml --out o --set configuration.joint1=1e300
fresh i35_15_scenario_joint_1e200
smoke_yaml "$D/s.yaml"
sed -i 's/joint1: 0.35/joint1: 1e200/' "$D/s.yaml"
attack i35_15_scenario_joint_1e200 2 "1line gone:o" -- "$FB" run s.yaml --out o
fresh i35_15_mjcf_pos_1e308
model_with "$D/m.xml" 's/<body name="base" pos="0 0 0.05">/<body name="base" pos="-1e308 0 0.05">/'
smoke_yaml "$D/s.yaml" "" "$D/m.xml"
attack i35_15_mjcf_pos_1e308 2 "1line gone:o" -- "$FB" run s.yaml --out o

# 16. report on valid JSON of the wrong shape.
for shape in array types deep; do
  fresh "i35_16_report_$shape"
  mkdir -p "$D/r"
  case $shape in
    array) echo '[]' >"$D/r/summary.json" ;;
    types) echo '{"scenario": 5, "kind": [], "seed": {}, "gates": 3, "metrics": "x"}' >"$D/r/summary.json" ;;
    deep) { head -c 100000 /dev/zero | tr '\0' '['; head -c 100000 /dev/zero | tr '\0' ']'; } >"$D/r/summary.json" ;;
  esac
  attack "i35_16_report_$shape" 2 "1line err~summary.json" -- "$FB" report r
done

# 17. A calibration error far above the stated noise is never quiet: warning, `unexplained`.
if [ -n "$PY" ]; then
  fresh i35_17_outliers_unexplained
  (cd "$D" && "$PY" - <<'EOF'
import os, numpy as np, flexbench
m = flexbench.DeclaredModel.load(os.environ["SRC"] + "/models/planar3.declared.yaml")
rng = np.random.default_rng(1)
def rows(n, outlier=False):
    out = ["joint1,joint2,joint3,x,y,z"]
    for i in range(n):
        q = rng.uniform(-0.8, 0.8, m.nq)
        p = m.fk(q, None)[:3, 3] + rng.normal(0, 1e-4, 3)
        out.append(",".join("%.6f" % v for v in list(q) + list(p)))
    return out
cal = rows(60)
cal += ["0.100000,0.200000,0.300000,500.000000,0.000000,0.100000"] * 25
open("cal.csv", "w").write("\n".join(cal) + "\n")
open("val.csv", "w").write("\n".join(rows(30)) + "\n")
EOF
  )
  attack i35_17_outliers_unexplained "0|3" "err~warning has:o/summary.json:unexplained" \
    -- "$FB" identify --declared "$DECLARED" --calibration cal.csv --validation val.csv \
    --out o --candidates joint_offset
else
  skip i35_17_outliers_unexplained "no Python module to make consistent rows"
fi

# 18. Small ones.
fresh i35_18_out_250_chars
smoke_yaml "$D/s.yaml"
long_out=$(printf 'o%.0s' {1..250})
attack i35_18_out_250_chars 0 "kept:$long_out/summary.json" -- "$FB" run s.yaml --out "$long_out" --quiet
fresh i35_18_out_empty
smoke_yaml "$D/s.yaml"
attack i35_18_out_empty 2 "1line err~--out gone:out" -- "$FB" run s.yaml --out ''
for seed in -1 18446744073709551616; do
  fresh "i35_18_seed_$seed"
  smoke_yaml "$D/s.yaml"
  attack "i35_18_seed_$seed" 2 "1line err~--seed gone:o" -- "$FB" run s.yaml --out o --seed "$seed"
done
for sig in TERM INT; do
  fresh "i35_18_sig${sig}_cleans_tmp"
  cp "$SRC/scenarios/rover_apriltag_exp1.yaml" "$D/slow.yaml"
  sed -i "s|\.\./models/|$SRC/models/|g" "$D/slow.yaml"
  # set -m: a background job of a script ignores SIGINT otherwise. Exit 0 means the signal
  # came after the run had ended (the attack did not land).
  attack "i35_18_sig${sig}_cleans_tmp" "1|2|130|143" "none:o.tmp-* none:o.old-*" -- bash -c '
    set -m
    "$FB" run slow.yaml --out "$D/o" --quiet &
    pid=$!
    for k in $(seq 100); do compgen -G "o.tmp-*" >/dev/null && break; sleep 0.05; done
    sleep 0.3
    kill -'"$sig"' $pid
    wait $pid'
done
fresh i35_18_sigterm_sweep_workers
cp "$SRC/scenarios/rover_apriltag_exp1.yaml" "$D/slow.yaml"
sed -i "s|\.\./models/|$SRC/models/|g" "$D/slow.yaml"
sweep_yaml "$D/sw.yaml" slow.yaml "seeds: [1, 2, 3, 4]"
# A worker outlived its sweep when it still runs, or made or renamed a folder in runs/, after
# the sweep's death (a run may take less than a second).
attack i35_18_sigterm_sweep_workers 0 "log~no.worker.left" -- bash -c '
  "$FB" sweep sw.yaml --out "$D/sw" -j 2 >/dev/null 2>&1 &
  pid=$!
  # Its workers are forks with the same command line: wait until one runs.
  for k in $(seq 150); do [ "$(pgrep -cf -- "--out $D/sw -j")" -ge 2 ] && break; sleep 0.1; done
  [ "$(pgrep -cf -- "--out $D/sw -j")" -ge 2 ] || { echo "no worker seen"; exit 93; }
  kill -TERM $pid
  wait $pid
  touch killed
  sleep 2
  left=$(pgrep -f -- "--out $D/sw -j" | tr "\n" " ")
  late=$(find sw/runs -mindepth 2 -maxdepth 2 -cnewer killed | head -n 1)
  [ -z "$left$late" ] && echo "no worker left" || echo "workers left: $left; wrote after: $late"'
fresh i35_18_one_row_message
point_csv "$D/one.csv" 1
point_csv "$D/val.csv" 30
attack i35_18_one_row_message 2 "1line noerr~rows.with.rows" -- "$FB" identify --declared "$DECLARED" \
  --calibration one.csv --validation val.csv --out o --folds-by row
fresh i35_18_unknown_subcommand
attack i35_18_unknown_subcommand 2 "1line err~frobnicate noerr~subcommand.is.required" -- "$FB" frobnicate

# === Round 1 ==========================================================================

fresh i21_out_with_user_files
smoke_yaml "$D/s.yaml"
mkdir -p "$D/mine" && echo "years of work" >"$D/mine/thesis.tex"
attack i21_out_with_user_files 2 "1line err~not.a.flexbench.result kept:mine/thesis.tex" \
  -- "$FB" run s.yaml --out mine
fresh i21_out_is_scenario_folder_force
smoke_yaml "$D/here/s.yaml"
attack i21_out_is_scenario_folder_force 2 "1line kept:here/s.yaml" -- "$FB" run here/s.yaml --out here --force
fresh i21_out_is_regular_file
smoke_yaml "$D/s.yaml"
echo "keep me" >"$D/notes.txt"
attack i21_out_is_regular_file 2 "1line err~not.a.folder has:notes.txt:keep.me" \
  -- "$FB" run s.yaml --out notes.txt --force
fresh i21_non_utf8_description
smoke_yaml "$D/s.yaml" "$(printf 'description: caf\xe9')"
attack i21_non_utf8_description 2 "1line err~UTF-8 gone:out" -- "$FB" run s.yaml --out out
fresh i21_killed_run_tmp_cleaned
cp "$SRC/scenarios/rover_apriltag_exp1.yaml" "$D/slow.yaml"
sed -i "s|\.\./models/|$SRC/models/|g" "$D/slow.yaml"
smoke_yaml "$D/s.yaml"
attack i21_killed_run_tmp_cleaned 0 "none:o.tmp-* kept:o/summary.json" -- bash -c '
  "$FB" run slow.yaml --out o --quiet &
  pid=$!
  for k in $(seq 100); do compgen -G "o.tmp-*" >/dev/null && break; sleep 0.05; done
  kill -KILL $pid
  wait $pid
  "$FB" run s.yaml --out o --quiet'
long=$(printf 'a%.0s' {1..300})
fresh i21_long_name_run
attack i21_long_name_run 2 "1line" -- "$FB" run "$long"
fresh i21_long_name_list
attack i21_long_name_list 2 "1line" -- "$FB" list --dir "$long"
fresh i21_long_name_inspect
attack i21_long_name_inspect 2 "1line noerr~.{400}" -- "$FB" inspect "$long.yaml"
fresh i21_long_name_identify
attack i21_long_name_identify 2 "1line" -- "$FB" identify --model "$long" --declared "$DECLARED" \
  --calibration "$long" --validation c
for size in 'offwidth="60000" offheight="60000"' 'offwidth="640" offheight="-5"'; do
  n=$([[ $size == *-5* ]] && echo neg || echo huge)
  fresh "i21_offscreen_$n"
  model_with "$D/m.xml" "s/offwidth=\"640\" offheight=\"480\"/$size/"
  smoke_yaml "$D/s.yaml" "" "$D/m.xml"
  attack "i21_offscreen_$n" 2 "1line err~offwidth noerr~Press.Enter gone:MUJOCO_LOG.TXT gone:o" \
    -- "$FB" run s.yaml --out o
done
fresh i21_run_dev_zero
attack i21_run_dev_zero 2 "1line fast:5" -- "$FB" run /dev/zero
fresh i21_yaml_complex_key
printf 'scenario: k\nkind: smoke\n? [a, b]\n: 1\n' >"$D/s.yaml"
attack i21_yaml_complex_key 2 "1line" -- "$FB" run s.yaml --out o
fresh i21_yaml_duplicate_key
smoke_yaml "$D/s.yaml" "seed: 4"
attack i21_yaml_duplicate_key 2 "1line err~seed" -- "$FB" run s.yaml --out o
fresh i21_yaml_second_document
smoke_yaml "$D/s.yaml" "---
scenario: other"
attack i21_yaml_second_document 2 "1line" -- "$FB" run s.yaml --out o
fresh i21_identify_model_is_folder
point_csv "$D/cal.csv" 30
point_csv "$D/val.csv" 31
attack i21_identify_model_is_folder 2 "1line err~--model" -- "$FB" identify --model /tmp \
  --declared "$DECLARED" --calibration cal.csv --validation val.csv --out o
fresh i21_point_std_1e-300
point_csv "$D/cal.csv" 30
point_csv "$D/val.csv" 31
attack i21_point_std_1e-300 2 "1line err~--point-std" -- "$FB" identify --declared "$DECLARED" \
  --calibration cal.csv --validation val.csv --out o --point-std 1e-300
fresh i21_same_rows_cal_val
point_csv "$D/cal.csv" 30
attack i21_same_rows_cal_val 2 "1line err~same.rows" -- "$FB" identify --declared "$DECLARED" \
  --calibration cal.csv --validation cal.csv --out o
fresh i21_check_gates_without_gates
smoke_yaml "$D/s.yaml"
attack i21_check_gates_without_gates 2 "1line err~no.gates gone:o" -- "$FB" run s.yaml --out o --check-gates
fresh i21_gate_metric_typo
smoke_yaml "$D/s.yaml" "gates:
  - {name: typo, metric: corner_rmse_pix, op: '<', threshold: 1.0}"
attack i21_gate_metric_typo 2 "1line err~corner_rmse_pix gone:o" -- "$FB" run s.yaml --out o --check-gates
fresh i21_csv_bom_accepted
point_csv "$D/plain.csv" 30
{ printf '\xef\xbb\xbf'; cat "$D/plain.csv"; } >"$D/cal.csv"
point_csv "$D/val.csv" 31
attack i21_csv_bom_accepted 0 "kept:o/summary.json" -- "$FB" identify --declared "$DECLARED" \
  --calibration cal.csv --validation val.csv --out o --candidates joint_offset --quiet
fresh i21_group_spanning_sets_warned
for f in cal val; do
  awk -v k="$([ $f = cal ] && echo 0.05 || echo 0.04)" 'BEGIN { print "joint1,joint2,joint3,group,set";
    for (i = 0; i < 24; ++i) printf "%.3f,%.3f,%.3f,g%d,s%d\n", k * i, -0.02 * i, 0.03 * i, i % 3, i % 2 }' >"$D/$f.csv"
done
attack i21_group_spanning_sets_warned "0|2|3" "err~warning.*group.'g0'.spans.sets" -- "$FB" identify \
  --declared "$DECLARED" --calibration cal.csv --validation val.csv --out o --candidates joint_offset
skip i21_10k_point_rows_under_5s "a benchmark, not an attack: BM_IdentifyPointCsv"
fresh i21_identify_option_named
point_csv "$D/cal.csv" 30
point_csv "$D/val.csv" 31
attack i21_identify_option_named 2 "1line err~--candidates noerr~flexbench_identify" -- "$FB" identify \
  --declared "$DECLARED" --calibration cal.csv --validation val.csv --out o --candidates bogus_effect
fresh i21_yaml_over_size_cap
truncate -s $(((16 << 20) + 1)) "$D/big.yaml"
attack i21_yaml_over_size_cap 2 "1line err~more.than fast:5" -- "$FB" run big.yaml --out o
fresh i21_model_over_size_cap
truncate -s $(((64 << 20) + 1)) "$D/big.xml"
smoke_yaml "$D/s.yaml" "" "$D/big.xml"
attack i21_model_over_size_cap 2 "1line err~more.than fast:5" -- "$FB" run s.yaml --out o
fresh i21_csv_over_size_cap
truncate -s $(((512 << 20) + 1)) "$D/big.csv"
point_csv "$D/val.csv" 31
attack i21_csv_over_size_cap 2 "1line err~more.than fast:5" -- "$FB" identify --declared "$DECLARED" \
  --calibration big.csv --validation val.csv --out o
fresh i21_detector_decimate_1e300
smoke_yaml "$D/s.yaml" "detector: {family: tag36h11, decimate: 1.1e300}"
attack i21_detector_decimate_1e300 2 "1line err~detector. gone:o" -- "$FB" run s.yaml --out o
fresh i21_scenario_name_escape
smoke_yaml "$D/s.yaml"
sed -i 's|scenario: smoke_copy|scenario: ../../escape|' "$D/s.yaml"
attack i21_scenario_name_escape 2 "1line err~plain.name" -- "$FB" run s.yaml

# === Found by the fuzz targets (tests/fuzz/regressions/) ===================================

# A number JSON cannot hold (nlohmann's out_of_range 406, not a parse_error).
# Recorded logs (flexbench replay): a stream that is a device or a pipe, a log whose --out is
# the log folder itself, an IMU header of another format.
replay_log() {  # replay_log DIR: the example log with an absolute declared path
  mkdir -p "$1"
  cp "$SRC"/scenarios/logs/jsk_flexible_arm/{joints.csv,imu.csv,truth.tum} "$1"/
  sed "s|^declared: .*|declared: $SRC/models/jsk_arm.declared.yaml|" \
    "$SRC/scenarios/logs/jsk_flexible_arm/log.yaml" >"$1/log.yaml"
}
fresh replay_imu_is_dev_zero
replay_log "$D/log"
ln -sf /dev/zero "$D/log/imu.csv"
attack replay_imu_is_dev_zero 2 "1line err~imu.csv fast:10" -- "$FB" replay log --out o
fresh replay_joints_is_a_fifo
replay_log "$D/log"
rm "$D/log/joints.csv"
mkfifo "$D/log/joints.csv"
attack replay_joints_is_a_fifo 2 "1line err~joints.csv fast:10" -- "$FB" replay log --out o
fresh replay_out_onto_the_log
replay_log "$D/log"
attack replay_out_onto_the_log 2 "1line kept:log/joints.csv kept:log/log.yaml" -- \
  "$FB" replay log --out log --force
fresh replay_imu_header_of_another_format
replay_log "$D/log"
sed -i '1s/.*/timestamp,wx,wy,wz,ax,ay,az/' "$D/log/imu.csv"
attack replay_imu_header_of_another_format 2 "1line err~imu.csv:1" -- "$FB" replay log --out o
# Tag streams: a camera tags.csv names that log.yaml lacks; a frame in images/ not named by its
# time; a PNG that is not one (the detector's reader must refuse it, not crash).
replay_tags() {  # replay_tags DIR: the example log with a camera and a tag declared
  replay_log "$1"
  printf 'cameras: {cam0: {frame: external_camera, fx: 579, fy: 579, cx: 320, cy: 240, width: 640, height: 480}}\n' >>"$1/log.yaml"
}
fresh replay_tags_unknown_camera
replay_tags "$D/log"
printf 'tags: {file: tags.csv, ids: {20: {frame: tag_gripper, size_m: 0.04}}}\n' >>"$D/log/log.yaml"
printf 't_s,camera,tag_id,u0_px,v0_px,u1_px,v1_px,u2_px,v2_px,u3_px,v3_px\n1,cam9,20,1,2,3,4,5,6,7,8\n' >"$D/log/tags.csv"
attack replay_tags_unknown_camera 2 "1line err~tags.csv:2:.column.'camera'" -- "$FB" replay log --out o
fresh replay_image_not_named_by_time
replay_tags "$D/log"
printf 'tags: {ids: {20: {frame: tag_gripper, size_m: 0.04}}}\nimages: {dir: images}\n' >>"$D/log/log.yaml"
mkdir -p "$D/log/images/cam0" && echo x >"$D/log/images/cam0/frame1.png"
attack replay_image_not_named_by_time 2 "1line err~frame1.png:.expected.<t_ns>.png" -- "$FB" replay log --out o
fresh replay_image_not_a_png
replay_tags "$D/log"
printf 'tags: {ids: {20: {frame: tag_gripper, size_m: 0.04}}}\nimages: {dir: images}\n' >>"$D/log/log.yaml"
mkdir -p "$D/log/images/cam0" && head -c 5000 /dev/urandom >"$D/log/images/cam0/100000000.png"
attack replay_image_not_a_png 2 "1line err~100000000.png:.not.an.8-bit" -- "$FB" replay log --out o
fresh replay_joints_of_100M_short_rows
replay_log "$D/log"
{ echo t_s,link1_yaw_joint_rad; yes 0,0 | head -n 100000000; } >"$D/log/joints.csv"
attack replay_joints_of_100M_short_rows 2 "1line err~joints.csv.*would.need fast:30" -- \
  "$FB" replay log --out o
fresh fuzz_report_number_overflow
mkdir -p "$D/r"
echo '{"scenario": "s", "metrics": {"x": 1e999}}' >"$D/r/summary.json"
attack fuzz_report_number_overflow 2 "1line err~summary.json" -- "$FB" report r
# Nesting deep inside a value: report's recursive JSON copy overflows the stack (SIGSEGV).
fresh fuzz_report_deep_metric
mkdir -p "$D/r"
{
  printf '{"scenario": "s", "metrics": {"a": '
  head -c 1000000 /dev/zero | tr '\0' '['
  head -c 1000000 /dev/zero | tr '\0' ']'
  printf '}}\n'
} >"$D/r/summary.json"
attack fuzz_report_deep_metric 2 "1line err~summary.json" -- "$FB" report r
# summary on folders that are not results, or whose summary.json is not JSON.
fresh summary_not_a_result
mkdir -p "$D/r"
attack summary_not_a_result 2 "1line err~not.a.flexbench.result" -- "$FB" summary r
fresh summary_bad_json
mkdir -p "$D/r"
echo '{"scenario": ' >"$D/r/summary.json"
attack summary_bad_json 2 "1line err~summary.json" -- "$FB" summary r
# Valid JSON of the wrong types is still listed (a dash), never an internal error.
for shape in name_number passed_string sweep_list; do
  fresh "summary_types_$shape"
  mkdir -p "$D/r"
  case $shape in
    name_number) echo '{"scenario": 5, "timing": 3}' >"$D/r/summary.json" ;;
    passed_string) echo '{"scenario": "s", "gates": [{"passed": "yes", "value": "x"}]}' >"$D/r/summary.json" ;;
    sweep_list) echo '{"sweep": [1], "gates": 7}' >"$D/r/aggregate.json" ;;
  esac
  attack "summary_types_$shape" 0 "" -- "$FB" summary r
done
# An AprilTag family error names neither the file nor the --set.
fresh fuzz_set_detector_family_named
smoke_yaml "$D/s.yaml"
attack fuzz_set_detector_family_named 2 "1line err~--set.detector.family" -- "$FB" run s.yaml --out o \
  --set detector.family=bogus
fresh fuzz_scenario_detector_family_named
smoke_yaml "$D/s.yaml" "detector: {family: bogus}"
attack fuzz_scenario_detector_family_named 2 "1line err~s.yaml:[0-9]+" -- "$FB" run s.yaml --out o

# === flexbench convert (a URDF as MJCF with servos) ========================================

# A URDF whose XML ends mid-element, one whose joint names a link that does not exist, a file
# that is a folder, and a URDF a path that is not one: one line naming it, and no output written.
fresh convert_urdf_cut
printf '<?xml version="1.0"?>\n<robot name="r">\n  <link name="a"/>\n  <joint name="j" type="rev' \
  >"$D/r.urdf"
attack convert_urdf_cut 2 "1line err~r.urdf none:*.xml" -- "$FB" convert r.urdf --actuators position
fresh convert_urdf_unknown_link
printf '<robot name="r"><link name="a"/><joint name="j" type="revolute"><parent link="a"/><child link="ghost"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>\n' \
  >"$D/r.urdf"
attack convert_urdf_unknown_link 2 "1line err~r.urdf none:*.xml" -- "$FB" convert r.urdf --actuators position
fresh convert_urdf_is_folder
mkdir -p "$D/d.urdf"
attack convert_urdf_is_folder 2 "1line err~d.urdf" -- "$FB" convert d.urdf --actuators position -o o.xml
fresh convert_kp_nan
printf '<robot name="r"><link name="a"/></robot>\n' >"$D/r.urdf"
attack convert_kp_nan 2 "1line err~--kp none:*.xml" -- "$FB" convert r.urdf --actuators position --kp nan
fresh convert_output_is_input
printf '<robot name="r"><link name="a"/></robot>\n' >"$D/r.urdf"
attack convert_output_is_input 2 "1line err~input has:r.urdf:robot" -- "$FB" convert r.urdf \
  --actuators position -o ./r.urdf --force

# === Summary =================================================================================
wait
PASSED=0
FAILED=0
SKIPPED=0
DETAILS=""
printf "$FMT" "ATTACK" "EXPECTED" "OBSERVED" "RESULT"
printf "$FMT" "------" "--------" "--------" "------"
for f in "$W"/.results/*; do
  sed -n 2p "$f"
  case $(head -n 1 "$f") in
    PASS) PASSED=$((PASSED + 1)) ;;
    FAIL) FAILED=$((FAILED + 1)); DETAILS+="$(sed -n 3p "$f")"$'\n' ;;
    *) SKIPPED=$((SKIPPED + 1)) ;;
  esac
done
if [ -n "$DETAILS" ]; then
  printf '\nfailures:\n%s' "$DETAILS"
fi
printf '(%d skipped; %d s in all)\n' "$SKIPPED" "$(($(date +%s) - T0))"
echo "hostile: $PASSED passed, $FAILED failed"
[ "$FAILED" -eq 0 ]
