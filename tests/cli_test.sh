#!/usr/bin/env bash
# Every executable answers --help (exit 0) and refuses a bad flag with a non-zero exit and a
# one-line reason on stderr.
set -u
bin=$1
fail=0
# Each executable with its required arguments, so the bad flag is the only fault.
declare -A args=([ave-server]="" [ave-agent]="--camera c --source sim:campus#cam1" [ave-viewer]="" [ave-admin]="list" [ave-sim]="camera --scenario minimal --camera c --out /tmp/ave_cli_sim" [ave-bench]="sim" [ave-loadgen]="" [ave-model]="classify --input /x.las --out /tmp/ave_cli_y.las" [ave-calibrate]="--images /x/*.jpg --board 9x6 --square 0.025 --out /tmp/ave_cli_k.yaml")
for exe in ave-server ave-agent ave-viewer ave-admin ave-sim ave-bench ave-loadgen ave-model ave-calibrate; do
  if ! "$bin/$exe" --help >/tmp/ave_cli_help.$$ 2>&1; then echo "FAIL $exe --help exited non-zero"; fail=1; fi
  grep -q -- "--" /tmp/ave_cli_help.$$ || { echo "FAIL $exe --help printed no options"; fail=1; }
  # shellcheck disable=SC2086
  "$bin/$exe" ${args[$exe]} --no-such-flag >/tmp/ave_cli_out.$$ 2>/tmp/ave_cli_err.$$
  rc=$?
  lines=$(wc -l </tmp/ave_cli_err.$$)
  if [ "$rc" -eq 0 ]; then echo "FAIL $exe accepted --no-such-flag"; fail=1; fi
  if [ "$lines" -ne 1 ]; then echo "FAIL $exe printed $lines lines on stderr for a bad flag:"; cat /tmp/ave_cli_err.$$; fail=1; fi
  grep -q "no-such-flag" /tmp/ave_cli_err.$$ || { echo "FAIL $exe did not name the bad flag"; fail=1; }
  [ "$fail" = 0 ] && echo "ok   $exe: --help, bad flag -> exit $rc: $(cat /tmp/ave_cli_err.$$)"
