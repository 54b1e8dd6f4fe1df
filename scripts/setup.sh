#!/usr/bin/env bash
# Install the system packages grin needs (Debian): OpenVDB for vdb-sys, Mesa's lavapipe
# for wgpu without a GPU, python3-openvdb and the OpenVDB tools for the example data, numpy
# for the tests that make VDB files or cross-correlate BOS images, and
# Xvfb with the X11 libraries winit loads, for `grin view` without a display.
# Idempotent: does nothing when everything is present.
set -euo pipefail
pkgs=(libopenvdb-dev libboost-dev libtbb-dev libopenvdb-tools python3-openvdb python3-numpy
      mesa-vulkan-drivers libvulkan1 g++ pkg-config fonts-dejavu-core
      xvfb xauth libx11-6 libx11-xcb1 libxcursor1 libxrandr2 libxi6 libxkbcommon-x11-0)
missing=()
for p in "${pkgs[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
fi
