#!/usr/bin/env bash
# Runs clang-tidy (checks in .clang-tidy) over the project's sources, or the files given.
# Needs a configured release build for compile_commands.json.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -f build/release/compile_commands.json ] || cmake --preset release >/dev/null
if [ $# -gt 0 ]; then files=("$@"); else
  mapfile -t files < <(git ls-files '*.cpp' | grep -E '^(app|calib|core|vision|planner|robotio)/')
fi
printf '%s\n' "${files[@]}" | xargs -P 2 -n 4 clang-tidy -p build/release --quiet
