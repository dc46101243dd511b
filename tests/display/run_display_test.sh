#!/bin/sh
# ctest entry (label `display`): the participant display under Xvfb against
# `manip_rt --backend sim` on a live LCM bus.
# usage: run_display_test.sh PYTHON MANIP_RT
# LCM multicast on loopback needs a multicast route; the test makes one in a
# private network namespace so the host's routes are never touched
# (docs/display.md, /work/shared/notes/platform-facts.md). Exit 77 (skipped)
# only when Xvfb or an unprivileged-to-us network namespace is unavailable.
set -eu
py="$1"; rt="$2"
here="$(cd "$(dirname "$0")" && pwd)"
if ! command -v xvfb-run >/dev/null 2>&1 || ! command -v Xvfb >/dev/null 2>&1; then
  echo "SKIP: xvfb-run/Xvfb not installed (scripts/setup.sh installs xvfb)"; exit 77
fi
if ! command -v unshare >/dev/null 2>&1 || ! unshare -n true 2>/dev/null; then
  echo "SKIP: cannot create a private network namespace (unshare -n needs root or CAP_SYS_ADMIN)"; exit 77
fi
exec unshare -n sh -c '
  ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo || exit 1
  exec xvfb-run -a -s "-screen 0 1024x768x24 -nolisten tcp" "$0" "$@"' \
  "$py" "$here/display_test.py" "$rt"
