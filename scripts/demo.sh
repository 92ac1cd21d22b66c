#!/usr/bin/env bash
# vdyn's main job on its built-in default world: installs what it needs, builds, and runs a live
# session - the server on `facility` in real time (1 kHz), with the demo drive fed to it as live
# driver input over DDS by vdyn-input, and a terminal line of speed, step rate and lateness. The
# session is recorded to out/live.mcap (vdyn-recorder), then re-simulated and checked bit for bit.
#   scripts/demo.sh            the live session (about 45 s)
#   scripts/demo.sh --batch    the same drive as a batch run, as fast as possible, to out/demo.csv
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh release vdyn-server vdyn-input vdyn-recorder
bin=build/release
if [ "${1:-}" = "--batch" ]; then
  shift
  exec "$bin/server/vdyn-server" --demo "$@"
fi
# Loopback only unless the caller configured Cyclone DDS; a domain of its own.
export CYCLONEDDS_URI="${CYCLONEDDS_URI:-<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>}"
domain="${VDYN_DOMAIN:-42}"
rec="$bin/clients/recorder/vdyn-recorder"
mkdir -p out
# The recorder first, so it has the whole session: every topic, raw, into MCAP.
"$rec" record out/live.mcap --domain "$domain" --no-status &
recorder=$!
"$bin/server/vdyn-server" --domain "$domain" --world facility --duration 44 --status \
  --stats-out out/live-stats.txt &
server=$!
trap 'kill "$server" "$recorder" 2>/dev/null || true' EXIT
"$bin/clients/wheel_input/vdyn-input" --domain "$domain" --maneuver demo --wait 30
wait "$server"
kill -INT "$recorder"
wait "$recorder"
trap - EXIT
echo "live session done; run summary in out/live-stats.txt; recording in out/live.mcap"
"$rec" verify out/live.mcap
cat <<EOF
Next, with the recording:
  $rec info   out/live.mcap                      # channels, vehicles, world, gaps
  $rec export out/live.mcap --csv out/live.csv   # the columns of --batch --csv
  $rec plot   out/live.mcap                      # figures and out/live-plots/index.html
  $rec play   out/live.mcap --domain 43          # a viewer on domain 43 shows it as a live drive
EOF
