#!/usr/bin/env bash
# The README's main command: installs what is missing, builds, and runs the embedded demo.
# Extra arguments are passed to `robocal demo` (e.g. --seed 7 --out /tmp/demo).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/bootstrap.sh
# Only the program (each library's sources compiled in batches: ROBOCAL_BATCH_BUILD in
# CMakeLists.txt).
bash scripts/build.sh release robocal
exec ./build/release/app/robocal demo "$@"
