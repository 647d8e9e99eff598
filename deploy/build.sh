#!/usr/bin/env bash
# Configures and builds AVE (Release) into ${AVE_BUILD_DIR:-build}. Used by demo.sh and test.sh.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${AVE_BUILD_DIR:-$root/build}
jobs=${AVE_JOBS:-$(nproc)}
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build" -j "$jobs"
