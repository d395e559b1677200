#!/usr/bin/env bash
# `cmake --install` of a build into a temporary prefix (through DESTDIR, as a package build does),
# then the installed robocal run from a folder outside the source and build trees: it must find
# its robot library under <prefix>/share/robocal/robots, not in the source tree it was built from.
# Usage: install_prefix.sh <build dir>
set -euo pipefail
build=$(cd "$1" && pwd)
fail() { echo "install_prefix: $*" >&2; exit 1; }

work=$(mktemp -d "${TMPDIR:-/tmp}/robocal_install.XXXXXX")
trap 'rm -rf "$work"' EXIT
prefix=/opt/robocal-install-test
DESTDIR="$work/root" cmake --install "$build" --prefix "$prefix" >"$work/install.log" \
  || { cat "$work/install.log" >&2; fail "cmake --install $build failed"; }
root=$work/root$prefix

# The layout: program, robot library, documents, examples; nothing else (no tests, no static
# libraries, no headers).
for f in bin/robocal share/robocal/robots/rotary_delta.yaml share/robocal/robots/README.md \
         share/doc/robocal/README.md share/doc/robocal/planner/README.md \
         share/doc/robocal/examples/cells/delta_two_cameras.yaml; do
  [ -f "$root/$f" ] || fail "$root/$f was not installed"
done
[ -x "$root/bin/robocal" ] || fail "$root/bin/robocal is not executable"
stray=$(cd "$root" && find . -type f ! -path './bin/robocal' ! -path './share/robocal/*' \
          ! -path './share/doc/robocal/*')
[ -z "$stray" ] || fail "installed outside bin/robocal, share/robocal and share/doc/robocal: $stray"

# Run from a folder of its own: a relative path into the source tree cannot resolve there.
mkdir "$work/cwd" && cd "$work/cwd"
unset ROBOCAL_ROBOT_LIBRARY
exe=$root/bin/robocal

# A robot file that only the installed library has: resolving it by name proves the library is
# the installed one (the source tree's testdata/robots has no such file).
cp "$root/share/robocal/robots/linear_delta.yaml" "$root/share/robocal/robots/installed_only.yaml"
set +e
"$exe" demo --robot installed_only --quick --route pose --poses 24 --held-out 50 --seed 2 \
  --out "$work/cwd/demo" --json "$work/cwd/demo.json" >"$work/demo.log" 2>&1
rc=$?
set -e
[ $rc -eq 0 ] || { cat "$work/demo.log" >&2; fail "installed robocal demo --robot installed_only: exit $rc"; }
grep -q '"validate"' "$work/cwd/demo.json" || fail "the demo wrote no validation ($work/cwd/demo.json)"

# An unknown robot names the installed library folder and the robots in it.
set +e
msg=$("$exe" demo --robot no_such_robot --quick 2>&1)
rc=$?
set -e
[ $rc -eq 3 ] || fail "an unknown robot gave exit $rc, not 3 (bad input): $msg"
case $msg in
  *"$root/share/robocal/robots"*installed_only*rotary_delta*) ;;
  *) fail "the unknown-robot message does not name the installed library and its robots: $msg" ;;
esac

# The override: a folder that does not exist is refused by name.
set +e
msg=$(ROBOCAL_ROBOT_LIBRARY="$work/none" "$exe" demo --robot rotary_delta --quick 2>&1)
rc=$?
set -e
[ $rc -eq 3 ] || fail "ROBOCAL_ROBOT_LIBRARY=<missing folder> gave exit $rc, not 3: $msg"
case $msg in *"ROBOCAL_ROBOT_LIBRARY=$work/none"*) ;; *) fail "unclear message: $msg" ;; esac

echo "install_prefix: $prefix (DESTDIR $work/root) holds a working robocal with its robot library"
