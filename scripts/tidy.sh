#!/usr/bin/env bash
# Runs clang-tidy (checks in .clang-tidy) over the project's sources, or the files given.
# Needs a configured release build for compile_commands.json.
#
# A file that passed is remembered (ROBOCAL_TIDY_CACHE, default ~/.cache/robocal-tidy) under a
# key of everything its verdict depends on: the clang-tidy version, .clang-tidy, the file's own
# compile command, its own text and the text of every project header it includes. The headers a
# file includes are the compiler's own record (ninja's dependency log of the release build, current
# after a build; for a source compiled in a batch, the batch's); a file the log does not know is
# keyed on every project header instead. So a header change re-checks only the files that include
# it.
# ROBOCAL_TIDY_CACHE=off disables the cache.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -f build/release/compile_commands.json ] || cmake --preset release >/dev/null
if [ $# -gt 0 ]; then files=("$@"); else
  mapfile -t files < <(git ls-files '*.cpp' | grep -E '^(app|calib|core|vision|planner|robotio)/')
fi

# Every source's own compile command. A library compiled in batches (ROBOCAL_BATCH_BUILD) has
# commands for its batch sources only; each batch line names the source it includes (after //),
# which is checked with the batch's command, compiling that source instead (without the warnings
# only a batch switches off). Written as a
# compilation database of its own (build/release/tidy-sources) for clang-tidy's -p, with the
# object each source's dependencies are recorded under (its batch's, or its own).
sources_db=build/release/tidy-sources
mkdir -p "$sources_db"
awk -v root="$PWD/" -v objects="$sources_db/objects.tsv" '
  # One field per line, as CMake writes it: the readers below take a field per line.
  function emit(file, cmd) {
    printf "%s{\n  \"directory\": \"%s\",\n  \"command\": \"%s\",\n  \"file\": \"%s\"\n}\n", sep, dir, cmd, file
    sep = ","
  }
  BEGIN { print "[" }
  /^ *"directory":/ { dir = $0; sub(/^ *"directory": *"/, "", dir); sub(/",? *$/, "", dir) }
  /^ *"command":/ { cmd = $0; sub(/^ *"command": *"/, "", cmd); sub(/",? *$/, "", cmd) }
  /^ *"file":/ {
    f = $0; sub(/^ *"file": *"/, "", f); sub(/",? *$/, "", f)
    obj = cmd; sub(/^.* -o /, "", obj); sub(/ .*$/, "", obj)
    if (f !~ /\.batches\/batch_[0-9]+\.cpp$/) {
      rel = f; sub(root, "", rel); print rel "\t" obj > objects; emit(f, cmd); next
    }
    while ((getline line < f) > 0) {
      if (line !~ /^#include ".*"  \/\/ /) continue
      rel = line; sub(/^.*  \/\/ /, "", rel)
      c = cmd; sub(/ -c [^ ]*$/, " -c " root rel, c)
      # The warnings a batch alone switches off (cmake/RobocalBatches.cmake) stay on.
      gsub(/ -Wno-(subobject-linkage|restrict|null-dereference)/, "", c)
      print rel "\t" obj > objects; emit(root rel, c)
    }
    close(f)
  }
  END { print "]" }' build/release/compile_commands.json >"$sources_db/compile_commands.json"

cache=${ROBOCAL_TIDY_CACHE:-$HOME/.cache/robocal-tidy}
if [ "$cache" = off ]; then
  printf '%s\n' "${files[@]}" | xargs -P 2 -n 4 clang-tidy -p "$sources_db" --quiet
  exit 0
fi
mkdir -p "$cache"

# What every file's verdict depends on: the tool and its checks. Its flags are its own compile
# command without its output and input (with this checkout's path taken out so that a clean
# checkout elsewhere finds the same keys).
common=$( { clang-tidy --version; cat .clang-tidy; } | sha256sum | cut -d' ' -f1)
declare -A commands=() object_of=()
while IFS=$'\t' read -r src cmd; do commands[$src]=$cmd; done < <(
  awk -v root="$PWD/" '
    /^ *"command":/ { cmd = $0; sub(/ -o .*$/, "", cmd); gsub(root, "", cmd) }
    /^ *"file":/ { f = $0; sub(/^ *"file": *"/, "", f); sub(/",? *$/, "", f); sub(root, "", f)
                   print f "\t" cmd }' "$sources_db/compile_commands.json")
while IFS=$'\t' read -r src obj; do object_of[$src]=$obj; done <"$sources_db/objects.tsv"
# Fallback for a file without a dependency record: every project and generated header.
all_headers=$(
  {
    git ls-files --cached --others --exclude-standard -z -- '*.hpp' '*.h' | sort -z \
      | xargs -0 sha256sum
    find build/release/app/generated -type f -print0 2>/dev/null | sort -z | xargs -0 -r cat
  } | sha256sum | cut -d' ' -f1
)

# object (relative to the build directory) -> the project headers its source includes (relative
# to the build directory: ../../x for the checkout's, generated ones without ../), from ninja's
# dependency log. A batch's list serves each of its sources: a superset of what one includes.
declare -A deps=()
while IFS=$'\t' read -r obj list; do deps[$obj]=$list; done < <(
  ninja -C build/release -t deps 2>/dev/null | awk '
    /^[^ ].*: #deps/ { if (obj != "") print obj "\t" list; obj = $1; sub(/:$/, "", obj); list = ""; next }
    /^    / { p = $1; if (p !~ /^\// && p !~ /\.cpp$/) list = list " " p }
    END { if (obj != "") print obj "\t" list }')

header_key() {  # $1: the source; prints the hash of the project headers it includes
  local obj=${object_of[$1]-}
  local list=${deps[$obj]-}
  if [ -z "$obj" ] || [ -z "${deps[$obj]+set}" ]; then echo "all $all_headers"; return; fi
  # shellcheck disable=SC2086  # the list is space-separated paths without spaces
  (cd build/release && sha256sum $list </dev/null) | sha256sum | cut -d' ' -f1
}

todo=()
for f in "${files[@]}"; do
  key=$( { echo "$common $f $(header_key "$f")"; echo "${commands[$f]-all}"; cat "$f"; } \
    | sha256sum | cut -d' ' -f1)
  [ -e "$cache/$key" ] || todo+=("$f" "$key")
done
echo "tidy: $(( ${#todo[@]} / 2 )) of ${#files[@]} files to check ($(( ${#files[@]} - ${#todo[@]} / 2 )) unchanged since they passed)"
[ ${#todo[@]} -eq 0 ] && exit 0

# Files are checked in batches. Most of a file's check time goes to the headers it includes
# (Eigen, Ceres, OpenCV: parsed, and walked by every check's matchers), not to its own code; the
# files of one library target share their compile flags and most of those headers, so up to
# eight of them are checked as one translation unit that includes them (about 3x less work than
# one at a time). A batch that fails (a finding, or two files that clash only when compiled
# together, such as equal names in anonymous namespaces) is checked again file by file, and only
# those verdicts count. What a batch can miss: a using-declaration one file leaves unused and a
# later file of the same batch uses (misc-unused-using-decls). core/ is checked file by file: the
# header filter leaves its files out when they are included.
batches=build/release/tidy-batches
rm -rf "$batches" && mkdir -p "$batches"
declare -A raw=()  # source (relative) -> its compile command as written in the JSON
while IFS=$'\t' read -r src cmd; do raw[$src]=$cmd; done < <(
  awk -v root="$PWD/" '
    /^ *"command":/ { cmd = $0; sub(/^ *"command": *"/, "", cmd); sub(/",? *$/, "", cmd) }
    /^ *"file":/ { f = $0; sub(/^ *"file": *"/, "", f); sub(/",? *$/, "", f); sub(root, "", f)
                   print f "\t" cmd }' "$sources_db/compile_commands.json")
declare -A group_of=() members=()
jobs=()
for ((i = 0; i < ${#todo[@]}; i += 2)); do
  f=${todo[i]}
  if [[ $f == core/* || -z ${raw[$f]+set} || ${raw[$f]} != *" -o "* ]]; then
    jobs+=("- ${todo[i]} ${todo[i + 1]}"); continue
  fi
  flags=${raw[$f]% -o *}
  g=${group_of[$flags]-}
  if [ -z "$g" ] || [ "$(wc -w <<<"${members[$g]}")" -ge 16 ]; then
    g=$(( ${#members[@]} + 1 )); group_of[$flags]=$g; members[$g]=""
    echo "$flags" >"$batches/$g.flags"
  fi
  members[$g]+="$f ${todo[i + 1]} "
done
{
  echo "["; sep=""
  for g in "${!members[@]}"; do
    unit="$PWD/$batches/batch$g.cpp"
    for w in ${members[$g]}; do
      [[ $w == *.cpp ]] && echo "#include \"$PWD/$w\"  // NOLINT(bugprone-suspicious-include)"
    done >"$unit"
    printf '%s{"directory": "%s", "command": "%s -o batch%s.o -c %s", "file": "%s"}\n' \
      "$sep" "$PWD/build/release" "$(cat "$batches/$g.flags")" "$g" "$unit" "$unit"
    sep=","
    jobs+=("$unit ${members[$g]}")
  done
  echo "]"
} >"$batches/compile_commands.json"

# $1: "UNIT file key file key ...": UNIT the batch's translation unit, or - for one file checked
# alone. A failed batch is checked again file by file. Passed files are remembered in the cache.
check_job() {
  local -a w
  read -r -a w <<<"$1"
  if [ "${w[0]}" != - ] && clang-tidy -p "$batches" --quiet "${w[0]}" >"${w[0]}.log" 2>&1; then
    for ((j = 2; j < ${#w[@]}; j += 2)); do touch "$cache/${w[j]}"; done
    return 0
  fi
  local status=0
  for ((j = 1; j < ${#w[@]}; j += 2)); do
    if clang-tidy -p "$sources_db" --quiet "${w[j]}"; then touch "$cache/${w[j + 1]}"; else status=1; fi
  done
  return $status
}
export -f check_job
export cache batches sources_db
printf '%s\0' "${jobs[@]}" | xargs -0 -P 2 -n 1 bash -c 'check_job "$0"'
