#!/usr/bin/env bash
# The test suite: installs what it needs, builds, and runs every test twice - in the release build
# and under AddressSanitizer + UndefinedBehaviorSanitizer - then fuzzes every parser for a bounded
# time. Each stage is timed; the times are printed at the end (also when a stage fails).
#   scripts/test.sh           the default run: both suites (a one-minute recording soak among them)
#                             and 10 s of fuzzing per target (VDYN_FUZZ_SECONDS)
#   scripts/test.sh --full    also the long soaks (the ten-minute recording with nothing lost) and
#                             120 s of fuzzing per target
# The sanitizer build is clang's: the same build holds the suite and the libFuzzer targets
# (tests/fuzz/run.sh fuzzes from it), so the code is compiled twice in all, not three times. It
# compiles alongside the release suite, and the fuzzers run alongside the sanitizer suite, at the
# lowest CPU priority (below). Logs of the two: build/asan-build.log, build/fuzz.log.
set -euo pipefail
cd "$(dirname "$0")/.."

full=0
case "${1:-}" in
  "") ;;
  --full) full=1 ;;
  -h | --help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  *) echo "test.sh: unknown option '$1' (--full, --help)" >&2; exit 2 ;;
esac

stages=()
started=$(date +%s)
current=""
bg_pid=""
report() {
  local rc=$?
  if [ -n "$bg_pid" ]; then kill -- "-$bg_pid" 2>/dev/null || kill "$bg_pid" 2>/dev/null || true; fi
  echo
  echo "== times"
  for s in "${stages[@]}"; do echo "   $s"; done
  printf '   %-34s %5d s\n' "total" "$(($(date +%s) - started))"
  if [ "$rc" -ne 0 ]; then echo "== FAILED (exit $rc) in stage: ${current:-?}"; fi
}
trap report EXIT
stage() {  # stage NAME COMMAND...: runs and times one stage
  current="$1"
  shift
  echo "== $current"
  local t0
  t0=$(date +%s)
  "$@"
  stages+=("$(printf '%-34s %5d s' "$current" "$(($(date +%s) - t0))")")
}
# The suites mostly wait on real time (servers at 1 kHz, processes starting, DDS discovery) and
# leave most of the two cores idle; the builds and the fuzzers are pure CPU. So the sanitizer build
# runs alongside the release suite, and the fuzzers alongside the sanitizer suite, each at the
# lowest CPU priority (nice 19): the tests' processes take the CPU whenever they want it, the
# build or fuzzer takes what they leave. Its output goes to a log, printed when it fails.
bg_name="" bg_log="" bg_t0=0
background() {  # background NAME LOG COMMAND...: starts one low-priority job
  bg_name="$1" bg_log="$2"
  shift 2
  echo "== $bg_name (alongside, nice 19; log: $bg_log)"
  bg_t0=$(date +%s)
  setsid nice -n 19 "$@" >"$bg_log" 2>&1 &
  bg_pid=$!
}
await() {  # await: waits for the background job; fails (its log shown) when it failed
  current="$bg_name"
  local rc=0
  wait "$bg_pid" || rc=$?
  bg_pid=""
  stages+=("$(printf '%-34s %5d s' "$bg_name (alongside)" "$(($(date +%s) - bg_t0))")")
  if [ "$rc" -ne 0 ]; then
    echo "== $bg_name failed (exit $rc); the end of $bg_log:"
    tail -60 "$bg_log"
    return "$rc"
  fi
  echo "== $bg_name done"
}

export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# The long soaks carry the ctest label "full": left out of the default run.
# One test a core; the long programs run as shards (tests/CMakeLists.txt, vdyn_test ... SHARDS)
# so that their parts fill both. Two tests a core was tried (2026-12-05): load 19, and the
# Foxglove bridge's rate tests failed in the release suite.
ctest_args=(--output-on-failure --timeout 900 -j "$(nproc)")
if [ "$full" -eq 0 ]; then ctest_args+=(-LE full); fi
fuzz_seconds="${VDYN_FUZZ_SECONDS:-$([ "$full" -eq 1 ] && echo 120 || echo 10)}"
mkdir -p build

stage "install dependencies" ./scripts/install-deps.sh
# The tests' readers of best-effort states (recorders, players, Python, the tests' own) need the
# socket buffers they ask for: a fresh Debian caps them at 208 KiB (scripts/raise-rmem.sh).
./scripts/raise-rmem.sh test.sh
stage "build release" ./scripts/build.sh release
background "build asan + fuzz" build/asan-build.log ./scripts/build.sh asan
stage "test release" ctest --test-dir build/release "${ctest_args[@]}"
await
background "fuzz (${fuzz_seconds} s a target)" build/fuzz.log tests/fuzz/run.sh "$fuzz_seconds"
stage "test asan" ctest --test-dir build/asan "${ctest_args[@]}"
await
grep -E "^== fuzz_|stat::" build/fuzz.log || true
current=""
echo "== all tests passed (release and asan) and the fuzzers found nothing"
