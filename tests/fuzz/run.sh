#!/usr/bin/env bash
# Fuzzes every parser for a bounded time: builds the fuzz targets with clang, libFuzzer, ASan and
# UBSan (build/fuzz), then runs each for SECONDS from its committed seeds. New inputs go to a
# scratch folder, not into the repository. A crash fails the run and names the input: add it to
# tests/fuzz/regressions/<target>/ (a test from then on) with the fix.
# The mutations follow a fixed seed (VDYN_FUZZ_SEED, default 1), so a run repeats what an
# earlier run of the same code did, up to where it stopped; a slower machine stops sooner and finds
# nothing a faster one did not. VDYN_FUZZ_SEED=0 lets libFuzzer pick a new seed (explore).
# Usage: tests/fuzz/run.sh [SECONDS=20]
set -euo pipefail
cd "$(dirname "$0")/../.."
seconds="${1:-20}"
seed="${VDYN_FUZZ_SEED:-1}"
dir=build/fuzz
flags=(-DCMAKE_BUILD_TYPE=RelWithDebInfo -DVDYN_SANITIZE=ON -DVDYN_FUZZ=ON -DVDYN_BUILD_BENCH=OFF
       -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++)
if command -v ccache >/dev/null 2>&1; then flags+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
cmake -S . -B "$dir" -G Ninja "${flags[@]}" >/dev/null
targets=(maneuver vehicle_params world_file world_description server_messages mcap recover_verify)
cmake --build "$dir" --parallel "$(nproc)" --target "${targets[@]/#/fuzz_}"
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:allocator_may_return_null=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
scratch="$dir/scratch"
mkdir -p "$dir/artifacts"
status=0
for t in "${targets[@]}"; do
  rm -rf "$scratch/$t"
  mkdir -p "$scratch/$t"
  echo "== fuzz_$t for ${seconds} s (seeds: tests/fuzz/corpus/$t; -seed=$seed)"
  if ! "$dir/tests/fuzz/fuzz_$t" -seed="$seed" -max_total_time="$seconds" -rss_limit_mb=2560 -timeout=10 \
       -print_final_stats=1 -artifact_prefix="$dir/artifacts/$t-" \
       "$scratch/$t" "tests/fuzz/corpus/$t" > "$dir/fuzz_$t.log" 2>&1; then
    echo "fuzz_$t found a crash:"; tail -40 "$dir/fuzz_$t.log"; status=1
  else
    grep -E "stat::number_of_executed_units|stat::new_units_added" "$dir/fuzz_$t.log" | tr '\n' ' '
    echo
  fi
done
exit $status
