#!/usr/bin/env bash
# Runs `robocal batch` as N shards on this machine (N processes at once, as a Slurm job array or
# a Kubernetes indexed Job runs them on N machines) and merges their summaries with
# `robocal batch-merge`: a local rehearsal of the cluster setups in docs/cluster.md.
#
#   scripts/batch-shards.sh [-n SHARDS] [-w WORKDIR] [-a BATCH_ARG]... OUT.json FOLDER...
#
#   -n SHARDS   number of shards (default 2)
#   -w WORKDIR  where each shard's summary (shard-K.json) and console output (shard-K.log) go
#               (default: OUT.json without .json, plus .shards/)
#   -a ARG      one more argument for every shard's `robocal batch` (repeat: -a --jobs -a 2)
#   ROBOCAL     the robocal binary (default build/release/app/robocal of this checkout, else
#               robocal on PATH)
#
# Exit code: the merge's (0 every session ok, 1 some failed, 3 a summary refused); a shard that
# ends with another code than 0 or 1 stops the script with that code, naming its log.
set -euo pipefail

usage() {
  sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
}

shards=2
work=""
batch_args=()
while getopts "n:w:a:h" opt; do
  case "$opt" in
    n) shards="$OPTARG" ;;
    w) work="$OPTARG" ;;
    a) batch_args+=("$OPTARG") ;;
    *) usage ;;
  esac
done
shift $((OPTIND - 1))
[[ $# -ge 2 ]] || usage
[[ "$shards" =~ ^[1-9][0-9]*$ ]] || { echo "batch-shards.sh: -n: '$shards' is not a number of shards (1 or more)" >&2; exit 2; }
out="$1"
shift
[[ -n "$work" ]] || work="${out%.json}.shards"

if [[ -z "${ROBOCAL:-}" ]]; then
  ROBOCAL="$(cd "$(dirname "$0")/.." && pwd)/build/release/app/robocal"
  [[ -x "$ROBOCAL" ]] || ROBOCAL=robocal
fi

mkdir -p "$work"
pids=()
for ((k = 0; k < shards; k++)); do
  rm -f "$work/shard-$k.json"
  "$ROBOCAL" batch --shard "$k/$shards" --json "$work/shard-$k.json" "${batch_args[@]}" "$@" \
    >"$work/shard-$k.log" 2>&1 &
  pids+=($!)
done

status=0
for ((k = 0; k < shards; k++)); do
  rc=0
  wait "${pids[$k]}" || rc=$?
  echo "shard $k/$shards: exit $rc (log: $work/shard-$k.log)"
  if [[ $rc -ne 0 && $rc -ne 1 && $status -eq 0 ]]; then
    echo "batch-shards.sh: shard $k/$shards ended with exit code $rc; the end of its log:" >&2
    tail -n 5 "$work/shard-$k.log" >&2
    status=$rc
  fi
done
[[ $status -eq 0 ]] || exit "$status"

summaries=()
for ((k = 0; k < shards; k++)); do summaries+=("$work/shard-$k.json"); done
exec "$ROBOCAL" batch-merge "${summaries[@]}" --json "$out"
