#!/usr/bin/env bash
# vdyn's main job on its built-in default world: installs what it needs, builds, and runs the
# demo drive on `facility` (batch, as fast as possible), writing every quantity to out/demo.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh release vdyn-server
exec ./build/release/server/vdyn-server --demo "$@"
