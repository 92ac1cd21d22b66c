#!/usr/bin/env bash
# Installs every build and test dependency of vdyn on Debian 12, from Debian's own packages.
# Idempotent: packages already present are skipped by apt. Run as root (or through sudo).
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  libeigen3-dev libembree-dev libprotobuf-dev protobuf-compiler
  libspdlog-dev libfmt-dev libcli11-dev libassimp-dev libstb-dev
  libgtest-dev libgmock-dev libbenchmark-dev libbullet-dev
  cyclonedds-dev cyclonedds-tools iproute2
  libsdl2-dev xvfb xauth xdotool libgl1-mesa-dri
  libzstd-dev liblz4-dev zlib1g-dev gnuplot-nox
  libepoxy-dev libimgui-dev libopenxr-dev libx11-dev
)
# The recorder's independent-reader test also needs Node.js with npm (it installs @mcap/core from
# the npm registry); these machines come with Node.js 20.

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if [ "${#missing[@]}" -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then exec sudo "$0" "$@"; fi
  echo "install-deps: missing packages (${missing[*]}) and not root; run as root" >&2
  exit 1
fi

echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}"
