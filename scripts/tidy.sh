#!/usr/bin/env bash
# Runs clang-tidy (checks in .clang-tidy) over the project's sources, or the files given.
# Needs a configured release build for compile_commands.json.
#
# A file that passed is remembered (ROBOCAL_TIDY_CACHE, default ~/.cache/robocal-tidy) under a
# key of everything its verdict depends on: the clang-tidy version, .clang-tidy, the file's own
# compile command, its own text and the text of every project header it includes. The headers a file includes are the compiler's own record (ninja's dependency log of
# the release build, current after a build); a file the log does not know is keyed on every
# project header instead. So a header change re-checks only the files that include it.
# ROBOCAL_TIDY_CACHE=off disables the cache.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -f build/release/compile_commands.json ] || cmake --preset release >/dev/null
# scripts/demo.sh compiles robocal_app's sources in batches, which leaves them no compile command
# of their own.
if grep -q '^ROBOCAL_UNITY_BUILD:BOOL=ON' build/release/CMakeCache.txt; then
  echo "tidy: build/release compiles robocal_app in batches (ROBOCAL_UNITY_BUILD=ON, from" \
       "scripts/demo.sh); run: cmake --preset release -DROBOCAL_UNITY_BUILD=OFF" >&2
  exit 1
fi
if [ $# -gt 0 ]; then files=("$@"); else
  mapfile -t files < <(git ls-files '*.cpp' | grep -E '^(app|calib|core|vision|planner|robotio)/')
fi

cache=${ROBOCAL_TIDY_CACHE:-$HOME/.cache/robocal-tidy}
if [ "$cache" = off ]; then
  printf '%s\n' "${files[@]}" | xargs -P 2 -n 4 clang-tidy -p build/release --quiet
  exit 0
fi
mkdir -p "$cache"

# What every file's verdict depends on: the tool and its checks. Its flags are its own compile
# command (compile_commands.json, with this checkout's path taken out so that a clean checkout
# elsewhere finds the same keys).
common=$( { clang-tidy --version; cat .clang-tidy; } | sha256sum | cut -d' ' -f1)
declare -A commands=()
while IFS=$'\t' read -r src cmd; do commands[$src]=$cmd; done < <(
  awk -v root="$PWD/" '
    /^ *"command":/ { cmd = $0; gsub(root, "", cmd) }
    /^ *"file":/ { f = $0; sub(/^ *"file": *"/, "", f); sub(/",? *$/, "", f); sub(root, "", f)
                   print f "\t" cmd }' build/release/compile_commands.json)
# Fallback for a file without a dependency record: every project and generated header.
all_headers=$(
  {
    git ls-files --cached --others --exclude-standard -z -- '*.hpp' '*.h' | sort -z \
      | xargs -0 sha256sum
    find build/release/app/generated -type f -print0 2>/dev/null | sort -z | xargs -0 -r cat
  } | sha256sum | cut -d' ' -f1
)

# source file (relative to the checkout) -> the project headers it includes (relative to the
# build directory: ../../x for the checkout's, generated ones without ../), one line per source.
declare -A deps=()
while IFS=$'\t' read -r src list; do deps[$src]=$list; done < <(
  ninja -C build/release -t deps 2>/dev/null | awk '
    /^[^ ].*: #deps/ { if (src != "") print src "\t" list; src = ""; list = ""; first = 1; next }
    /^    / { p = $1
              if (first) { first = 0; sub(/^\.\.\/\.\.\//, "", p); src = p; next }
              if (p !~ /^\//) list = list " " p }
    END { if (src != "") print src "\t" list }')

header_key() {  # $1: the source; prints the hash of the project headers it includes
  local list=${deps[$1]-}
  if [ -z "${deps[$1]+set}" ]; then echo "all $all_headers"; return; fi
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

check_one() { clang-tidy -p build/release --quiet "$1" && touch "$2/$3"; }
export -f check_one
printf '%s\n' "${todo[@]}" | xargs -P 2 -n 2 bash -c 'check_one "$0" "'"$cache"'" "$1"'