done
rm -f /tmp/ave_cli_*.$$
# Semantic errors also name what is wrong.
out=$("$bin/ave-agent" --camera c --source ftp://x 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "unknown scheme" <<<"$out"; then echo "FAIL ave-agent bad source: rc=$rc $out"; fail=1; fi
out=$("$bin/ave-server" --listen 127.0.0.1:0 --store /nonexistent-dir/x.db --admin-token t 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "/nonexistent-dir/x.db" <<<"$out"; then echo "FAIL ave-server bad store: rc=$rc $out"; fail=1; fi
# Issue 14: no bearer token in plaintext off loopback unless --insecure-plaintext says so. The
# server refuses a wildcard address without TLS in one line naming both ways out; each client
# refuses a plaintext non-loopback target, naming it, before it connects.
"$bin/ave-server" --listen 0.0.0.0:0 --store /tmp/ave_cli_plain.$$.db --admin-token t >/dev/null 2>/tmp/ave_cli_err.$$; rc=$?
if [ $rc -eq 0 ] || [ "$(wc -l </tmp/ave_cli_err.$$)" -ne 1 ] || ! grep -q -- "--insecure-plaintext" /tmp/ave_cli_err.$$ ||
   ! grep -q -- "--tls-cert/--tls-key" /tmp/ave_cli_err.$$ || [ -e /tmp/ave_cli_plain.$$.db ]; then
  echo "FAIL ave-server plaintext on 0.0.0.0: rc=$rc $(cat /tmp/ave_cli_err.$$)"; fail=1
fi
out=$("$bin/ave-admin" --server 10.255.1.2:50051 --token t list 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "10.255.1.2:50051" <<<"$out" || ! grep -q -- "--insecure-plaintext" <<<"$out"; then
  echo "FAIL ave-admin plaintext to a non-loopback server: rc=$rc $out"; fail=1
fi
out=$("$bin/ave-agent" --server 10.255.1.2:50051 --camera c --source sim:campus#cam1 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "10.255.1.2:50051" <<<"$out" || ! grep -q -- "--insecure-plaintext" <<<"$out"; then
  echo "FAIL ave-agent plaintext to a non-loopback server: rc=$rc $out"; fail=1
fi
out=$("$bin/ave-viewer" --server 10.255.1.2:50051 --headless --snapshot /tmp/ave_cli_v.png 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "10.255.1.2:50051" <<<"$out" || ! grep -q -- "--insecure-plaintext" <<<"$out"; then
  echo "FAIL ave-viewer plaintext to a non-loopback server: rc=$rc $out"; fail=1
fi
out=$("$bin/ave-loadgen" --server 10.255.1.2:50051 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "10.255.1.2:50051" <<<"$out"; then echo "FAIL ave-loadgen non-loopback target: rc=$rc $out"; fail=1; fi
rm -f /tmp/ave_cli_err.$$ /tmp/ave_cli_plain.$$.db
out=$("$bin/ave-viewer" --headless 2>&1); rc=$?
if [ $rc -ne 2 ] || ! grep -q -- "--snapshot" <<<"$out"; then echo "FAIL ave-viewer --headless without output: rc=$rc $out"; fail=1; fi
out=$("$bin/ave-model" classify --input /nonexistent-dir/in.las --out /tmp/ave_cli_out.las 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "/nonexistent-dir/in.las" <<<"$out"; then echo "FAIL ave-model bad input: rc=$rc $out"; fail=1; fi
out=$("$bin/ave-calibrate" --images '/nonexistent-dir/*.jpg' --board 9x6 --square 0.025 --out /tmp/ave_cli_k.yaml 2>&1); rc=$?
if [ $rc -eq 0 ] || ! grep -q "nonexistent-dir" <<<"$out"; then echo "FAIL ave-calibrate no images: rc=$rc $out"; fail=1; fi

# Issue 14: every path flag (and the numeric flags whose bad values could do harm) is refused with
# an error naming the file or flag; none crashes (exit >= 128) or hangs (30 s). docs/RELIABILITY.md,
# "Input surfaces", points at these lines.
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
missing=$tmp/missing                      # a folder that does not exist
printf 'not what you think\n' >"$tmp/junk"   # a file of the wrong kind (also a "folder" nothing can be made in)
cp "$tmp/junk" "$tmp/junk.pcd"; cp "$tmp/junk" "$tmp/junk.yaml"; cp "$tmp/junk" "$tmp/junk.pem"
# expect_error NAME WANT CMD...: CMD exits non-zero (not by a signal, not by the timeout) and says WANT.
expect_error() {
  local name=$1 want=$2 out rc
  shift 2
  out=$(timeout 30 "$@" 2>&1 </dev/null); rc=$?
  if [ $rc -eq 0 ] || [ $rc -eq 124 ] || [ $rc -ge 128 ] || ! grep -qF -- "$want" <<<"$out"; then
    echo "FAIL $name: exit $rc, wanted '$want' in: $(tail -2 <<<"$out")"; fail=1
  fi
}
S=("$bin/ave-server" --listen 127.0.0.1:0 --store "$tmp/s.db" --admin-token t)
expect_error "server --tls-cert missing" "$missing/cert.pem" "${S[@]}" --tls-cert "$missing/cert.pem" --tls-key "$missing/key.pem"
expect_error "server --tls-cert not PEM" "$tmp/junk.pem': not a PEM file" "${S[@]}" --tls-cert "$tmp/junk.pem" --tls-key "$tmp/junk.pem"
expect_error "server --tls-client-ca without cert" "need --tls-cert" "${S[@]}" --tls-client-ca "$missing/ca.pem"
expect_error "server --store not SQLite" "$tmp/junk" "$bin/ave-server" --listen 127.0.0.1:0 --store "$tmp/junk" --admin-token t
expect_error "server --campus-grid 0" "campus_grid_m" "${S[@]}" --campus-grid 0
expect_error "server --max-ingest-fps -1" "flow budgets" "${S[@]}" --max-ingest-fps -1
expect_error "server --max-frame-mb nan" "max_jpeg_bytes" "${S[@]}" --max-frame-mb nan
expect_error "server --listen port out of range" "port '70000' is not in 0..65535" "$bin/ave-server" --listen 127.0.0.1:70000 --store "$tmp/s3.db" --admin-token t
expect_error "server --listen host not resolving" "host 'no-such-host.invalid' does not resolve" "$bin/ave-server" --listen no-such-host.invalid:0 --insecure-plaintext --store "$tmp/s3.db" --admin-token t
expect_error "server --metrics-listen bad" "metrics address 'nope'" "${S[@]}" --metrics-listen nope
expect_error "server no token at all" "no token" env -u AVE_ADMIN_TOKEN -u AVE_SENSOR_TOKEN -u AVE_VIEWER_TOKEN "$bin/ave-server" --listen 127.0.0.1:0 --store "$tmp/s2.db"
expect_error "server env AVE_TLS_CERT missing" "$missing/env.pem" env AVE_TLS_CERT="$missing/env.pem" AVE_TLS_KEY="$missing/k.pem" "${S[@]}"
A0=("$bin/ave-agent" --camera c --server 127.0.0.1:1 --token x)   # no server listens on port 1
A=("${A0[@]}" --source "sim:minimal#cam1")
expect_error "agent --intrinsics missing" "$missing/k.yaml" "${A[@]}" --intrinsics "$missing/k.yaml"
expect_error "agent --intrinsics not YAML" "$tmp/junk.yaml:1: intrinsics" "${A[@]}" --intrinsics "$tmp/junk.yaml"
expect_error "agent --pose-log missing" "$missing/gps.csv" "${A[@]}" --pose-mode gps-imu --pose-log "$missing"
expect_error "agent --tls-ca missing" "$missing/ca.pem" "${A[@]}" --tls-ca "$missing/ca.pem"
expect_error "agent --tls-cert without --tls-ca" "needs --tls-ca" "${A[@]}" --tls-cert "$tmp/junk.pem" --tls-key "$tmp/junk.pem"
expect_error "agent --source file: missing" "file:$missing/v.mp4': cannot open" "${A0[@]}" --source "file:$missing/v.mp4"
expect_error "agent --source file: not a video" "$tmp/junk" "${A0[@]}" --source "file:$tmp/junk" --max-frames 1
expect_error "agent --source sim: scenario missing" "$missing/s.yaml" "${A0[@]}" --source "sim:$missing/s.yaml#c"
expect_error "agent --source v4l2: huge device" "device number out of range" "${A0[@]}" --source "v4l2:99999999999999999999"
expect_error "agent --fov 0" "--fov" "${A[@]}" --fov 0
expect_error "agent --fps nan" "fps" "${A[@]}" --fps nan
expect_error "agent --latency nan" "--latency" "${A[@]}" --detect-only --out - --latency nan
expect_error "agent --position 2 values" "--position/--look-at" "${A[@]}" --position 1,2 --look-at 1,2,3
expect_error "agent --detect-only --out missing" "$missing/t.jsonl" "${A[@]}" --detect-only --out "$missing/t.jsonl"
expect_error "agent --spill folder missing" "--spill: $missing/a.meta: no folder" "${A[@]}" --spill "$missing/a.meta"
out=$(timeout 30 "${A[@]}" --duration 0.3 2>&1); rc=$?   # a --duration ends the agent even with no server
if [ $rc -ne 0 ]; then echo "FAIL agent --duration with no server: exit $rc: $(tail -2 <<<"$out")"; fail=1; fi
AD=("$bin/ave-admin" --server 127.0.0.1:1 --token t)
expect_error "admin --intrinsics missing" "$missing/k.yaml" "${AD[@]}" add-camera --id c --position 1,2,3 --look-at 4,5,6 --intrinsics "$missing/k.yaml"
expect_error "admin --tls-ca missing" "$missing/ca.pem" "${AD[@]}" --tls-ca "$missing/ca.pem" list
expect_error "admin env AVE_TLS_CA missing" "$missing/env-ca.pem" env AVE_TLS_CA="$missing/env-ca.pem" "${AD[@]}" list
expect_error "admin --fov 0" "--fov" "${AD[@]}" add-camera --id c --position 1,2,3 --look-at 4,5,6 --fov 0
expect_error "admin issue-token --role bad" "--role: root not in" "${AD[@]}" issue-token --role root
expect_error "admin put-avatar --file missing" "$missing/walk.avseq" "${AD[@]}" put-avatar --file "$missing/walk.avseq"
expect_error "admin put-avatar --file not an avseq" "$tmp/junk" "${AD[@]}" put-avatar --file "$tmp/junk"
expect_error "admin --size bad" "--size must be WIDTHxHEIGHT" "${AD[@]}" add-camera --id c --position 1,2,3 --look-at 4,5,6 --size 64x
expect_error "admin --quaternion bad" "--quaternion" "${AD[@]}" add-camera --id c --position 1,2,3 --quaternion 1,0,0
V=("$bin/ave-viewer" --server 127.0.0.1:1 --headless --timeout 1)
expect_error "viewer window without DISPLAY" "GLFW: no DISPLAY set; use the headless context" env -u DISPLAY -u WAYLAND_DISPLAY "$bin/ave-viewer" --server 127.0.0.1:1 --timeout 1
expect_error "viewer --snapshot folder missing" "no folder $missing" "${V[@]}" --snapshot "$missing/x.png"
expect_error "viewer --depth folder missing" "no folder $missing" "${V[@]}" --snapshot "$tmp/x.png" --depth "$missing/d.exr"
expect_error "viewer --record under a file" "--record $tmp/junk/rec" "${V[@]}" --record "$tmp/junk/rec"
expect_error "viewer --tls-ca missing" "$missing/ca.pem" "${V[@]}" --snapshot "$tmp/x.png" --tls-ca "$missing/ca.pem"
expect_error "viewer --size 0x0" "size must be" "${V[@]}" --snapshot "$tmp/x.png" --size 0x0
expect_error "viewer --max-rate nan" "max rate" "${V[@]}" --snapshot "$tmp/x.png" --max-rate nan
# Replay flags (issue 18); each refused before any connection is tried.
expect_error "viewer --replay-from alone" "--replay-from and --replay-to go together" "${V[@]}" --snapshot "$tmp/x.png" --replay-from -60
expect_error "viewer --replay-to before --replay-from" "--replay-to must be after --replay-from" "${V[@]}" --snapshot "$tmp/x.png" --replay-from -10 --replay-to -60
expect_error "viewer --replay-rate 32" "--replay-rate must be 0.25 .. 16" "${V[@]}" --snapshot "$tmp/x.png" --replay-from -60 --replay-to 0 --replay-rate 32
expect_error "viewer --video without replay" "--video needs --headless and --replay-from / --replay-to" "${V[@]}" --record "$tmp/rec" --video "$tmp/v.mkv"
expect_error "viewer --video-fps 0" "--video-fps must be 1 .. 120" "${V[@]}" --record "$tmp/rec" --replay-from -60 --replay-to 0 --video "$tmp/v.mkv" --video-fps 0
expect_error "viewer --video .mp4" "must end in .mkv or .avi" "${V[@]}" --record "$tmp/rec" --replay-from -60 --replay-to 0 --video "$tmp/v.mp4"
expect_error "viewer --video folder missing" "--video $missing/v.mkv: no folder $missing" "${V[@]}" --record "$tmp/rec" --replay-from -60 --replay-to 0 --video "$missing/v.mkv"
expect_error "model build --input missing" "$missing/x.las" "$bin/ave-model" build --input "$missing/x.las"
expect_error "model build --input not a PCD" "$tmp/junk.pcd: header line 1" "$bin/ave-model" build --input "$tmp/junk.pcd"
expect_error "model build --input unknown extension" "unknown point cloud extension" "$bin/ave-model" build --input "$tmp/junk"
expect_error "model build --units bad" "--units 'furlong'" "$bin/ave-model" build --input "$tmp/junk.pcd" --units furlong
expect_error "model build --resolution nan" "--resolution" "$bin/ave-model" build --input "$tmp/junk.pcd" --resolution nan
expect_error "model export --db missing" "$missing/m.db: no such model store" "$bin/ave-model" export --db "$missing/m.db" --out "$tmp/m.ply"
expect_error "model export --db typo creates nothing" "$tmp/typo.db: no such model store" "$bin/ave-model" export --db "$tmp/typo.db" --out "$tmp/m.ply"
if [ -e "$tmp/typo.db" ]; then echo "FAIL model export created $tmp/typo.db"; fail=1; fi
expect_error "model export --db not SQLite" "$tmp/junk" "$bin/ave-model" export --db "$tmp/junk" --out "$tmp/m.ply"
expect_error "model fit --input missing" "$missing/x.las" "$bin/ave-model" fit --input "$missing/x.las" --type box --click 1,2
expect_error "model fit --units nan" "--units" "$bin/ave-model" fit --input "$missing/x.las" --type box --click 1,2 --units nan
expect_error "sim --scenario missing" "$missing/s.yaml" "$bin/ave-sim" camera --scenario "$missing/s.yaml" --camera c --out "$tmp/sim"
expect_error "sim --scenario not YAML" "junk.yaml" "$bin/ave-sim" camera --scenario "$tmp/junk.yaml" --camera c --out "$tmp/sim"
expect_error "sim --camera unknown" "no camera 'nope' (cameras: cam1)" "$bin/ave-sim" camera --scenario minimal --camera nope --out "$tmp/sim"
expect_error "sim --out under a file" "cannot create $tmp/junk/sub" "$bin/ave-sim" camera --scenario minimal --camera cam1 --out "$tmp/junk/sub" --frames 1
expect_error "sim --fps nan" "--fps" "$bin/ave-sim" camera --scenario minimal --camera cam1 --out "$tmp/sim" --fps nan
expect_error "sim --start nan" "--start" "$bin/ave-sim" camera --scenario minimal --camera cam1 --out "$tmp/sim" --start nan
expect_error "sim --seconds nan" "--seconds" "$bin/ave-sim" rotating-lidar --scenario courtyard --out "$tmp/sim" --seconds nan
expect_error "calibrate --square nan" "square" "$bin/ave-calibrate" --images "$tmp/junk" --board 9x6 --square nan --out "$tmp/k.yaml"
expect_error "calibrate --out folder missing" "--out: $missing/k.yaml: no folder" "$bin/ave-calibrate" --images "$tmp/junk" --board 9x6 --square 0.02 --out "$missing/k.yaml"
expect_error "calibrate --images not images" "board was found in 0 of 1" "$bin/ave-calibrate" --images "$tmp/junk" --board 9x6 --square 0.02 --out "$tmp/k.yaml"
expect_error "loadgen --server-bin missing" "--server-bin $missing/ave-server" "$bin/ave-loadgen" --server-bin "$missing/ave-server" --duration 1 --streams 1
expect_error "loadgen --duration nan" "--duration" "$bin/ave-loadgen" --duration nan
expect_error "loadgen --tls-ca missing" "$missing/ca.pem" "$bin/ave-loadgen" --server 127.0.0.1:1 --duration 1 --streams 1 --tls-ca "$missing/ca.pem"
expect_error "bench --scenario missing" "$missing/s.yaml" "$bin/ave-bench" sim --scenario "$missing/s.yaml"
expect_error "bench --seconds nan" "--seconds" "$bin/ave-bench" sim --seconds nan
# Outputs into a folder that exists but takes no file (/proc/self refuses new files, even to root):
# refused at parse time, naming the flag and the path, before any work (issue 14).
ro=/proc/self
expect_error "agent --spill folder unwritable" "--spill: $ro/a.meta: folder $ro cannot be written" "${A[@]}" --spill "$ro/a.meta"
expect_error "agent --detect-only --out unwritable" "--out: $ro/t.jsonl: folder $ro cannot be written" "${A[@]}" --detect-only --out "$ro/t.jsonl"
expect_error "calibrate --out folder unwritable" "--out: $ro/k.yaml: folder $ro cannot be written" "$bin/ave-calibrate" --images "$tmp/junk" --board 9x6 --square 0.02 --out "$ro/k.yaml"
expect_error "model build --mesh unwritable" "--mesh: $ro/m.ply: folder $ro cannot be written" "$bin/ave-model" build --input "$tmp/junk.pcd" --mesh "$ro/m.ply"
expect_error "model build --exr unwritable" "--exr: $ro/t.exr: folder $ro cannot be written" "$bin/ave-model" build --input "$tmp/junk.pcd" --exr "$ro/t.exr"
expect_error "model build --classified unwritable" "--classified: $ro/c.las: folder $ro cannot be written" "$bin/ave-model" build --input "$tmp/junk.pcd" --classified "$ro/c.las"
expect_error "model classify --out unwritable" "--out: $ro/c.las: folder $ro cannot be written" "$bin/ave-model" classify --input "$tmp/junk.pcd" --out "$ro/c.las"
expect_error "model export --out unwritable" "--out: $ro/m.gltf: folder $ro cannot be written" "$bin/ave-model" export --db "$tmp/junk" --out "$ro/m.gltf"
expect_error "model export --out is a folder" "--out: $tmp: is a folder" "$bin/ave-model" export --db "$tmp/junk" --out "$tmp"
expect_error "loadgen --plot unwritable" "--plot: $ro/p.png: folder $ro cannot be written" "$bin/ave-loadgen" --duration 1 --streams 1 --plot "$ro/p.png"
for b in "pose --png" "detect --png" "lidar --png" "environment --png" "model --png" "render --plot" "select --plot"; do
  set -- $b
  expect_error "bench $1 $2 unwritable" "$2: $ro/p.png: folder $ro cannot be written" "$bin/ave-bench" "$1" "$2" "$ro/p.png"
done
if [ -e "$missing" ]; then echo "FAIL something created $missing"; fail=1; fi

[ "$fail" = 0 ] && echo "cli: all checks passed"
exit $fail
