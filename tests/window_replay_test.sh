#!/usr/bin/env bash
# Issue 18: an operator scrubs back in the viewer window. Runs deploy/demo.sh (the server records
# into rec/) with a GLFW window on a virtual X display (Xvfb) and drives it with xdotool, as
# tests/window_input_test.sh does:
#   r        opens the panel's Replay section (the viewer logs where its time line and "live" are)
#   a left drag on the time line from its right end ("now") to its left end, released there: a seek
#            back (to the earliest recorded moment, once the recording is 20 s long)
#   a click on "pause" as soon as the replay shows its first recorded moment, then p: a snapshot of
#            the paused replay (the window's replay rate is 0.25x, so the pause lands within seconds
#            of recorded time of the seek however slow the machine is)
#   a click on "live", then p: a snapshot back on live; Esc closes the window
# and checks, from what the viewer and the server write (not from time): the viewer logged the seek
# from the time line to a moment at least 18 s before the drag and then showed recorded time from
# it; the server audited that Replay request by the viewer's token with the same start; the pause
# held a recorded moment after the seek; "live" (the button, not the replay running out) took the
# viewer back to live; the replay snapshot's time line has the yellow replay playhead and no red live
# one, the live snapshot the red one at the right end; the replay snapshot (paused near the
# recording's first moment) shows at most a quarter of live's object paths.
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
# Runs inside the virtual display: waits for the viewer window and its log lines, then types,
# drags and clicks. Every wait is for an event; the loop bounds only guard against a hang.
set -uo pipefail
out=$1
source "$2/tests/window_drive_lib.sh"
log=$out/window/viewer.log
# wait_for REGEX TENTHS: until viewer.log has a line matching REGEX (extended); prints the last one.
wait_for() {
  local line
  for _ in $(seq 1 "$2"); do
    line=$(grep -E -- "$1" "$log" 2>/dev/null | tail -1)
    [ -n "$line" ] && { echo "$line"; return 0; }
    sleep 0.1
  done
  return 1
}
snapshots() { grep -c -- "viewer: wrote $out/window/quad.png" "$log" 2>/dev/null || true; }
# snapshot NAME: 'p', then waits for the viewer's "wrote" line and keeps the picture and the layout.
snapshot() {
  local before
  before=$(snapshots)
  xdotool key --delay 50 p
  for _ in $(seq 1 200); do [ "$(snapshots)" -gt "$before" ] && break; sleep 0.1; done
  [ "$(snapshots)" -gt "$before" ] || give_up "'p' wrote no snapshot ($1)"
  cp "$out/window/quad.png" "$out/$1.png"
  grep 'viewer: replay time line at' "$log" | tail -1 >"$out/$1.layout"
}
# click_button NAME: a left click in the middle of the panel's "NAME" button, where the viewer's
# last layout line says it is.
click_button() {
  local layout x y w h
  layout=$(grep 'viewer: replay time line at' "$log" | tail -1)
  read -r x y w h < <(echo "$layout" | sed -n "s/.*$1 button at x \\([0-9-]*\\) y \\([0-9-]*\\) w \\([0-9]*\\) h \\([0-9]*\\) px.*/\\1 \\2 \\3 \\4/p")
  [ -n "${h:-}" ] || give_up "unreadable layout line for '$1': $layout"
  xdotool mousemove --window "$win" $((x + w / 2)) $((y + h / 2))
  sleep 0.3
  xdotool click 1
}
focus_viewer_window
trap 'give_up "an xdotool step failed"' ERR

rec=$(wait_for 'viewer: the server records [1-9][0-9]* cameras, from [1-9]' 600) ||
  give_up "the viewer saw no recording on the server"
start_ns=$(echo "$rec" | sed -n 's/.* from \([0-9]*\) ns.*/\1/p')
xdotool key --delay 50 r
layout=$(wait_for 'viewer: replay time line at' 300) || give_up "'r' opened no Replay section"
# The past to scrub back into: a recording at least 20 s long (a replay from its start then runs
# for 20 s or more at 1x, time for the snapshot and the click on "live" before it catches up,
# even on a loaded machine).
for _ in $(seq 1 600); do
  [ "$(date +%s%N)" -gt $((start_ns + 20000000000)) ] && break
  sleep 0.1
