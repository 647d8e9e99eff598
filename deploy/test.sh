#!/usr/bin/env bash
# The whole test suite: installs what is missing, builds, runs every test with ctest.
#   sudo deploy/test.sh            (AVE_SKIP_DEPS=1 skips the package check)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${AVE_BUILD_DIR:-$root/build}
[ "${AVE_SKIP_DEPS:-0}" = 1 ] || bash "$root/deploy/install-deps.sh"
start=$(date +%s)
AVE_BUILD_DIR=$build bash "$root/deploy/build.sh"
echo "build: $(( $(date +%s) - start )) s"
ctest --test-dir "$build" --output-on-failure -j "${AVE_TEST_JOBS:-2}"
# A cheap form of the flakiness hunt (docs/RELIABILITY.md, "No flaky test"): the end-to-end and
# render tests, the ones that race threads, processes and the GPU driver, three times more while
# two CPU hogs load the machine. AVE_LOADED_REPEAT=0 skips it.
if [ "${AVE_LOADED_REPEAT:-3}" != 0 ]; then
  stress-ng --cpu 2 --timeout 900 --quiet &
  hogs=$!
  trap 'kill $hogs 2>/dev/null || true' EXIT
  ctest --test-dir "$build" --output-on-failure -j 2 -R '^ave_(e2e|objects_e2e|render|server)_test$' \
    --repeat until-fail:"${AVE_LOADED_REPEAT:-3}"
  kill $hogs 2>/dev/null || true
  wait $hogs 2>/dev/null || true
  trap - EXIT
  echo "loaded repeat: passed"
fi
# Every parser of outside input under libFuzzer for a short bounded time (clang build of its own;
# AVE_FUZZ_SECONDS=0 skips it; the long runs are recorded in docs/RELIABILITY.md).
if [ "${AVE_FUZZ_SECONDS:-10}" != 0 ]; then
  AVE_FUZZ_SECONDS=${AVE_FUZZ_SECONDS:-10} AVE_FUZZ_BUILD=${AVE_FUZZ_BUILD:-$build-fuzz} bash "$root/deploy/fuzz.sh"
fi
echo "build + tests: $(( $(date +%s) - start )) s"
