#!/usr/bin/env bash
# Installs the Debian 12 packages robocal needs that are not yet installed. Idempotent: when
# everything is present it does nothing (no apt-get update, no network).
#
#   scripts/bootstrap.sh          what building and running `robocal` needs (scripts/demo.sh)
#   scripts/bootstrap.sh --tests  that, plus what the test suite, the benchmarks and the CI
#                                 checks use (scripts/test.sh, .ci/run)
#
# The test-only packages (chromium, clang-tidy, gtest, ...) are a large part of the download,
# which a user trying the demo does not need.
set -euo pipefail

usage() { echo "usage: $0 [--tests]" >&2; exit 2; }
with_tests=0
case "${1-}" in
  "") ;;
  --tests) with_tests=1 ;;
  *) usage ;;
esac
[ $# -le 1 ] || usage

packages=(
  # toolchain: the release build (demo, test command) compiles with clang, quicker than GCC here
  # (docs/figures.md); GCC (build-essential) builds the sanitizer preset, and build-essential's
  # dpkg-dev makes the Debian package
  build-essential clang cmake ninja-build pkg-config ccache
  # the Debian package (cpack): dpkg-shlibdeps (dpkg-dev, from build-essential) reads the
  # dependencies of the files `file` says are ELF programs
  file
  # vision and numerics
  libopencv-dev libopencv-contrib-dev libapriltag-dev libceres-dev libeigen3-dev
  # the capture writes its PNG frames through libpng itself (OpenCV's writer is twice as slow)
  libpng-dev
  # cameras: Aravis' pkg-config file needs libusb-1.0-0-dev, which libaravis-dev does not pull in
  libv4l-dev libaravis-dev libusb-1.0-0-dev
  # planner: collision and distance queries (FCL; pulls in libccd and octomap)
  libfcl-dev
  # exports: URDF read and written through urdfdom (robocal export --format urdf)
  liburdfdom-dev
  # file formats, command line, logging
  libyaml-cpp-dev nlohmann-json3-dev libcli11-dev libspdlog-dev libfmt-dev
  # the wizard's line editing
  libreadline-dev
)
if [ "$with_tests" -eq 1 ]; then
  packages+=(
    # tests and benchmarks
    libgtest-dev libgmock-dev libbenchmark-dev
    # the report's test renders the HTML page headless
    chromium
    # camera tests: a network namespace per test run (ip netns) for two fake GigE cameras
    iproute2
    # CI's format and static checks (scripts/check-format.sh, scripts/tidy.sh list files by git)
    clang-format clang-tidy git
    # the open link's reference adapter (robotio/adapters, Python standard library) is run
    # against link-check
    python3
  )
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "bootstrap: all ${#packages[@]} Debian packages present"
  exit 0
fi

echo "bootstrap: installing ${#missing[@]} missing Debian packages: ${missing[*]}"
sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    sudo_cmd=(sudo)
  else
    echo "bootstrap: not root and no sudo; install these packages as root: ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" </dev/null
