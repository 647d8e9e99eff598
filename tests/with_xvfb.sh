#!/usr/bin/env bash
# Runs a command on a virtual X display of its own: Xvfb picks a free display number itself
# (-displayfd), so tests that run in parallel (ctest -j, two checkouts on one machine) never race for
# the same number, as `xvfb-run -a` can (it probes lock files, then starts the server: two callers
# may both probe :99 free, and one of them fails). Usage: with_xvfb.sh COMMAND [ARGS...]
set -euo pipefail
tmp=$(mktemp -d)
trap 'kill "$xvfb" 2>/dev/null || true; wait "$xvfb" 2>/dev/null || true; rm -rf "$tmp"' EXIT
mkfifo "$tmp/display"
Xvfb -displayfd 3 -screen 0 1280x1024x24 -nolisten tcp 3>"$tmp/display" 2>"$tmp/xvfb.log" &
xvfb=$!
# Xvfb writes the number once it accepts connections; EOF without one means it did not start.
read -r number <"$tmp/display" || true
[ -n "${number:-}" ] || { cat "$tmp/xvfb.log" >&2; echo "with_xvfb: Xvfb did not start" >&2; exit 1; }
DISPLAY=":$number" "$@"
