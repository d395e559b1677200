#!/usr/bin/env bash
# Recount of the hostile survey: one case for each bad input the reliability issue names, run
# against the built program in temporary folders. For each case: the command, its exit code, the
# first line of its message, and a verdict:
#   clear   exit 1/2/3 with a message naming the cause and the file or option (the words the
#           case lists must all appear), or exit 0 where the right answer is to go on without the
#           bad part and say so (named words again), previous results and recorded data intact
#   unclear exit 1/2/3 but the message lacks the cause or the file/option
#   garbage exit 0 with a wrong result (the case's words are missing)
#   crash   killed by a signal it was not sent, or exit 4 / "internal error"
#   hang    no end within 120 s
#   lost    previous results or recorded data changed or deleted
# Not part of the test suite (each of these inputs also has its own test); run by hand:
#   bash tests/survey/recount.sh [ROBOCAL]   (default: build/release/app/robocal)
# Writes build/survey/counts.tsv and counts.md; the work folder is removed at the end.
set -uo pipefail

SRC=$(cd "$(dirname "$0")/../.." && pwd)
R=${1:-$SRC/build/release/app/robocal}
R=$(readlink -f "$R")
T=$SRC/testdata
HERE=$SRC/build/survey
mkdir -p "$HERE"
W=$(mktemp -d /tmp/recount.XXXXXX)
chmod 755 "$W"
TSV=$HERE/counts.tsv
: >"$TSV"
SIM_CELL_PID=""
cleanup() {
  [ -n "$SIM_CELL_PID" ] && kill "$SIM_CELL_PID" 2>/dev/null && wait "$SIM_CELL_PID" 2>/dev/null
  rm -rf "$W"
}
trap cleanup EXIT

log() { echo "recount: $*" >&2; }

# A fingerprint of every file under the given folders (path + sha256): what "intact" means.
fingerprint() {
  local d
  for d in "$@"; do
    [ -e "$d" ] || { echo "MISSING $d"; continue; }
    (cd "$d" && find . -type f -print0 | sort -z | xargs -0 -r sha256sum)
  done
}

