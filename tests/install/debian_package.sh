#!/usr/bin/env bash
# The Debian package CPack builds from the install rules (cmake/RobocalInstall.cmake): its control
# data names the shared libraries' packages (dpkg-shlibdeps), it holds the program, the robot
# library and the documents under /usr, and the program unpacked from it (dpkg -x, not installed,
# away from the source and build trees) finds its robot library.
# Usage: debian_package.sh <build dir>
set -euo pipefail
build=$(cd "$1" && pwd)
fail() { echo "debian_package: $*" >&2; exit 1; }
for tool in cpack dpkg-deb dpkg-shlibdeps file; do
  command -v "$tool" >/dev/null || fail "$tool not found (bash scripts/bootstrap.sh installs it)"
done

work=$(mktemp -d "${TMPDIR:-/tmp}/robocal_deb.XXXXXX")
trap 'rm -rf "$work"' EXIT
cpack --config "$build/CPackConfig.cmake" -B "$work" >"$work/cpack.log" 2>&1 \
  || { cat "$work/cpack.log" >&2; fail "cpack failed"; }
debs=("$work"/robocal_*.deb)
[ -f "${debs[0]}" ] || fail "cpack made no robocal_*.deb in $work: $(ls "$work")"
deb=${debs[0]}

info=$(dpkg-deb -I "$deb")
depends=$(dpkg-deb -f "$deb" Depends)
# The libraries robocal links shared: each must be a dependency, or the package would install on
# a machine without them.
for lib in libc6 libstdc++6 libceres libopencv-core libapriltag libyaml-cpp libaravis libfcl \
           liburdfdom libreadline libpng16; do
  case $depends in *"$lib"*) ;; *) fail "Depends lacks $lib: $depends" ;; esac
done
case $depends in *-dev*) fail "Depends names a -dev package (a compiler's, not a user's): $depends" ;; esac
[ "$(dpkg-deb -f "$deb" Package)" = robocal ] || fail "package name: $info"
[ "$(dpkg-deb -f "$deb" Architecture)" = "$(dpkg --print-architecture)" ] || fail "architecture: $info"

files=$(dpkg-deb -c "$deb" | awk '{print $NF}' | grep -v '/$')
for f in ./usr/bin/robocal ./usr/share/robocal/robots/rotary_delta.yaml \
         ./usr/share/doc/robocal/README.md; do
  grep -qx "$f" <<<"$files" || fail "$f is not in the package: $files"
done
stray=$(grep -vE '^\./usr/(bin/robocal$|share/robocal/|share/doc/robocal/)' <<<"$files" || true)
[ -z "$stray" ] || fail "files outside /usr/bin/robocal, /usr/share/robocal, /usr/share/doc/robocal: $stray"

dpkg -x "$deb" "$work/root"
mkdir "$work/cwd" && cd "$work/cwd"
unset ROBOCAL_ROBOT_LIBRARY
"$work/root/usr/bin/robocal" version >/dev/null || fail "the packaged robocal does not run"
set +e
msg=$("$work/root/usr/bin/robocal" demo --robot no_such_robot --quick 2>&1)
rc=$?
set -e
[ $rc -eq 3 ] || fail "an unknown robot gave exit $rc, not 3: $msg"
case $msg in
  *"$work/root/usr/share/robocal/robots"*rotary_delta*) ;;
  *) fail "the packaged robocal does not look in its own /usr/share/robocal/robots: $msg" ;;
esac
echo "debian_package: $(basename "$deb"), $(du -k "$deb" | cut -f1) KiB; Depends: $depends"
