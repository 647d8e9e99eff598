#!/usr/bin/env bash
# Installs every Debian 12 package AVE needs to build, test and run. Idempotent: packages already
# present are skipped, and nothing is fetched when all are there. Run as root (or with sudo).
set -euo pipefail

PACKAGES=(
  # toolchain
  cmake ninja-build g++ pkg-config ca-certificates python3 procps
  # wire: gRPC + Protobuf
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  # vision, math, point clouds
  libopencv-dev libopencv-contrib-dev libeigen3-dev libpcl-dev
  # rendering: GLFW window, headless EGL (Mesa llvmpipe), GL loader, math
  libglfw3-dev libglm-dev libepoxy-dev libegl-dev libgl-dev libgl1-mesa-dri libegl-mesa0 xvfb xauth
  # window input in the tests: synthetic keyboard and mouse events on the virtual display
  xdotool
  # the viewer's on-screen panel: Dear ImGui with its OpenGL 3 backend (static library)
  libimgui-dev
  # store
  libsqlite3-dev libopenexr-dev libabsl-dev
  # security: TLS certificates (openssl CLI), token hashing (libcrypto)
  openssl libssl-dev
  # command lines, JSON
  libcli11-dev nlohmann-json3-dev libyaml-cpp-dev
  # tests and benchmarks; clang + its runtime for the libFuzzer targets (deploy/fuzz.sh)
  libgtest-dev libgmock-dev libbenchmark-dev clang-14 libclang-rt-14-dev
  # CPU load beside the repeated end-to-end tests (deploy/test.sh, docs/RELIABILITY.md)
  stress-ng
  # the libpcap peer of ave-bench lidar-decode (the product reads pcap files itself)
  libpcap-dev
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  command -v sudo >/dev/null || { echo "install-deps: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
  SUDO="sudo"
fi

echo "install-deps: installing ${#missing[@]} packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "install-deps: done"
