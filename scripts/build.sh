#!/usr/bin/env bash
# Configures and builds a preset (default: release). Usage: scripts/build.sh [preset] [targets...]
set -euo pipefail
cd "$(dirname "$0")/.."
# ccache keyed on paths relative to the checkout, so a fresh clone elsewhere (CI) reuses objects.
export CCACHE_BASEDIR="$PWD" CCACHE_NOHASHDIR=1
preset=${1:-release}
shift || true

# A build folder whose cache disagrees with the preset (another C++ compiler, or a preset variable
# missing) is configured from scratch (--fresh). Left to itself, CMake notices a compiler change,
# deletes its cache and configures again without the preset's other variables: a release folder
# once built with GCC would build with clang but without CMAKE_BUILD_TYPE, i.e. unoptimised, and
# say nothing.
cache="build/$preset/CMakeCache.txt"
fresh=()
if [ -f "$cache" ]; then
  while IFS='=' read -r name value; do
    recorded=$(sed -n "s/^$name:[A-Z]*=//p" "$cache")
    case "$name" in
      # Compared as the programs they name: the cache holds the name the preset gave (clang++)
      # after a plain configure, the path CMake found (/usr/bin/clang++) after a fresh one.
      CMAKE_C_COMPILER | CMAKE_CXX_COMPILER)
        value=$(command -v "$value" || echo "$value")
        recorded=$(command -v "$recorded" || echo "$recorded")
        ;;
    esac
    if [ "$value" != "$recorded" ]; then
      echo "build.sh: build/$preset has $name=${recorded:-(unset)}, the preset $value:" \
        "configuring it from scratch" >&2
      fresh=(--fresh)
      break
    fi
  done < <(cmake --preset "$preset" -N | sed -n 's/^ *\([A-Za-z_0-9]*\)="\(.*\)"$/\1=\2/p')
fi
cmake --preset "$preset" "${fresh[@]}" >/dev/null
if [ $# -gt 0 ]; then
  cmake --build --preset "$preset" --target "$@"
else
  cmake --build --preset "$preset"
fi
