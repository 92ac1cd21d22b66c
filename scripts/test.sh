#!/usr/bin/env bash
# The test suite: installs what it needs, builds, and runs every test twice - in the release build
# and under AddressSanitizer + UndefinedBehaviorSanitizer - then fuzzes every parser for a bounded
# time. Each stage is timed; the times are printed at the end (also when a stage fails).
#   scripts/test.sh           the default run: both suites (a one-minute recording soak among them)
#                             and 10 s of fuzzing per target (VDYN_FUZZ_SECONDS)
#   scripts/test.sh --full    also the long soaks (the ten-minute recording with nothing lost) and
#                             120 s of fuzzing per target
# The sanitizer build is clang's: the same build holds the suite and the libFuzzer targets
# (tests/fuzz/run.sh fuzzes from it), so the code is compiled twice in all, not three times.
set -euo pipefail
cd "$(dirname "$0")/.."

full=0
case "${1:-}" in
  "") ;;
  --full) full=1 ;;
  -h | --help) sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  *) echo "test.sh: unknown option '$1' (--full, --help)" >&2; exit 2 ;;
esac

stages=()
started=$(date +%s)
report() {
  local rc=$?
  echo
  echo "== times"
  for s in "${stages[@]}"; do echo "   $s"; done
  printf '   %-22s %5d s\n' "total" "$(($(date +%s) - started))"
  if [ "$rc" -ne 0 ]; then echo "== FAILED (exit $rc) in stage: ${current:-?}"; fi
}
trap report EXIT
current=""
stage() {  # stage NAME COMMAND...: runs and times one stage
  current="$1"
  shift
  echo "== $current"
  local t0
  t0=$(date +%s)
  "$@"
  stages+=("$(printf '%-22s %5d s' "$current" "$(($(date +%s) - t0))")")
}

export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# The long soaks carry the ctest label "full": left out of the default run.
ctest_args=(--output-on-failure --timeout 900 -j "$(nproc)")
if [ "$full" -eq 0 ]; then ctest_args+=(-LE full); fi

stage "install dependencies" ./scripts/install-deps.sh
stage "build release" ./scripts/build.sh release
stage "test release" ctest --test-dir build/release "${ctest_args[@]}"
stage "build asan + fuzz" ./scripts/build.sh asan
stage "test asan" ctest --test-dir build/asan "${ctest_args[@]}"
fuzz_seconds="${VDYN_FUZZ_SECONDS:-$([ "$full" -eq 1 ] && echo 120 || echo 10)}"
stage "fuzz (${fuzz_seconds} s a target)" tests/fuzz/run.sh "$fuzz_seconds"
current=""
echo "== all tests passed (release and asan) and the fuzzers found nothing"