done
layout=$(grep 'viewer: replay time line at' "$log" | tail -1)
read -r x y w h < <(echo "$layout" | sed -n 's/.*time line at x \([0-9-]*\) y \([0-9-]*\) w \([0-9]*\) h \([0-9]*\) px.*/\1 \2 \3 \4/p')
[ -n "${h:-}" ] || give_up "unreadable layout line: $layout"
mid=$((y + h / 2))
date +%s%N >"$out/drag_ns"
# Press on "now" (the right end), drag to the left end in steps, release there. The pauses let the
# viewer draw frames between the steps (the time line seeks on release).
xdotool mousemove --window "$win" $((x + w - 3)) "$mid"
sleep 0.3
xdotool mousedown 1
sleep 0.3
for f in 75 50 25 0; do
  xdotool mousemove --window "$win" $((x + 2 + (w - 5) * f / 100)) "$mid"
  sleep 0.2
done
sleep 0.3
xdotool mouseup 1
wait_for 'viewer: (replay from .*\(time line\)|live \()' 300 >/dev/null || give_up "the drag on the time line did nothing"
wait_for 'viewer: replaying recorded time' 300 >/dev/null || give_up "the replay showed no recorded moment"
# Pause where the replay is, so the snapshot shows a moment near the seek however late 'p' lands.
click_button pause
wait_for 'viewer: paused at recorded time' 300 >/dev/null || give_up "the click on 'pause' did nothing"
snapshot replay
click_button live
wait_for 'viewer: live \(' 300 >/dev/null || give_up "the click on 'live' did nothing"
# Off the panel before the last picture: no hover highlight or tooltip over the time line.
xdotool mousemove --window "$win" 900 700
sleep 0.3
snapshot live
xdotool key Escape
echo "drive: done" >"$out/drive.log"
SH
chmod +x "$out/drive.sh"

cat >"$out/session.sh" <<SH
#!/usr/bin/env bash
"$out/drive.sh" "$out" "$root" &
# Last resort: a viewer still open after three minutes is closed (the test then fails on its checks).
( sleep 180; pkill -f -- "--snapshot $out/window/quad.png" ) >/dev/null 2>&1 &
AVE_SKIP_DEPS=1 AVE_SKIP_BUILD=1 AVE_BUILD_DIR="$build" AVE_DEMO_OUT="$out/window" AVE_DEMO_FPS=5 \
  AVE_VIEWER_FRAMES=0 AVE_VIEWER_ARGS="--replay-rate 0.25" timeout 210 bash "$root/deploy/demo.sh"
SH
chmod +x "$out/session.sh"
"$root/tests/with_xvfb.sh" "$out/session.sh" >"$out/demo.log" 2>&1 ||
  { cat "$out/demo.log" "$out/drive.log" 2>/dev/null; tail -20 "$out/window/viewer.log" 2>/dev/null
    echo "FAIL: the demo with a window did not end cleanly (Esc not taken?)"; exit 1; }
grep -q "drive: done" "$out/drive.log" 2>/dev/null ||
  { cat "$out/drive.log" 2>/dev/null; tail -20 "$out/window/viewer.log"; echo "FAIL: input driver did not finish"; exit 1; }

