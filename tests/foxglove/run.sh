#!/usr/bin/env bash
# Runs one of vdyn-foxglove's end-to-end tests (a node:test file in this folder) against real
# processes on loopback: installs the npm packages the tests use into the build folder (once; as
# tests/recorder/independent_reader.sh does), takes a DDS domain no other test uses (the lock
# files of testing::FreshDomain), and runs the file with node's test runner.
# Usage: run.sh BUILD_DIR SOURCE_DIR TEST.js
# Exit: the test runner's; 77 (skipped) when the test needs Chromium and it is not installed.
set -euo pipefail
build="$1"
src="$2"
test="$3"
work="$build/tests/foxglove_js"
mkdir -p "$work"
if ! command -v npm >/dev/null 2>&1; then
  echo "run.sh: npm is needed (Node.js 20 with npm) to install the Foxglove protocol client" >&2
  exit 1
fi
if [ "$test" = page.test.js ] && [ ! -x /usr/bin/chromium ]; then
  echo "SKIPPED: the page test needs Debian's chromium (apt-get install chromium; scripts/install-deps.sh installs it)"
  exit 77
fi
(
  # One install at a time: the tests run side by side under ctest -j.
  flock 9
  if [ ! -f "$work/node_modules/.installed" ] || [ "$src/package.json" -nt "$work/node_modules/.installed" ]; then
    cp "$src/package.json" "$work/"
    (cd "$work" && npm install --no-audit --no-fund --loglevel=error >npm.log 2>&1) || { cat "$work/npm.log"; exit 1; }
    touch "$work/node_modules/.installed"
  fi
) 9>"$work/.install.lock"
# A domain of 100..229 that no other test holds (released when this script exits).
. "$(dirname "$0")/../domain-lock.sh"
export VDYN_DOMAIN="$domain"
export VDYN_BUILD="$build"
export VDYN_WORK="$work/$(basename "$test" .test.js)"
export NODE_PATH="$work/node_modules"
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>'
rm -rf "$VDYN_WORK"
mkdir -p "$VDYN_WORK"
exec node --test --test-concurrency=1 "$src/$test"
