#!/usr/bin/env bash
# Issue 7: the viewer window takes real keyboard and mouse input. Runs deploy/demo.sh with a GLFW
# window on a virtual X display (Xvfb) and drives it with xdotool (synthetic X events, the same path
# a user's keyboard and mouse take through the X server):
#   p        writes the snapshot now (the first picture: panel shown, browse view as it starts)
#   h        hides the panel; W held flies the browse view forward; a left drag orbits it
#   Esc      closes the window, which writes the snapshot again and ends the demo
# and checks that the second picture differs from the first where the panel was (the panel is
# hidden) and in the browse view (it moved), that the three camera-locked views did not move, and
# that the viewer closed on Esc (not on a timeout).
set -euo pipefail
root=$1
build=$2
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for tool in Xvfb xdotool; do
  command -v "$tool" >/dev/null || { echo "FAIL: $tool missing (deploy/install-deps.sh installs it)"; exit 1; }
done

cat >"$out/drive.sh" <<'SH'
#!/usr/bin/env bash
# Runs inside the virtual display: waits for the viewer window, then types and drags.
set -uo pipefail
out=$1
source "$2/tests/window_drive_lib.sh"
focus_viewer_window
trap 'give_up "an xdotool step failed"' ERR
# The first picture must show all three locked views with their video: wait for the viewer to say
# its cells are filled and each locked camera's first frame arrived (CI stop 40 took it while one
# cell was still a plan view, which then moved with the browse view).
wait_locked_views_streaming || give_up "the locked views did not fill with live video within 60 s"
xdotool key --delay 50 p                 # snapshot 1
# The PNG is complete once it ends with its IEND chunk.
for _ in $(seq 1 100); do
  tail -c 8 "$out/window/quad.png" 2>/dev/null | grep -q IEND && break
  sleep 0.1
done
cp "$out/window/quad.png" "$out/first.png"
xdotool key --delay 50 h                 # hide the panel
xdotool keydown w; sleep 1.0; xdotool keyup w       # fly forward for a second
xdotool mousemove --window "$win" 300 200 mousedown 1 mousemove --window "$win" 420 230 mouseup 1
sleep 1
xdotool key Escape
echo "drive: done" >"$out/drive.log"
SH
chmod +x "$out/drive.sh"

cat >"$out/session.sh" <<SH
#!/usr/bin/env bash
"$out/drive.sh" "$out" "$root" &
# Last resort: a viewer still open after two minutes is closed (the test then fails on its checks).
( sleep 120; pkill -f -- "--snapshot $out/window/quad.png" ) >/dev/null 2>&1 &
AVE_SKIP_DEPS=1 AVE_SKIP_BUILD=1 AVE_BUILD_DIR="$build" AVE_DEMO_OUT="$out/window" AVE_DEMO_FPS=5 \
  AVE_VIEWER_FRAMES=0 timeout 150 bash "$root/deploy/demo.sh"
SH
chmod +x "$out/session.sh"
"$root/tests/with_xvfb.sh" "$out/session.sh" >"$out/demo.log" 2>&1 ||
  { cat "$out/demo.log"; echo "FAIL: the demo with a window did not end cleanly (Esc not taken?)"; exit 1; }
grep -q "drive: done" "$out/drive.log" 2>/dev/null || { cat "$out/drive.log" 2>/dev/null; echo "FAIL: input driver did not finish"; exit 1; }
test -s "$out/first.png" || { echo "FAIL: 'p' wrote no snapshot"; exit 1; }
test -s "$out/window/quad.png" || { echo "FAIL: closing the window wrote no snapshot"; exit 1; }

python3 - "$out/first.png" "$out/window/quad.png" "$root/tests" <<'PY'
import sys
sys.path.insert(0, sys.argv[3])
from png_read import read_png

def mean_diff(img1, img2, x0, y0, x1, y1):
    (w, h, bpp, r1), (_, _, _, r2) = img1, img2
    total = n = 0
    for y in range(y0, y1, 4):
        for x in range(x0, x1, 4):
            for k in range(3):
                total += abs(r1[y][x * bpp + k] - r2[y][x * bpp + k])
            n += 3
    return total / n

first, last = read_png(sys.argv[1]), read_png(sys.argv[2])
assert first[:2] == last[:2], 'snapshot sizes differ'
w, h = first[:2]
panel = mean_diff(first, last, 20, 40, 400, 280)          # under the panel (top left)
browse = mean_diff(first, last, 440, 20, w // 2 - 10, h // 2 - 10)  # browse view right of the panel
# The three camera-locked views only change by their video and the moving objects.
locked = mean_diff(first, last, w // 2 + 90, h // 2 + 20, w - 90, h - 20)
print(f'mean |difference| in levels: panel area {panel:.1f}, browse view {browse:.1f}, a locked view {locked:.1f}')
assert panel > 12, "'h' did not hide the panel"
assert browse > 12, 'the browse view did not move under W and the drag'
assert locked < browse, 'a camera-locked view changed more than the browse view'
PY
if [ -n "${AVE_TEST_KEEP:-}" ]; then mkdir -p "$AVE_TEST_KEEP" && cp "$out/first.png" "$out/window/quad.png" "$AVE_TEST_KEEP/"; fi
echo "window input: ok"
