#!/usr/bin/env bash
# The README's test command: installs what is missing, builds everything (release) and runs the
# whole test suite (unit, integration, end-to-end). Benchmarks are built but not run.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh --tests
bash scripts/build.sh release
ctest --preset release "$@"
