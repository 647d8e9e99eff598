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

# Waits (up to 60 s) until the viewer's log ($out/window/viewer.log) says its three locked views
# show cameras and each of those cameras' first frame arrived; fails otherwise.
wait_locked_views_streaming() {
  local log="$out/window/viewer.log" line ids id ready
  for _ in $(seq 1 600); do
    line=$(grep -o "viewer: locked views: .*" "$log" 2>/dev/null | tail -1 || true)
    ids=${line#viewer: locked views: }
    if [ -n "$line" ] && [[ "$ids" != *"(plan view)"* ]]; then
      ready=1
      IFS=',' read -ra cams <<<"$ids"
      for id in "${cams[@]}"; do
        grep -qF "viewer: first frame from camera '${id# }'" "$log" || { ready=0; break; }
      done
      [ "$ready" = 1 ] && return 0
    fi
    sleep 0.1
  done
  return 1
}
