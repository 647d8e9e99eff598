#!/usr/bin/env bash
# Runs a command on a virtual X display of its own. Xvfb picks a free display number itself
# (-displayfd), and starts are serialised under a lock until the new display answers a client:
# two Xvfb starting at the same moment could otherwise both go for the same number (seen under
# ctest -j2: both wrote ":0", and neither test could open it), as `xvfb-run -a` also can.
# Usage: with_xvfb.sh COMMAND [ARGS...]
set -euo pipefail
tmp=$(mktemp -d)
xvfb=""
trap '[ -n "$xvfb" ] && { kill "$xvfb" 2>/dev/null || true; wait "$xvfb" 2>/dev/null || true; }; rm -rf "$tmp"' EXIT
exec 9>"${TMPDIR:-/tmp}/.ave-with-xvfb.lock"
flock 9
mkfifo "$tmp/display"
# -noreset: by default an X server resets when its last client disconnects, and a client that
# connects during the reset is refused ("Failed to open display"). The readiness probe below and
# the window tests' xdotool polling disconnect again and again, so the viewer's own connect could
# land in a reset (seen once in 23 loaded suite runs; 46 of 1,500 connect/disconnect cycles failed
# without -noreset, 0 of 2,100 with it).
Xvfb -displayfd 3 -screen 0 1280x1024x24 -nolisten tcp -noreset 3>"$tmp/display" 2>"$tmp/xvfb.log" 9>&- &
xvfb=$!
read -r number <"$tmp/display" || true
[ -n "${number:-}" ] || { cat "$tmp/xvfb.log" >&2; echo "with_xvfb: Xvfb did not start" >&2; exit 1; }
# Ready means a client can connect: wait for that (or for the server's death), not for a time.
until DISPLAY=":$number" xdotool getdisplaygeometry >/dev/null 2>&1; do
  kill -0 "$xvfb" 2>/dev/null || { cat "$tmp/xvfb.log" >&2; echo "with_xvfb: Xvfb :$number exited" >&2; exit 1; }
  sleep 0.05
done
flock -u 9
exec 9>&-
DISPLAY=":$number" "$@"
