#!/usr/bin/env bash
# Installs everything artrace needs to build and test, from Debian's packages only.
# Run as root on Debian 12 (bookworm) or newer.
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
packages=(
  build-essential cmake ninja-build pkg-config
  libglm-dev libtbb-dev libcli11-dev nlohmann-json3-dev
  libeigen3-dev libopencv-dev libopencv-contrib-dev libopenni2-dev libdeflate-dev libtinygltf-dev libopen3d-dev
  libavformat-dev libavcodec-dev libavutil-dev libswscale-dev
  libgtest-dev libgmock-dev
  libembree-dev
  xvfb  # the replay viewer's test runs under a virtual display
  slurm-wlm munge  # the sharded-export test starts a single-node Slurm cluster
  clang libclang-rt-dev  # the libFuzzer harnesses (scripts/fuzz.sh): Clang and its libFuzzer runtime
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
