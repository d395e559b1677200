#!/usr/bin/env bash
# Runs clang-tidy (checks in .clang-tidy) over the project's sources, or the files given.
# Needs a configured release build for compile_commands.json.
#
# A file that passed is remembered (ROBOCAL_TIDY_CACHE, default ~/.cache/robocal-tidy) under a
# key of everything its verdict depends on: its own text, every project header and build file,
# the generated headers, .clang-tidy and the clang-tidy version. An unchanged file is not checked
# again; any header or flag change checks everything. ROBOCAL_TIDY_CACHE=off disables it.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -f build/release/compile_commands.json ] || cmake --preset release >/dev/null
if [ $# -gt 0 ]; then files=("$@"); else
  mapfile -t files < <(git ls-files '*.cpp' | grep -E '^(app|calib|core|vision|planner|robotio)/')
fi

cache=${ROBOCAL_TIDY_CACHE:-$HOME/.cache/robocal-tidy}
if [ "$cache" = off ]; then
  printf '%s\n' "${files[@]}" | xargs -P 2 -n 4 clang-tidy -p build/release --quiet
  exit 0
fi
mkdir -p "$cache"

common=$(
  {
    clang-tidy --version
    cat .clang-tidy
    git ls-files --cached --others --exclude-standard -z -- '*.hpp' '*.h' '*CMakeLists.txt' \
      '*.cmake' 'CMakePresets.json' | sort -z | xargs -0 sha256sum
    find build/release/app/generated -type f -print0 2>/dev/null | sort -z | xargs -0 -r cat
  } | sha256sum | cut -d' ' -f1
)

todo=()
for f in "${files[@]}"; do
  key=$( { echo "$common $f"; cat "$f"; } | sha256sum | cut -d' ' -f1)
  [ -e "$cache/$key" ] || todo+=("$f" "$key")
done
echo "tidy: $(( ${#todo[@]} / 2 )) of ${#files[@]} files to check ($(( ${#files[@]} - ${#todo[@]} / 2 )) unchanged since they passed)"
[ ${#todo[@]} -eq 0 ] && exit 0

check_one() { clang-tidy -p build/release --quiet "$1" && touch "$2/$3"; }
export -f check_one
printf '%s\n' "${todo[@]}" | xargs -P 2 -n 2 bash -c 'check_one "$0" "'"$cache"'" "$1"'