if [ -n "${AVE_TEST_KEEP:-}" ]; then mkdir -p "$AVE_TEST_KEEP" && cp "$out/window/ave.db" "$out"/{replay,live}.png "$out"/*.layout "$out/window/viewer.log" "$AVE_TEST_KEEP/"; fi
python3 - "$out" "$root/tests" <<'PY'
import json, re, sqlite3, sys
out = sys.argv[1]
sys.path.insert(0, sys.argv[2])
from png_read import read_png
log = open(f'{out}/window/viewer.log').read()
drag_ns = int(open(f'{out}/drag_ns').read())
seek = re.search(r'viewer: replay from (\d+) ns \(([\d.]+) s before now\) to (\d+) ns at \S+ \(time line\)', log)
assert seek, 'the viewer logged no seek from the time line:\n' + log[-3000:]
from_ns, to_ns = int(seek.group(1)), int(seek.group(3))
recorded_from = int(re.search(r'viewer: the server records \d+ cameras, from (\d+) ns', log).group(1))
print(f'seek: to {(drag_ns - from_ns) / 1e9:.1f} s before the drag (the recording began '
      f'{(drag_ns - recorded_from) / 1e9:.1f} s before it)')
assert from_ns <= drag_ns - 18e9, 'the drag to the left end did not seek at least 18 s back'
assert from_ns >= recorded_from - 1e9, 'the seek went before the recording'
after = log[seek.end():]
shown = re.search(r'viewer: replaying recorded time (\d+) ns', after)
assert shown, 'no recorded moment shown after the seek'
shown_ns = int(shown.group(1))
assert from_ns <= shown_ns < from_ns + 10e9, f'the first moment shown ({shown_ns}) is not the one sought ({from_ns})'
paused = re.search(r'viewer: paused at recorded time (\d+) ns', after)
assert paused, 'no pause logged after the seek'
paused_ns = int(paused.group(1))
print(f'pause: {(paused_ns - from_ns) / 1e9:.1f} s of recorded time after the seek')
assert from_ns <= paused_ns, f'the pause ({paused_ns}) is before the seek ({from_ns})'
live = re.search(r'viewer: live \(([^)]*)\)', after)
assert live and live.group(1) == 'live button', f'back to live by {live.group(1) if live else "nothing"}, not the live button'

db = sqlite3.connect(f'file:{out}/window/ave.db?mode=ro', uri=True)
rows = db.execute("SELECT actor, after_json FROM audit WHERE action = 'Replay'").fetchall()
audited = [a for a, j in rows if json.loads(j)['from_ns'] == from_ns and json.loads(j)['to_ns'] == to_ns]
assert audited, f'the server audited no Replay from {from_ns} to {to_ns}: {rows}'
assert all(a.startswith('viewer:') for a in audited), f'replay audited for {audited}, not the viewer token'
print(f'audit: {len(audited)} Replay row(s) for the seek, actor {audited[0].split("@")[0]}')

def count(img, rect, rgb, tol=40):
    w, h, bpp, rows = img
    x0, y0, rw, rh = rect
    n = 0
    for y in range(max(0, y0), min(h, y0 + rh)):
        for x in range(max(0, x0), min(w, x0 + rw)):
            if all(abs(rows[y][x * bpp + k] - rgb[k]) <= tol for k in range(3)):
                n += 1
    return n

def rect_of(name):
    line = open(f'{out}/{name}.layout').read()
    m = re.search(r'time line at x (-?\d+) y (-?\d+) w (\d+) h (\d+) px', line)
    return tuple(int(v) for v in m.groups())

YELLOW, RED = (250, 210, 40), (235, 60, 50)
replay, live_img = read_png(f'{out}/replay.png'), read_png(f'{out}/live.png')
r_rect, l_rect = rect_of('replay'), rect_of('live')
r_yellow, r_red = count(replay, r_rect, YELLOW), count(replay, r_rect, RED)
l_yellow = count(live_img, l_rect, YELLOW)
x, y, w, h = l_rect
l_red_right = count(live_img, (x + w - 6, y, 8, h), RED)
print(f'time line ({h} px high) pixels: replay snapshot {r_yellow} yellow / {r_red} red, live snapshot {l_yellow} yellow / '
      f'{l_red_right} red at the right end')
# The playhead is a 2 px line across the time line's height h, its edges blended: at least h / 2
# pixels of its colour (about h seen).
assert r_yellow >= h // 2, 'the replay snapshot has no replay playhead on the time line'
assert r_red < h // 2, 'the replay snapshot still has the live playhead'
assert l_yellow < h // 2, 'the live snapshot still has the replay playhead'
assert l_red_right >= h // 2, 'the live snapshot has no live playhead at the right end'

# The past looks different: the replay shows the recording's first moment, when the trackers had
# no paths yet; live, the demo's people and cars trail orange paths across the views.
def path_pixels(img):
    w, h, bpp, rows = img
    return sum(1 for y in range(0, h, 2) for x in range(0, w, 2)
               if abs(rows[y][x * bpp] - 255) <= 30 and abs(rows[y][x * bpp + 1] - 120) <= 40 and rows[y][x * bpp + 2] <= 80)
r_paths, l_paths = path_pixels(replay), path_pixels(live_img)
# Where the replay playhead stood in the replay snapshot (0 = the time line's left end, the
# recording's start; 1 = now): how far the replay had played when 'p' was taken.
def playhead_fraction(img, rect):
    w, h, bpp, rows = img
    x0, y0, rw, rh = rect
    xs = [x for y in range(max(0, y0), min(h, y0 + rh)) for x in range(max(0, x0), min(w, x0 + rw))
          if all(abs(rows[y][x * bpp + k] - YELLOW[k]) <= 40 for k in range(3))]
    return (sum(xs) / len(xs) - x0) / max(1, rw) if xs else float('nan')
print(f'object path pixels (every 2nd row and column): replay snapshot {r_paths}, live snapshot {l_paths}; '
      f'replay playhead at {playhead_fraction(replay, r_rect):.2f} of the time line')
assert l_paths >= 50, 'the live snapshot shows no object paths'
assert r_paths * 4 <= l_paths, 'the replay snapshot shows as many object paths as live: not the recording\'s start'
PY
echo "window replay: ok"