# record NAME COMMAND EXIT VERDICT FIRST_LINE NOTE
record() {
  local first=${5//$'\t'/ }
  printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$1" "$2" "$3" "$4" "${first:0:220}" "$6" >>"$TSV"
  log "$1: exit $3 -> $4"
}

# run_case NAME EXPECT WORDS INTACT -- ARGS...
#   EXPECT: the exit codes that are right for this case, e.g. "3" or "1|3" or "0" (0: going on
#           without the bad part is right, and the words say what was left out)
#   WORDS:  '|'-separated strings that must all appear in the output (cause and file/option)
#   INTACT: folders whose files must not change ('' for none)
# The command runs in a folder of its own with a timeout of 120 s.
CASE_OUT=""
run_case() {
  local name=$1 expect=$2 words=$3 intact=$4
  shift 5
  local dir=$W/run_$name
  mkdir -p "$dir"
  local before=""
  # shellcheck disable=SC2086
  [ -n "$intact" ] && before=$(fingerprint $intact)
  local cmd="robocal $*"
  cmd=${cmd//$W/\$W}
  (cd "$dir" && timeout -s KILL 120 "$R" "$@" >"$dir/out" 2>&1)
  local code=$?
  CASE_OUT=$dir/out
  classify "$name" "$cmd" "$code" "$expect" "$words" "$intact" "$before" "$dir/out"
}

# classify NAME CMD CODE EXPECT WORDS INTACT BEFORE OUTFILE [SENT_SIGNAL_EXIT]
classify() {
  local name=$1 cmd=$2 code=$3 expect=$4 words=$5 intact=$6 before=$7 out=$8 sent=${9:-}
  local first
  # The message's first line: an "error:" line, else a refusal or verdict line, else the first
  # line that is not a progress line.
  first=$(grep -m1 -E '^(error|Error|[a-z -]+: error)|^[a-z-]+: (interrupted|the safety guard)' "$out" ||
    grep -m1 -E 'NOT PLAUSIBLE|NOT accepted|REJECTED|not used|refus|excludes|unknown|not in|failed|ambiguous|cannot|does not|same session' "$out" ||
    grep -v -E '^\s*$|[0-9]+/[0-9]+ \(|done in' "$out" | head -1)
  first=${first//$W/\$W}
  local missing=()
  local IFS='|'
  local w
  for w in $words; do
    grep -qF -- "$w" "$out" || missing+=("$w")
  done
  unset IFS
  local after=""
  # shellcheck disable=SC2086
  [ -n "$intact" ] && after=$(fingerprint $intact)
  local verdict note=""
  if [ "$code" -eq 137 ] && [ "$sent" != 137 ]; then
    verdict=hang
    note="killed after 120 s"
  elif [ "$code" -ge 128 ] && [ "$code" != "$sent" ]; then
    verdict=crash
    note="signal $((code - 128))"
  elif [ "$code" -eq 4 ] || grep -qi 'internal error' "$out"; then
    verdict=crash
    note="internal error"
  elif [ -n "$intact" ] && [ "$before" != "$after" ]; then
    verdict=lost
    note="files changed: $(diff <(echo "$before") <(echo "$after") | grep -c '^[<>]') lines of the fingerprint differ"
  elif [[ "|$expect|" == *"|$code|"* ]] && [ ${#missing[@]} -eq 0 ]; then
    verdict=clear
  elif [ "$code" -eq 0 ]; then
    verdict=garbage
    note="exit 0; missing: ${missing[*]:-}"
  else
    verdict=unclear
    note="expected exit $expect; missing: ${missing[*]:-}"
  fi
  [ -n "$intact" ] && [ "$verdict" = clear ] && note="files intact"
  record "$name" "$cmd" "$code" "$verdict" "$first" "$note"
}

# ---------------------------------------------------------------------------------------------
# Inputs: a small processed session (simulate, measure, identify), and a measurements file.
log "making the base session (simulate --quick --poses 12 --seed 3, measure, identify)"
BASE=$W/base
"$R" simulate --quick --poses 12 --seed 3 --out "$BASE" >"$W/base.out" 2>&1 &&
  "$R" measure "$BASE" >>"$W/base.out" 2>&1 &&
  "$R" identify "$BASE" >>"$W/base.out" 2>&1 || {
  log "the base session failed:"
  tail -20 "$W/base.out" >&2
  exit 1
}
copy() { rm -rf "$W/$1" && cp -a "$BASE" "$W/$1" && echo "$W/$1"; }
RIGVIEWS=$BASE/calibration/rig
LD=$T/robots/linear_delta.yaml
RD=$T/robots/rotary_delta.yaml
"$R" identify --robot "$LD" --simulate "$W/m.yaml" --kind pose --poses 30 --json "$W/m_sim.json" \
  >"$W/m.out" 2>&1 || log "identify --simulate failed"

# Edited robot files.
sed 's/length: 0.27}/length: 0.05}/g' "$LD" >"$W/short_linear.yaml"
sed 's/d1: 0.9}/d1: 0.1}/g' "$RD" >"$W/short_rods.yaml"
sed 's/limits: \[0.0, 0.45\]/limits: [0.3, 0.3005]/g' "$LD" >"$W/sliver.yaml"
sed '0,/params: {y: 0.174}/s//params: {y: 174}/' "$LD" >"$W/mm_length.yaml"
sed '0,/limits: \[-pi\/3, pi\/2\]/s//limits: [-60, 90]/' "$RD" >"$W/degree_limits.yaml"
cp -r "$T/cells/linear_delta" "$W/cell_deg"
sed -i 's/rpy: \[1.570796326795, 3.141592653590, 1.570796326795\]/rpy: [90, 180, 90]/' \
  "$W/cell_deg/cell.yaml"
for f in short_linear short_rods sliver mm_length degree_limits; do
  cmp -s "$W/$f.yaml" "$LD" && log "edit of $f.yaml made no change"
  cmp -s "$W/$f.yaml" "$RD" && log "edit of $f.yaml made no change"
done

# ---------------------------------------------------------------------------------------------
# Interrupted re-runs: Ctrl-C (SIGINT) 1.5 s into measure / identify on a processed session.
for cmd in measure identify; do
  S=$(copy "int_$cmd")
  before=$(fingerprint "$S")
  out=$W/int_$cmd.out
  "$R" "$cmd" "$S" >"$out" 2>&1 &
  pid=$!
  sleep 1.5
  kill -INT "$pid"
  timeout 120 tail --pid="$pid" -f /dev/null
  wait "$pid"
  code=$?
  classify "ctrl_c_$cmd" "robocal $cmd S; Ctrl-C after 1.5 s" "$code" "130" "interrupted" "$S" \
    "$before" "$out" 130
done

# identify on a truncated results file.
for f in rig.json pixel_observations.json; do
  S=$(copy "trunc_${f%%.*}")
  size=$(stat -c %s "$S/results/$f")
  truncate -s $((size / 2)) "$S/results/$f"
  run_case "identify_truncated_${f%%.*}" 3 "$f" "$S" -- identify "$S"
done

# plan --out onto an existing file with a plan it rejects.
mkdir -p "$W/plan_keep"
echo "the plan the operator had" >"$W/plan_keep/plan_old.yaml"
run_case plan_rejected_keeps_out 1 "NOT accepted|no plan written|plan_old.yaml" "$W/plan_keep" -- \
  plan --cell "$T/cells/delta_two_cameras.yaml" --count 5 --pool 300 --no-order --max-condition 1 \
  --out "$W/plan_keep/plan_old.yaml"

# intrinsics -o onto a folder.
mkdir -p "$W/emptyd"
run_case intrinsics_out_is_folder 3 "emptyd|is a folder" "" -- \
  intrinsics --images "$BASE/calibration/intrinsics/cam0" --target "$BASE/targets/calibration.yaml" \
  -o "$W/emptyd"

# identify --measurements with rotation vectors in degrees.
python3 - "$W/m.yaml" "$W/m_deg.yaml" <<'EOF'
import math, re, sys
text = open(sys.argv[1]).read()
def deg(m):
    return "rotation_vector: [" + ", ".join(str(float(v) * 180 / math.pi) for v in m.group(1).split(",")) + "]"
open(sys.argv[2], "w").write(re.sub(r"rotation_vector: \[([^\]]*)\]", deg, text))
EOF
run_case identify_rotvec_degrees 1 "stated noise|rotation" "" -- \
  identify --robot "$LD" --measurements "$W/m_deg.yaml" --out-robot "$W/deg_calibrated.yaml"
[ -e "$W/deg_calibrated.yaml" ] && sed -i "\$s/\tclear\t/\tgarbage\t/" "$TSV"

# Images of one camera swapped between two poses: those two poses are left out, named.
S=$(copy swapped)
mv "$S/poses/pose_006/cam1.png" "$S/swap.png"
mv "$S/poses/pose_009/cam1.png" "$S/poses/pose_006/cam1.png"
mv "$S/swap.png" "$S/poses/pose_009/cam1.png"
run_case measure_swapped_images 0 "pose_006|pose_009|images disagree" "$S/poses" -- measure "$S"

# measure --rig (folder mode) with one camera's images recorded at another resolution.
"$R" render --camera "$T/vision/camera_640x480.yaml" --target "$BASE/targets/end_effector.yaml" \
  --pose 0,0,0,0,0,0.4 --out "$W/small" >"$W/small.out" 2>&1
cp -r "$BASE/poses" "$W/poses_resized"
small=$(ls "$W"/small/*.png | head -1)
for p in "$W"/poses_resized/pose_*; do cp "$small" "$p/cam1.png"; done
run_case measure_rig_other_resolution 3 "cam1|640x480|1280x960" "" -- \
  measure --rig "$BASE/results/rig.json" --target "$BASE/targets/end_effector.yaml" \
  --poses "$W/poses_resized" --out "$W/resized.json"

# Swapped camera names in a rig file.
python3 - "$BASE/results/rig.json" "$W/rig_swapped.json" <<'EOF'
import json, sys
rig = json.load(open(sys.argv[1]))
a, b = rig["cameras"][0]["name"], rig["cameras"][1]["name"]
rig["cameras"][0]["name"], rig["cameras"][1]["name"] = b, a
json.dump(rig, open(sys.argv[2], "w"), indent=2)
EOF
run_case measure_rig_names_swapped 1 "rig_swapped.json|swapped" "" -- \
  measure --rig "$W/rig_swapped.json" --target "$BASE/targets/end_effector.yaml" \
  --poses "$BASE/poses" --out "$W/names.json"

# Robot and cell values in the wrong units.
run_case robot_lengths_mm 3 "mm_length.yaml:|174|millimetres" "" -- kin check "$W/mm_length.yaml"
run_case robot_limits_degrees 3 "degree_limits.yaml:|-60|degrees" "" -- kin check "$W/degree_limits.yaml"
run_case cell_rpy_degrees 3 "cell.yaml:|rpy|degrees" "" -- \
  plan --cell "$W/cell_deg/cell.yaml" --robot "$LD" --out "$W/p_deg.yaml"

# validate on a calibrated robot file that cannot be read.
S=$(copy validate_unreadable)
echo "robot: [" >"$S/results/calibrated_robot.yaml"
run_case validate_unreadable_calibrated 3 "calibrated_robot.yaml|cannot be read" "$S/poses" -- \
  validate "$S" --held-out 20

# Misspelled keys: session.yaml and a wizard answers file (target_mount).
S=$(copy misspelled)
sed -i 's/^  target_mount:/  target_mont:/' "$S/session.yaml"
run_case session_key_misspelled 3 "session.yaml:|target_mont|target_mount" "$S/poses" -- measure "$S"
printf 'robot:\n  model: linear_delta\n  target_mont: {tool.z: 0.01}\n' >"$W/answers.yaml"
run_case answers_key_misspelled 3 "answers.yaml|target_mont" "" -- \
  wizard "$W/wizard_run" --answers "$W/answers.yaml"

# Conflicting options, options of the other mode.
S=$(copy modes)
run_case priors_and_no_priors 2 "--priors|--no-priors" "" -- \
  identify --robot "$LD" --measurements "$W/m.yaml" --priors --no-priors
run_case session_with_rig 2 "--rig|SESSION" "$S/results" -- measure "$S" --rig "$BASE/results/rig.json"
run_case session_with_target 2 "--target|SESSION" "$S/results" -- \
  measure "$S" --target "$BASE/targets/end_effector.yaml"
run_case session_with_measurements 2 "--measurements|SESSION" "$S/results" -- \
  identify "$S" --measurements "$W/m.yaml"
run_case session_with_kfold 2 "--kfold|SESSION" "$S/results" -- identify "$S" --kfold 5
run_case session_with_holdout_every 2 "--holdout-every|SESSION" "$S/results" -- \
  identify "$S" --holdout-every 4

# sim-controller values.
run_case sim_controller_port_99999 2 "--tcp-port|99999" "" -- \
  sim-controller --robot linear_delta --max-seconds 1 --tcp-port 99999
run_case sim_controller_negative_steps 2 "--steps-per-mm" "" -- \
  sim-controller --robot linear_delta --max-seconds 1 --steps-per-mm -80
run_case sim_controller_negative_noise 2 "--noise" "" -- \
  sim-controller --robot linear_delta --max-seconds 1 --noise -1e-6
run_case sim_controller_cannot_assemble 3 "short_linear.yaml|cannot assemble" "" -- \
  sim-controller --robot "$W/short_linear.yaml" --no-pty --max-seconds 1

# batch with the same session three times.
S=$(copy batch3)
run_case batch_same_session_thrice 2 "batch3|same session folder" "$S/poses" -- batch "$S" "$S" "$S"

# kin fk where the assembly is ambiguous.
run_case kin_fk_ambiguous 1 "assembly mode ambiguous|singularity" "" -- \
  kin fk "$RD" --actuators 0.9,0,0.2

# simulate / plan with a robot that cannot assemble, too few reachable configurations, limits
# in degrees.
run_case simulate_cannot_assemble 3 "short_linear.yaml|cannot assemble" "" -- \
  simulate --robot "$W/short_linear.yaml" --quick --out "$W/sim_short"
run_case plan_cannot_assemble 3 "short_linear.yaml|cannot assemble" "" -- \
  plan --cell "$T/cells/linear_delta/cell.yaml" --robot "$W/short_linear.yaml" --count 10 \
  --out "$W/p_short.yaml"
run_case plan_cannot_assemble_rotary 3 "short_rods.yaml|cannot assemble" "" -- \
  plan --cell "$T/cells/rotary_delta/cell.yaml" --robot "$W/short_rods.yaml" --count 10 \
  --out "$W/p_rods.yaml"
run_case simulate_too_few_reachable 3 "sliver.yaml|too few reachable configurations" "" -- \
  simulate --robot "$W/sliver.yaml" --quick --out "$W/sim_sliver"
run_case simulate_limits_degrees 3 "degree_limits.yaml|degrees" "" -- \
  simulate --robot "$W/degree_limits.yaml" --quick --out "$W/sim_deg"
run_case plan_limits_degrees 3 "degree_limits.yaml|degrees" "" -- \
  plan --cell "$T/cells/rotary_delta/cell.yaml" --robot "$W/degree_limits.yaml" --count 10 \
  --out "$W/p_deg2.yaml"

# A symbolic link loop inside a session: measure and batch.
S=$(copy link_loop)
ln -s loop_b "$S/poses/loop_a"
ln -s loop_a "$S/poses/loop_b"
run_case measure_symlink_loop 3 "loop_|symbolic link loop" "$S/results" -- measure "$S"
run_case batch_symlink_loop 1 "loop_|symbolic link loop" "$S/results" -- \
  batch "$S" --json "$W/batch_loop.json"
grep -q "symbolic link loop" "$W/batch_loop.json" 2>/dev/null ||
  log "batch_symlink_loop: the summary does not name the loop"

# Bad values of options, an unknown command.
run_case actuators_abc 2 "--actuators|abc" "" -- kin fk "$LD" --actuators abc
run_case kind_foo 2 "--kind|foo" "" -- identify --robot "$LD" --simulate "$W/k.yaml" --kind foo
run_case model_foo 2 "--model|foo" "" -- \
  intrinsics --images "$BASE/calibration/intrinsics/cam0" --target "$BASE/targets/calibration.yaml" \
  --model foo
run_case firmware_foo 2 "--firmware|foo" "" -- \
  sim-controller --robot linear_delta --firmware foo --max-seconds 1
run_case faults_bogus 2 "--faults|bogus" "" -- \
  sim-controller --robot linear_delta --faults bogus=0.5 --max-seconds 1
run_case unknown_command 2 "frobnicate" "" -- frobnicate

# A camera file of another resolution than the rig views' images.
cams=()
first_view=$(find "$RIGVIEWS" -mindepth 1 -maxdepth 1 -type d | sort | head -1)
for png in "$first_view"/*.png; do
  cams+=(--camera "$(basename "$png" .png)=$T/vision/camera_640x480.yaml")
done
run_case rig_camera_other_resolution "1|3" "640x480|sees the board" "" -- \
  rig --target "$BASE/targets/calibration.yaml" --views "$RIGVIEWS" "${cams[@]}" \
  --out "$W/rig_res.json"

# A pose folder without read permission, for an unprivileged user (root ignores permissions).
S=$(copy unreadable)
chmod -R a+rwX "$S"
chmod 000 "$S/poses/pose_003"
before=$(fingerprint "$S/poses/pose_000")
out=$W/unreadable.out
(cd /tmp && timeout -s KILL 120 setpriv --reuid 65534 --regid 65534 --clear-groups \
  "$R" measure "$S" >"$out" 2>&1)
code=$?
classify folder_without_read_permission "setpriv --reuid 65534 ... robocal measure S (pose_003 mode 000)" \
  "$code" "0|1|3" "pose_003|permission denied" "$S/poses/pose_000" "$before" "$out"
chmod 755 "$S/poses/pose_003"

# A board file with the wrong column count.
S=$(copy columns)
cols=$(grep -m1 -o 'cols: [0-9]*' "$S/targets/end_effector.yaml" | grep -o '[0-9]*')
sed -i "0,/cols: $cols/s//cols: $((cols + 1))/" "$S/targets/end_effector.yaml"
run_case board_wrong_columns 1 "board's file does not match|cols" "$S/poses" -- measure "$S"

# ---------------------------------------------------------------------------------------------
# collect against a simulated cell (sim-cell: a simulated controller and in-process cameras).
log "starting a simulated cell for collect (rendering its calibration views takes minutes)"
CELL=$W/cell
"$R" sim-cell --robot linear_delta --quick --in-process --out "$CELL" --max-seconds 1800 \
  >"$W/sim_cell.out" 2>&1 &
SIM_CELL_PID=$!
for _ in $(seq 1 600); do
  grep -q '^ready:' "$W/sim_cell.out" 2>/dev/null && break
  kill -0 "$SIM_CELL_PID" 2>/dev/null || break
  sleep 1
done
LINK=$(grep -m1 'Controller address:' "$W/sim_cell.out" | grep -o -E 'tcp:[0-9.]+:[0-9]+')
if [ -z "$LINK" ]; then
  log "the simulated cell did not start:"
  tail -20 "$W/sim_cell.out" >&2
  record collect_guard_refuses_later_pose "robocal collect ..." "-" "not run" "sim-cell did not start" ""
  record collect_infeasible_plan "robocal collect ..." "-" "not run" "sim-cell did not start" ""
else
  CAMS=()
  for c in $(grep -m1 '^  Cameras:' "$W/sim_cell.out" | sed 's/^  Cameras: *//'); do
    CAMS+=(--camera "$c")
  done
  "$R" plan --cell "$CELL/cell/cell.yaml" --robot linear_delta --count 6 --pool 600 \
    --out "$W/plan_ok.yaml" >"$W/plan_ok.out" 2>&1 || log "planning for collect failed"
  # The last pose 9 cm below the others: out of the cell's workspace box.
  python3 - "$W/plan_ok.yaml" "$W/plan_guard.yaml" <<'EOF'
import re, sys
lines = open(sys.argv[1]).read().split("\n")
last = max(i for i, l in enumerate(lines) if "actuators: [" in l)
m = re.search(r"actuators: \[([^\]]*)\]", lines[last])
vals = ", ".join(str(float(v) - 0.09) for v in m.group(1).split(","))
lines[last] = lines[last][:m.start(1)] + vals + lines[last][m.end(1):]
open(sys.argv[2], "w").write("\n".join(lines))
EOF
  sed 's/^status: .*/status: infeasible/' "$W/plan_ok.yaml" >"$W/plan_infeasible.yaml"
  grep -q '^status: infeasible' "$W/plan_infeasible.yaml" ||
    { echo "status: infeasible"; cat "$W/plan_ok.yaml"; } >"$W/plan_infeasible.yaml"
  run_case collect_guard_refuses_later_pose 1 "to pose|before anything moved|outside its limits" "" -- \
    collect "$W/coll_guard" --robot linear_delta --cell "$CELL/cell/cell.yaml" \
    --plan "$W/plan_guard.yaml" --link "$LINK" "${CAMS[@]}" --yes
  [ -e "$W/coll_guard/poses" ] && log "collect_guard: poses were recorded"
  run_case collect_infeasible_plan 3 "plan_infeasible.yaml|infeasible|--accept-infeasible-plan" "" -- \
    collect "$W/coll_inf" --robot linear_delta --cell "$CELL/cell/cell.yaml" \
    --plan "$W/plan_infeasible.yaml" --link "$LINK" "${CAMS[@]}" --yes
fi

# ---------------------------------------------------------------------------------------------
# The table and the totals.
{
  echo "# Survey recount"
  echo
  echo "Program: \`$R\` ($(cd "$SRC" && git rev-parse --short HEAD) on $(cd "$SRC" && git rev-parse --abbrev-ref HEAD)), $(date -u +%Y-%m-%dT%H:%MZ)."
  echo "Script: tests/survey/recount.sh (verdicts defined at its top). \$W is its temporary folder."
  echo
  echo "| case | command | exit | first message line | verdict | note |"
  echo "| --- | --- | --- | --- | --- | --- |"
  while IFS=$'\t' read -r name cmd code verdict first note; do
    cmd=${cmd//|/\\|}
    first=${first//|/\\|}
    note=${note//|/\\|}
    echo "| $name | \`$cmd\` | $code | $first | **$verdict** | $note |"
  done <"$TSV"
  echo
  echo "## Totals"
  echo
  echo "| verdict | cases |"
  echo "| --- | --- |"
  for v in clear unclear garbage crash hang lost "not run"; do
    n=$(cut -f4 "$TSV" | grep -c -x "$v")
    echo "| $v | $n |"
  done
  echo "| all | $(wc -l <"$TSV") |"
} >"$HERE/counts.md"
log "done: $HERE/counts.md"
cut -f4 "$TSV" | sort | uniq -c >&2
