#!/usr/bin/env bash
# The main job: installs what is missing, builds, then runs the whole AVE loop on the bundled
# synthetic campus: ave-server on an embedded SQLite store, the three campus cameras and the moving
# backpack camera registered through the admin API, their simulated camera agents (the backpack's
# with its GPS + inertial + vision pose at its full 30 Hz), and a viewer — a window when DISPLAY is
# set, otherwise headless, writing a quad-view PNG — then stops everything cleanly.
# Every channel uses TLS with a site CA made by deploy/make-certs.sh; the sensors also present
# client certificates (mutual TLS) and each streams with its own camera-bound token issued through
# the admin API (the server keeps only the tokens' SHA-256).
#   sudo deploy/demo.sh                 (AVE_SKIP_DEPS=1 skips the package check)
# Output: ${AVE_DEMO_OUT:-build/demo}/quad.png, server.log, viewer.log, agent-*.log, ave.db, certs/, model.json,
# rec/ (the recording, issue 18: replay it with SceneService.Replay)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${AVE_BUILD_DIR:-$root/build}
out=${AVE_DEMO_OUT:-$build/demo}
[ "${AVE_SKIP_DEPS:-0}" = 1 ] || bash "$root/deploy/install-deps.sh"
[ "${AVE_SKIP_BUILD:-0}" = 1 ] || AVE_BUILD_DIR=$build bash "$root/deploy/build.sh"
bin=$build/bin
mkdir -p "$out"
rm -f "$out"/ave.db* "$out"/*.log "$out"/quad.png
rm -rf "$out"/rec

token() { head -c 16 /dev/urandom | od -An -tx1 | tr -d ' \n'; }
export AVE_SENSOR_TOKEN=${AVE_SENSOR_TOKEN:-$(token)}
export AVE_VIEWER_TOKEN=${AVE_VIEWER_TOKEN:-$(token)}
export AVE_ADMIN_TOKEN=${AVE_ADMIN_TOKEN:-$(token)}

certs=$out/certs
# Issue 16: the campus's rotating LiDAR 'hdl' (a tripod on the lawn south-east of the plaza) is a
# fourth sensor: its agent tracks people in the simulated sweeps (sensor_agent/lidar_track) and
# streams their foot tracks and points; the server fuses them with the cameras' objects.
# AVE_DEMO_ROTATING_LIDAR=0 leaves it out.
lidar_demo=${AVE_DEMO_ROTATING_LIDAR:-1}
# Issue 19: the backpack walker's camera streams at its full rate (30 Hz, the scenario's) with the
# pose fused from its GPS, inertial sensor and the video itself (--pose-mode gps-imu-vision).
# AVE_DEMO_BACKPACK=0 leaves it out.
backpack_demo=${AVE_DEMO_BACKPACK:-1}
backpack_fps=${AVE_DEMO_BACKPACK_FPS:-30}
sensors="cam1 cam2 cam3"
[ "$backpack_demo" = 1 ] && sensors="$sensors backpack"
[ "$lidar_demo" = 1 ] && sensors="$sensors hdl"
# shellcheck disable=SC2086
bash "$root/deploy/make-certs.sh" "$certs" $sensors >/dev/null
export AVE_TLS_CA=$certs/ca.pem  # ave-admin, ave-agent and ave-viewer trust the site CA

pids=()
cleanup() {
  local status=$?
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
  exit $status
}
trap cleanup EXIT INT TERM

# Issue 19 (session rate19): the backpack camera's frames pre-rendered once per build folder
# (ave-sim footage; again when ave-sim was rebuilt, or when the file is corrupt or stale) and
# played by its agent at the scenario's times (--sim-footage): its ~33 ms render is the simulator
# standing in for a physical camera, which delivers frames for free. The camera's own JPEG is kept,
# so the pose and the bytes sent are those of the live render. Rendered in the background while the
# model, the server and the avatar are made; the agent waits for it. The path's back-and-forth
# period is 210 s (6,300 frames, ~3.7 CPU minutes: far more than a demo needs or a first demo can
# wait for); the headless demo streams the backpack for 6-13 s, so 10 s are made (300 frames,
# ~7 MB, ~11 CPU seconds; AVE_DEMO_BACKPACK_FOOTAGE_S) and later frames are rendered live.
# AVE_DEMO_BACKPACK_FOOTAGE_S=0: no footage, every frame rendered live.
footage=""
footage_pid=""
if [ "$backpack_demo" = 1 ] && [ "${AVE_DEMO_BACKPACK_FOOTAGE_S:-10}" != 0 ]; then
  footage=$build/demo-footage/backpack-${backpack_fps}fps.avfoot
  mkdir -p "$build/demo-footage"
  (
    # Two demos may share a build folder: one renders, the other waits and finds the file good.
    exec 8>"$build/demo-footage.lock"
    flock 8
    if [ -e "$footage" ] && [ "$bin/ave-sim" -nt "$footage" ]; then rm -f "$footage"; fi
    exec "$bin/ave-sim" footage --scenario campus --camera backpack --fps "$backpack_fps" --threads 2 \
      --seconds "${AVE_DEMO_BACKPACK_FOOTAGE_S:-10}" --out "$footage"
  ) >"$out/footage.out" 2>"$out/footage.log" &
  footage_pid=$!
  pids+=("$footage_pid")
fi

# The static model (issue 4): the simulated airborne LiDAR survey of the campus through ave-model
# (terrain + buildings) into the store; ave-server serves the newest static model in it. A few
# seconds; AVE_DEMO_LIDAR=0 keeps the server's built-in campus mesh instead.
if [ "${AVE_DEMO_LIDAR:-1}" = 1 ]; then
  echo "demo: building the static model from the simulated airborne LiDAR"
  "$bin/ave-sim" airborne-lidar --scenario campus --out "$out/lidar" >/dev/null
  "$bin/ave-model" build --input "$out/lidar/campus.las" --db "$out/ave.db" --quiet >"$out/model.json" 2>"$out/model.log" ||
    { cat "$out/model.log" >&2; echo "demo: ave-model build failed" >&2; exit 1; }
fi

echo "demo: starting ave-server (store $out/ave.db)"
"$bin/ave-server" --listen 127.0.0.1:0 --store "$out/ave.db" \
  --tls-cert "$certs/server.pem" --tls-key "$certs/server.key" --tls-client-ca "$certs/ca.pem" --sensor-client-cert \
  --metrics-listen 127.0.0.1:0 --record-dir "$out/rec" --retention 1d >"$out/server.out" 2>"$out/server.log" &
server_pid=$!
pids+=("$server_pid")
port=""
for _ in $(seq 1 200); do
  # The server's output file is created by the background job, which may not have run yet: a
  # missing file is "no port yet", not an error (under set -e and pipefail it ended the demo at
  # once, silently; seen once in the loaded test runs, issue 14).
  port=$(sed -n 's/^listening on port \([0-9]*\)$/\1/p' "$out/server.out" 2>/dev/null | head -1 || true)
  [ -n "$port" ] && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$out/server.log" >&2; echo "demo: ave-server failed to start" >&2; exit 1; }
  sleep 0.1
done
[ -n "$port" ] || { echo "demo: ave-server did not report its port" >&2; exit 1; }
server=127.0.0.1:$port
echo "demo: server on $server (TLS); registering the campus cameras"
if [ "$backpack_demo" = 1 ]; then
  "$bin/ave-admin" --server "$server" import-campus --moving
else
  "$bin/ave-admin" --server "$server" import-campus
fi

# Issue 17: the people walk as 4D avatars reconstructed in the simulated 13+1-camera studio:
# ave-sim studio renders it, ave-studio segments (shadows removed), carves the visual hull, meshes,
# textures and finds the walk cycle (walk.avseq), ave-admin put-avatar stores it; the server then
# gives every tracked person an avatar walking its track. Made once per build folder (about 15 s),
# and again when ave-sim or ave-studio was rebuilt since (a new studio actor or reconstruction);
# AVE_DEMO_AVATARS=0 leaves people as boxes and cylinders.
if [ "${AVE_DEMO_AVATARS:-1}" = 1 ]; then
  avatar_dir=$build/demo-avatar
  # Two demos may share a build folder (the demo and window tests run at once): the first makes the
  # sequence in a folder of its own and moves it into place under a lock; the other waits for it.
  exec 9>"$build/demo-avatar.lock"
  flock 9
  if [ ! -s "$avatar_dir/walk.avseq" ] || [ "$bin/ave-sim" -nt "$avatar_dir/walk.avseq" ] ||
     [ "$bin/ave-studio" -nt "$avatar_dir/walk.avseq" ]; then
    echo "demo: reconstructing the walking avatar in the simulated studio (once per build)"
    studio_tmp=$(mktemp -d "$build/demo-avatar.XXXXXX")
    "$bin/ave-sim" studio --scenario studio --out "$studio_tmp/studio" >/dev/null
    "$bin/ave-studio" --input "$studio_tmp/studio" --out "$studio_tmp/out" --voxel-mm 20 --name studio-walk \
      2>"$out/studio.log" || { cat "$out/studio.log" >&2; rm -rf "$studio_tmp"; echo "demo: ave-studio failed" >&2; exit 1; }
    rm -rf "$avatar_dir"
    mv "$studio_tmp/out" "$avatar_dir"
    rm -rf "$studio_tmp"
  fi
  flock -u 9
  exec 9>&-
  "$bin/ave-admin" --server "$server" put-avatar --file "$avatar_dir/walk.avseq" --name studio-walk >/dev/null
  echo "demo: avatar sequence studio-walk stored; tracked people walk as avatars"
fi

for cam in cam1 cam2 cam3; do
  # A token bound to this camera only (printed once by the server, kept here in memory).
  cam_token=$("$bin/ave-admin" --server "$server" issue-token --role sensor --camera "$cam" --label "demo $cam" 2>/dev/null)
  "$bin/ave-agent" --server "$server" --camera "$cam" --source "sim:campus#$cam" --fps "${AVE_DEMO_FPS:-10}" --detect \
    --token "$cam_token" --tls-cert "$certs/sensor-$cam.pem" --tls-key "$certs/sensor-$cam.key" \
    >"$out/agent-$cam.out" 2>"$out/agent-$cam.log" &
  pids+=("$!")
done
echo "demo: 3 simulated camera agents streaming, detecting and tracking moving objects"
if [ "$backpack_demo" = 1 ]; then
  bp_token=$("$bin/ave-admin" --server "$server" issue-token --role sensor --camera backpack --label "demo backpack" 2>/dev/null)
  footage_args=()
  if [ -n "$footage_pid" ]; then
    if wait "$footage_pid"; then
      footage_args=(--sim-footage "$footage")
      # A corrupt or stale file was re-rendered: say so (the line names the file and why).
      if [ -s "$out/footage.log" ]; then sed 's/^/demo: /' "$out/footage.log"; fi
      echo "demo: the backpack camera's footage: $(cat "$out/footage.out")"
    else
      echo "demo: ave-sim footage failed ($(tail -1 "$out/footage.log")); the backpack's frames are rendered live" >&2
    fi
  fi
  "$bin/ave-agent" --server "$server" --camera backpack --source "sim:campus#backpack" --fps "$backpack_fps" \
    --pose-mode gps-imu-vision ${footage_args[@]+"${footage_args[@]}"} --token "$bp_token" --tls-cert "$certs/sensor-backpack.pem" --tls-key "$certs/sensor-backpack.key" \
    >"$out/agent-backpack.out" 2>"$out/agent-backpack.log" &
  pids+=("$!")
  echo "demo: the backpack camera's agent streaming at $backpack_fps Hz with its GPS + inertial + vision pose"
fi
if [ "$lidar_demo" = 1 ]; then
  # Registered like a camera (audited), with its own sensor-bound token. The position is the
  # scenario's (12, -14) at 2 m above the ground there; the simulated sweeps carry their own pose.
  "$bin/ave-admin" --server "$server" add-lidar --id hdl --name "Plaza LiDAR" --position 12,-14,2.1 --source "sim:campus#hdl"
  hdl_token=$("$bin/ave-admin" --server "$server" issue-token --role sensor --camera hdl --label "demo hdl" 2>/dev/null)
  "$bin/ave-agent" --server "$server" --camera hdl --source "sim:campus#hdl" \
    --token "$hdl_token" --tls-cert "$certs/sensor-hdl.pem" --tls-key "$certs/sensor-hdl.key" \
    >"$out/agent-hdl.out" 2>"$out/agent-hdl.log" &
  pids+=("$!")
  echo "demo: the rotating LiDAR agent (hdl) streaming foot tracks and points"
fi

metrics_port=$(sed -n 's/^metrics on port \([0-9]*\)$/\1/p' "$out/server.out" | head -1)
if [ -n "$metrics_port" ]; then
  # The LiDAR agent first builds its simulated sensor and the backpack's agent first simulates its
  # GPS and inertial history: wait (up to a minute) until the server has every sensor's stream open
  # and, with the LiDAR, its first sweep, so the viewer's first picture has them all in it.
  sensors=$((3 + backpack_demo + lidar_demo))
  python3 - "http://127.0.0.1:$metrics_port/metrics" "$sensors" "$lidar_demo" <<'PY' ||
import re, sys, time, urllib.request
want_sensors, want_sweep = int(sys.argv[2]), sys.argv[3] == "1"
def metric(text, name):
    m = re.search(r"^" + name + r" (\d+)$", text, re.M)
    return int(m.group(1)) if m else 0
for _ in range(600):
    text = urllib.request.urlopen(sys.argv[1], timeout=5).read().decode()
    if metric(text, "ave_sensors_connected") >= want_sensors and (not want_sweep or metric(text, "ave_lidar_sweeps_in_total") > 0):
        sys.exit(0)
    time.sleep(0.1)
sys.exit(1)
PY
    echo "demo: not every sensor is streaming yet (or the LiDAR has sent no sweep); going on"
fi

if [ -n "${DISPLAY:-}" ] && [ "${AVE_DEMO_HEADLESS:-0}" != 1 ]; then
  echo "demo: opening the viewer window (close it to stop)"
  # Waits for the first frames so the window opens on live video.
  sleep 2
  # AVE_VIEWER_ARGS: more ave-viewer flags for the window (e.g. --replay-rate 0.25), split on spaces.
  # shellcheck disable=SC2086
  "$bin/ave-viewer" --server "$server" --snapshot "$out/quad.png" --frames "${AVE_VIEWER_FRAMES:-0}" ${AVE_VIEWER_ARGS:-} 2>"$out/viewer.log" ||
    { tail -5 "$out/viewer.log" >&2; echo "demo: ave-viewer failed" >&2; exit 1; }
else
  echo "demo: no DISPLAY, rendering headless"
  # Tracks become objects only after persisting 1 s (issue 6): let them form before the snapshot.
  sleep "${AVE_DEMO_WARMUP_S:-4}"
  "$bin/ave-viewer" --server "$server" --headless --snapshot "$out/quad.png" --wait-cameras 3 --timeout 60 2>"$out/viewer.log" ||
    { tail -5 "$out/viewer.log" >&2; echo "demo: ave-viewer failed" >&2; exit 1; }
fi
echo "demo: quad view written to $out/quad.png"
"$bin/ave-admin" --server "$server" list >"$out/cameras.json"
if [ -n "$metrics_port" ]; then
  python3 -c "import sys, urllib.request; sys.stdout.write(urllib.request.urlopen(sys.argv[1], timeout=5).read().decode())" \
    "http://127.0.0.1:$metrics_port/metrics" >"$out/metrics.txt" || true
fi
echo "demo: stopping"
