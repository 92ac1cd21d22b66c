#!/usr/bin/env bash
# Configures and builds one configuration: release (default) or asan.
#   release   GCC, -O3, the programs, the tests and the benchmarks
#   asan      clang, AddressSanitizer + UndefinedBehaviorSanitizer, -O1 with line tables, the
#             programs and the tests (not the Python module: its tests run in the release build);
#             the parsers' libraries also carry libFuzzer's coverage, so tests/fuzz/run.sh fuzzes
#             from this same build (no third compile of the code)
# Usage: scripts/build.sh [release|asan] [extra targets...]
set -euo pipefail
cd "$(dirname "$0")/.."
config="${1:-release}"
shift || true
case "$config" in
  release) flags=(-DCMAKE_BUILD_TYPE=Release -DVDYN_SANITIZE=OFF -DCMAKE_CXX_COMPILER=g++
                  -DCMAKE_C_COMPILER=gcc) ;;
  asan) flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DVDYN_SANITIZE=ON -DVDYN_FUZZ=ON
               -DVDYN_BUILD_BENCH=OFF -DVDYN_PYTHON=OFF -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++
               "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -gline-tables-only -DNDEBUG"
               "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -gline-tables-only -DNDEBUG") ;;
  *) echo "build.sh: unknown configuration '$config' (release, asan)" >&2; exit 2 ;;
esac
dir="build/$config"
# A compiler cache where one is installed (developer machines); CI builds from scratch.
if command -v ccache >/dev/null 2>&1; then flags+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
# A folder configured with another compiler (an older checkout) starts again.
if [ -f "$dir/CMakeCache.txt" ]; then
  want=$([ "$config" = asan ] && echo clang++ || echo g++)
  if ! grep -q "^CMAKE_CXX_COMPILER:[A-Z]*=.*/$want\$\|^CMAKE_CXX_COMPILER:[A-Z]*=$want\$" "$dir/CMakeCache.txt"; then
    echo "build.sh: $dir was configured with another compiler; configuring it afresh"
    rm -rf "$dir"
  fi
fi
cmake -S . -B "$dir" -G Ninja "${flags[@]}" >/dev/null
cmake --build "$dir" --parallel "$(nproc)" ${1:+--target "$@"}
