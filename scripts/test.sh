#!/usr/bin/env bash
# The test suite: installs what it needs, then builds and runs every test twice, in the release
# build and under AddressSanitizer + UndefinedBehaviorSanitizer, then fuzzes every parser for a
# bounded time (tests/fuzz/run.sh: clang, libFuzzer; VDYN_FUZZ_SECONDS per target, default 20).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
for config in release asan; do
  echo "== $config: build"
  ./scripts/build.sh "$config"
  echo "== $config: test"
  ctest --test-dir "build/$config" --output-on-failure --timeout 900 -j "$(nproc)"
done
echo "== fuzz: every parser for ${VDYN_FUZZ_SECONDS:-20} s from its seeds"
tests/fuzz/run.sh "${VDYN_FUZZ_SECONDS:-20}"
echo "== all tests passed (release and asan) and the fuzzers found nothing"
