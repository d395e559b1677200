#!/usr/bin/env bash
# Writes the library's cells, testdata/cells/ROBOT/, one per library robot: the cell folder of
# `robocal sim-cell --robot ROBOT --seed 1` (cameras where the planner placed them to see the
# robot's working volume, their datasheet intrinsics, the end-effector and calibration boards).
#
#   scripts/library-cells.sh [ROBOT...]      (default: every robot in testdata/robots/)
#
#   ROBOCAL   the robocal binary (default build/release/app/robocal of this checkout)
set -euo pipefail
cd "$(dirname "$0")/.."
robocal=${ROBOCAL:-build/release/app/robocal}
if [ $# -gt 0 ]; then robots=("$@"); else
  mapfile -t robots < <(ls testdata/robots/*.yaml | xargs -n1 basename | sed 's/\.yaml$//')
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for robot in "${robots[@]}"; do
  # --in-process: no camera is served; the cell is written before the cell starts running.
  "$robocal" sim-cell --robot "$robot" --seed 1 --in-process --out "$work/$robot" \
    --max-seconds 1 >"$work/$robot.log" 2>&1 || { cat "$work/$robot.log" >&2; exit 1; }
  out=testdata/cells/$robot
  rm -rf "$out"
  mkdir -p "$out"
  {
    echo "# $robot: the cell \`robocal sim-cell --robot $robot --seed 1\` builds (cameras placed by"
    echo "# the planner to see the working volume; regenerate: scripts/library-cells.sh $robot)."
    sed "s/^cell: .*/cell: $robot/" "$work/$robot/cell/cell.yaml"
  } >"$out/cell.yaml"
  for f in "$work/$robot"/cell/*.yaml; do
    [ "$(basename "$f")" = cell.yaml ] || cp "$f" "$out/"
  done
  echo "$out: $(grep -c '^  - name:' "$out/cell.yaml") cameras"
done
