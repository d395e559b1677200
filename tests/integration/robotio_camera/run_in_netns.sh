#!/usr/bin/env bash
# Runs a camera test binary inside its own network namespace whose loopback has 127.0.0.1 and
# 127.0.0.2, so two fake GigE Vision cameras each get an address (on one address they collide)
# and no other process on the machine (another checkout's tests) shares their GVCP ports.
# Where no namespace can be created (not root, no `ip`, a container without CAP_SYS_ADMIN), the
# binary runs in the current namespace with ROBOCAL_NETNS_UNAVAILABLE set to the reason; the
# tests that need two addresses then skip with that reason.
# Usage: run_in_netns.sh BINARY [gtest arguments...]
set -uo pipefail
binary=$1
shift
ns="robocal-cam-$$-$RANDOM"
reason=""
if ! command -v ip >/dev/null 2>&1; then
  reason="the 'ip' command (iproute2) is not installed"
elif [ "$(id -u)" -ne 0 ]; then
  reason="creating a network namespace needs root (running as uid $(id -u))"
elif ! err=$(ip netns add "$ns" 2>&1); then
  reason="ip netns add failed: $err"
fi
if [ -n "$reason" ]; then
  echo "run_in_netns: no test network namespace: $reason" >&2
  ROBOCAL_NETNS_UNAVAILABLE="$reason" exec "$binary" "$@"
fi
trap 'ip netns delete "$ns" 2>/dev/null' EXIT
ip -n "$ns" link set lo up
ip -n "$ns" addr add 127.0.0.2/32 dev lo
ip netns exec "$ns" "$binary" "$@"
