#!/usr/bin/env bash
# Configures and builds one configuration: release (default) or asan (ASan + UBSan, for tests).
# Usage: scripts/build.sh [release|asan] [extra targets...]
set -euo pipefail
cd "$(dirname "$0")/.."
config="${1:-release}"
shift || true
case "$config" in
  release) flags=(-DCMAKE_BUILD_TYPE=Release -DVDYN_SANITIZE=OFF) ;;
  asan) flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DVDYN_SANITIZE=ON -DVDYN_BUILD_BENCH=OFF) ;;
  *) echo "build.sh: unknown configuration '$config' (release, asan)" >&2; exit 2 ;;
esac
dir="build/$config"
# A compiler cache where one is installed (developer machines); CI builds from scratch.
if command -v ccache >/dev/null 2>&1; then flags+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
cmake -S . -B "$dir" -G Ninja "${flags[@]}" >/dev/null
cmake --build "$dir" --parallel "$(nproc)" ${1:+--target "$@"}
