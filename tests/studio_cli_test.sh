#!/usr/bin/env bash
# ave-studio end to end on a short simulated studio (issue 17): ave-sim studio writes 13 frame
# sets of 14 views (320x240), ave-studio reconstructs them at 20 mm into OBJ/MTL/PNG per frame and
# walk.avseq; a missing image and a mismatched calibration are refused naming the file and camera.
#   studio_cli_test.sh SOURCE_DIR BIN_DIR
set -u
src=$1
bin=$2
work=$(mktemp -d /tmp/ave_studio_cli.XXXXXX)
trap 'rm -rf "$work"' EXIT
fail=0
"$bin/ave-studio" --help >/dev/null 2>&1 || { echo "FAIL ave-studio --help"; fail=1; }
"$bin/ave-studio" --input x --out y --no-such-flag 2>"$work/flag"; rc=$?
if [ $rc -eq 0 ] || [ "$(wc -l <"$work/flag")" -ne 1 ] || ! grep -q no-such-flag "$work/flag"; then echo "FAIL bad flag: rc=$rc $(cat "$work/flag")"; fail=1; fi
"$bin/ave-studio" --input "$work/nowhere" --out "$work/o" 2>"$work/nocal"; rc=$?
if [ $rc -eq 0 ] || ! grep -q "nowhere/calibration.json" "$work/nocal"; then echo "FAIL missing calibration: rc=$rc $(cat "$work/nocal")"; fail=1; fi
sed -e 's/duration_s: 2, width: 640, height: 480/duration_s: 1.3, width: 320, height: 240/' \
  "$src/model_store/scene/scenarios/studio.yaml" >"$work/short.yaml"
grep -q "duration_s: 1.3" "$work/short.yaml" || { echo "FAIL the studio scenario changed: cannot shorten it"; exit 1; }
"$bin/ave-sim" studio --scenario "$work/short.yaml" --out "$work/sim" >/dev/null || { echo "FAIL ave-sim studio"; exit 1; }

"$bin/ave-studio" --input "$work/sim" --out "$work/out" --voxel-mm 20 2>"$work/log"; rc=$?
cat "$work/log"
[ $rc -eq 0 ] || { echo "FAIL ave-studio exited $rc"; fail=1; }
[ "$(grep -c '^ave-studio: frame ' "$work/log")" -eq 13 ] || { echo "FAIL expected 13 progress lines"; fail=1; }
for f in frame_0000.obj frame_0000.mtl frame_0000.png frame_0012.obj walk.avseq; do
  [ -s "$work/out/$f" ] || { echo "FAIL $f missing or empty"; fail=1; }
done
grep -q '^f [0-9]*/[0-9]*/[0-9]* ' "$work/out/frame_0000.obj" || { echo "FAIL OBJ has no textured faces"; fail=1; }
grep -q '^map_Kd frame_0000.png' "$work/out/frame_0000.mtl" || { echo "FAIL MTL does not name the atlas"; fail=1; }
head -c 4 "$work/out/walk.avseq" | grep -q AVEA || { echo "FAIL walk.avseq is not an avatar blob"; fail=1; }
# The actor's walk cycle is 1/0.9 s = 11.1 frames at 10 fps, at 0.7 m/s.
grep -Eq 'walk cycle frames [0-9]+\.\.[0-9]+ \((10|11|12) frames.*0\.(6[5-9]|7[0-5]) m/s' "$work/log" || { echo "FAIL walk cycle not ~11 frames at ~0.7 m/s"; fail=1; }

# One frame set: a statue.
"$bin/ave-studio" --input "$work/sim" --out "$work/one" --voxel-mm 40 --frames 1 2>"$work/log1" || { echo "FAIL one frame"; fail=1; }
grep -q "statue" "$work/log1" || { echo "FAIL one frame set did not say statue:"; cat "$work/log1"; fail=1; }

# A missing image names the file and the camera.
rm "$work/sim/ring05/image_0004.png"
"$bin/ave-studio" --input "$work/sim" --out "$work/bad" --voxel-mm 40 2>"$work/err"; rc=$?
if [ $rc -eq 0 ] || ! grep -q "ring05" "$work/err" || ! grep -q "image_0004.png" "$work/err"; then
  echo "FAIL missing image: rc=$rc $(cat "$work/err")"; fail=1
else echo "ok   missing image: $(cat "$work/err")"; fi
# A calibration whose image size does not match names the file and the camera.
sed -i -e '0,/"width": 320/s//"width": 640/' "$work/sim/calibration.json"
"$bin/ave-studio" --input "$work/sim" --out "$work/bad" --voxel-mm 40 2>"$work/err"; rc=$?
if [ $rc -eq 0 ] || ! grep -q "ring00" "$work/err" || ! grep -q "calibration.json says 640x240" "$work/err"; then
  echo "FAIL size mismatch: rc=$rc $(cat "$work/err")"; fail=1
else echo "ok   size mismatch: $(cat "$work/err")"; fi
[ $fail -eq 0 ] && echo "ok   ave-studio"
exit $fail
