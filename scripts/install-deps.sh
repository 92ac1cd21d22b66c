#!/usr/bin/env bash
# Installs every build and test dependency of vdyn on Debian 12, from Debian's own packages.
# Idempotent: packages already present are skipped by apt. Run as root (or through sudo).
#   scripts/install-deps.sh             everything to build and test
#   scripts/install-deps.sh --runtime   only what the built programs need to run (the container
#                                       image's last stage, docker/Dockerfile)
set -euo pipefail

build_packages=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  libeigen3-dev libembree-dev libprotobuf-dev protobuf-compiler
  libspdlog-dev libfmt-dev libcli11-dev libassimp-dev libstb-dev
  libgtest-dev libgmock-dev libbenchmark-dev libbullet-dev
  cyclonedds-dev cyclonedds-tools iproute2
  libsdl2-dev xvfb xauth xdotool libgl1-mesa-dri openssl
  libzstd-dev liblz4-dev zlib1g-dev gnuplot-nox
  libepoxy-dev libimgui-dev libopenxr-dev libx11-dev
  clang libclang-rt-14-dev lld universal-ctags
  python3 python3-dev pybind11-dev python3-numpy python3-protobuf python3-pytest
  python3-pandas python3-matplotlib python3-venv python3-setuptools python3-pip
  libboost-dev libssl-dev nlohmann-json3-dev libjs-three chromium
)
# vdyn-foxglove: Boost.Asio and Beast (header-only), OpenSSL (wss), nlohmann's JSON, three.js for
# its page; Chromium for the page's test (tests/foxglove/page.test.js drives it headless).
# The recorder's independent-reader test and vdyn-foxglove's tests also need Node.js with npm
# (they install @mcap/core, @foxglove/ws-protocol and playwright-core from the npm registry); these
# machines come with Node.js 20.

# The shared libraries the vdyn programs load (what the -dev packages above bring for them), and
# openssl for scripts/lab-pki.sh, gnuplot for `vdyn-recorder plot`; libgl1 and Mesa for the viewer (libepoxy and SDL load OpenGL at run
# time, which ldd cannot see). docker/Dockerfile checks with ldd that nothing else is missing.
runtime_packages=(
  libembree3-3 libassimp5 libprotobuf32 libspdlog1.10 libfmt9 libddsc0debian
  libsdl2-2.0-0 libepoxy0 libopenxr-loader1 libx11-6 libgl1 libgl1-mesa-dri
  libstb0 libzstd1 liblz4-1 zlib1g openssl ca-certificates gnuplot-nox libssl3 libjs-three
)

case "${1:-}" in
  "") packages=("${build_packages[@]}") ;;
  --runtime) packages=("${runtime_packages[@]}") ;;
  *) echo "usage: $0 [--runtime]" >&2; exit 2 ;;
esac

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
