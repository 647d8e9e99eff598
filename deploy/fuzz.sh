#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan + LSan + UBSan) into ${AVE_FUZZ_BUILD:-build-fuzz}
# and runs each for ${AVE_FUZZ_SECONDS:-20} s on a copy of its seed corpus. Exits non-zero on the
# first finding (the reproducer is left in the build folder). Needs clang-14 and libclang-rt-14-dev.
#   deploy/fuzz.sh                  (AVE_FUZZ_SECONDS=600 for the long local runs)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${AVE_FUZZ_BUILD:-$root/build-fuzz}
seconds=${AVE_FUZZ_SECONDS:-20}
CC=clang-14 CXX=clang++-14 cmake -S "$root" -B "$build" -G Ninja -DAVE_FUZZ=ON -DAVE_BUILD_TESTS=OFF \
  -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
targets=(jpeg_header sensor_message mesh_blob avatar_blob scene_file grpc_services las_reader point_cloud intrinsics_file velodyne_pcap
  velodyne_udp velodyne_calibration velodyne_udp_socket image_decode)
# Each target's seeds live beside its source: <component>/fuzz/corpus/<target>.
corpus_dirs=(fusion_server/fuzz/corpus sensor_agent/fuzz/corpus viewer_client/fuzz/corpus)
cmake --build "$build" --target "${targets[@]/#/ave_fuzz_}"
# Two targets at a time (CI has two cores); each one's lines are printed together when it ends.
run_one() {
  local t=$1 work=$build/fuzz/corpus-$1 seeds="" d
  mkdir -p "$work"
  for d in "${corpus_dirs[@]}"; do
    if [[ -d "$root/$d/$t" ]]; then seeds=$root/$d/$t; fi
  done
  if [[ -z "$seeds" ]]; then
    echo "fuzz: no seed corpus for $t under ${corpus_dirs[*]}" >&2
    return 1
  fi
  local log rc=0
  log=$(cd "$build/fuzz" && nice -n 19 "./ave_fuzz_$t" -max_total_time="$seconds" -rss_limit_mb=2048 -print_final_stats=1 \
    "$work" "$seeds" 2>&1 | grep -E "^(stat::number_of_executed_units|Done|==[0-9]+==ERROR|SUMMARY)") || rc=$?
  printf 'fuzz: %s for %s s\n%s\n' "$t" "$seconds" "$log"
  return $rc
}
export -f run_one
export build root seconds
export corpus_dirs_list="${corpus_dirs[*]}"
printf '%s\n' "${targets[@]}" | xargs -P 2 -I{} bash -c 'set -o pipefail; corpus_dirs=($corpus_dirs_list); run_one "$1"' _ {}
echo "fuzz: no findings"
