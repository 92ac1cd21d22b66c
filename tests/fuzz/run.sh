#!/usr/bin/env bash
# Fuzzes every parser for a bounded time: builds the libFuzzer targets in the sanitizer build
# (build/asan: clang, ASan + UBSan, coverage in the parsers' libraries; scripts/build.sh asan), then
# runs each for SECONDS from its committed seeds. New inputs go to a scratch folder, not into the
# repository. A crash fails the run and names the input: add it to
# tests/fuzz/regressions/<target>/ (a test from then on) with the fix.
# The mutations follow a fixed seed (VDYN_FUZZ_SEED, default 1), so a run repeats what an
# earlier run of the same code did, up to where it stopped; a slower machine stops sooner and finds
# nothing a faster one did not. VDYN_FUZZ_SEED=0 lets libFuzzer pick a new seed (explore).
# An input that runs longer than 30 s is a failure (-timeout). libFuzzer counts wall-clock time,
# and scripts/test.sh runs the fuzzers at nice 19 beside the sanitizer suite, where an input of
# half a second's CPU once took 12 s; the targets' one-time set-up (a world, a session) is in
# LLVMFuzzerInitialize, outside that count.
# Usage: tests/fuzz/run.sh [SECONDS=10]
set -euo pipefail
cd "$(dirname "$0")/../.."
seconds="${1:-10}"
seed="${VDYN_FUZZ_SEED:-1}"
targets=(maneuver vehicle_params tire_file world_file world_description server_messages mcap recover_verify foxglove_client)
dir=build/asan
libfuzzer_targets=("${targets[@]/#/fuzz_}")
./scripts/build.sh asan "${libfuzzer_targets[@]/%/_libfuzzer}" >/dev/null
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:allocator_may_return_null=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
work="$dir/fuzz"
scratch="$work/scratch"
mkdir -p "$work/artifacts"
status=0
for t in "${targets[@]}"; do
  rm -rf "$scratch/$t"
  mkdir -p "$scratch/$t"
  echo "== fuzz_$t for ${seconds} s (seeds: tests/fuzz/corpus/$t; -seed=$seed)"
  if ! "$dir/tests/fuzz/fuzz_${t}_libfuzzer" -seed="$seed" -max_total_time="$seconds" \
       -rss_limit_mb=2560 -timeout=30 -print_final_stats=1 -artifact_prefix="$work/artifacts/$t-" \
       "$scratch/$t" "tests/fuzz/corpus/$t" > "$work/fuzz_$t.log" 2>&1; then
    echo "fuzz_$t found a crash:"; tail -40 "$work/fuzz_$t.log"; status=1
  else
    grep -E "stat::number_of_executed_units|stat::new_units_added" "$work/fuzz_$t.log" | tr '\n' ' '
    echo
  fi
done
exit $status
