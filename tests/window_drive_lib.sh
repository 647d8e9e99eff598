# Sourced by the window tests' input drivers (tests/window_*_test.sh), inside the virtual display.
# Needs $out (the test's folder; the viewer's snapshot is $out/window/quad.png).

# Whatever goes wrong, the viewer must not be left waiting for an Esc that never comes.
give_up() { echo "drive: $1" >"$out/drive.log"; pkill -f -- "--snapshot $out/window/quad.png"; exit 1; }

# Waits for the viewer's window to be mapped (only a viewable window can take the input focus),
# focuses it and sets $win; gives up after 60 s / 10 s.
focus_viewer_window() {
  win=""
  for _ in $(seq 1 600); do
    win=$(xdotool search --onlyvisible --name '^AVE' 2>/dev/null | head -1)
    [ -n "$win" ] && break
    sleep 0.1
  done
  [ -n "$win" ] || give_up "no viewer window within 60 s"
  local focused=0
  for _ in $(seq 1 50); do
    if xdotool windowfocus --sync "$win" 2>/dev/null; then focused=1; break; fi
    sleep 0.2
  done
  [ "$focused" = 1 ] || give_up "could not focus the viewer window"
}
