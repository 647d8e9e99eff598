#!/bin/bash
# Issue 17 on a GPU machine: `ave-bench avatars` through NVIDIA's EGL (docs/BENCHMARKS.md, "The same
# frames on a GPU"), and the renderer's tests (ave_render_test's sources as ave-render-test-gpu) on
# that driver. Not part of CI (no GPU there).
#   Here (Debian 12, the build done):   tests/bench/gpu/avatars_gpu.sh prepare
#     -> .gpu/ (ave-bench-avatars, ave-render-test-gpu and the Debian libraries they need, not glibc or libstdc++) and .gl/
#        (the glvnd loaders as .deb), both in .git/info/exclude
#   There (device tool, carry .gl and .gpu):  bash tests/bench/gpu/avatars_gpu.sh run   (writes $OUT/gpu.txt)
set -euo pipefail
case "${1:-}" in
  prepare)
    build=${AVE_BUILD:-build}
    ninja -C "$build" ave-bench-avatars ave-render-test-gpu
    for d in /.gl/ /.gpu/; do grep -qx "$d" .git/info/exclude || echo "$d" >> .git/info/exclude; done
    rm -rf .gpu && mkdir -p .gpu/lib .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    apt-get $o update >/dev/null
    (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
    cp "$build/bin/ave-bench-avatars" "$build/tests/ave-render-test-gpu" .gpu/
    for lib in $(ldd "$build/bin/ave-bench-avatars" "$build/tests/ave-render-test-gpu" | awk '{print $3}' | grep / | sort -u); do
      case $(basename "$lib") in
        libc.so*|libm.so*|libdl.so*|libpthread.so*|libstdc++*|libgcc_s*|libGLX*|libGLdispatch*) ;;
        *) cp -L "$lib" .gpu/lib/ ;;
      esac
    done
    cp -L /lib/x86_64-linux-gnu/libepoxy.so.0 .gpu/lib/
    du -sh .gpu .gl ;;
  run)
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
    export LD_LIBRARY_PATH=$PWD/.gpu/lib
    vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    if [ -f $vendor ]; then export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor; fi
    nvidia-smi -L
    echo "== ave-render-test-gpu" | tee -a "$OUT/gpu.txt" || true
    timeout 300 ./.gpu/ave-render-test-gpu 2>&1 | tee "$OUT/render_test.txt" | grep -E "^\[  (FAILED|PASSED) |tests ran" | tee -a "$OUT/gpu.txt" || true
    bench=./.gpu/ave-bench-avatars
    run() { echo "== $*" | tee -a "$OUT/gpu.txt"; timeout 120 $bench --png '' "$@" 2>&1 | tee -a "$OUT/gpu.txt" | tail -9; }
    run --frames 60
    run --frames 60 --counts 0,100 --no-view-cache
    run --frames 60 --counts 0,100 --cameras 0
    run --frames 30 --counts 0,100,1000
    run --frames 60 --counts 0,100 --no-model-shadows
    AVE_EGL_PLATFORM=device run --frames 60 --counts 0,100 ;;
  *) echo "usage: $0 prepare|run" >&2; exit 2 ;;
esac
