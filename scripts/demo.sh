#!/usr/bin/env bash
# vdyn's main job on its built-in default world: installs what it needs, builds, and runs a live
# session - the server on `facility` in real time (1 kHz), with the demo drive fed to it as live
# driver input over DDS by vdyn-input, and a terminal line of speed, step rate and lateness. The
# session is recorded to out/live.mcap (vdyn-recorder), then re-simulated and checked bit for bit.
# With a display (DISPLAY or WAYLAND_DISPLAY set) vdyn-viewer opens on the live session
# (VDYN_VIEWER=0 leaves it closed).
#   scripts/demo.sh            the live session (about 45 s)
#   scripts/demo.sh --batch    the same drive as a batch run, as fast as possible, to out/demo.csv
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh release vdyn-server vdyn-input vdyn-recorder vdyn-viewer
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
# The recorder's socket needs room for the world description the server sends in one burst (2 MB)
# and its first states: as root (a fresh machine), raise the kernel's cap (scripts/raise-rmem.sh).
./scripts/raise-rmem.sh demo.sh
# The recorder first, so it has the whole session: every topic, raw, into MCAP.
"$rec" record out/live.mcap --domain "$domain" --no-status &
recorder=$!
# The server runs the drive's 40 s of simulated time and ends; the input, started just after it,
# is still sending then (the car stands braked from ~35 s), and is stopped once the server has
# ended: no step runs without a driver. (Stopping the server after the input had ended left the
# last 0.1-0.5 s to the watchdog's safe state; a longer fixed duration, its last seconds.)
"$bin/server/vdyn-server" --domain "$domain" --world facility --status --duration 40 \
  --stats-out out/live-stats.txt &
server=$!
viewer=""
input=""
trap 'kill "$server" "$recorder" $viewer $input 2>/dev/null || true' EXIT
if [ -n "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ] && [ "${VDYN_VIEWER:-1}" != 0 ]; then
  # The viewer joins the session (it gets the world at once: transient local) and follows
  # vehicle 1 on the chase camera; its keys: F1.
  "$bin/clients/vr_viewer/vdyn-viewer" --domain "$domain" --follow 1 --camera chase \
    --stats-out out/viewer-stats.txt > out/viewer.log 2>&1 &
  viewer=$!
  echo "vdyn-viewer open on domain $domain (log in out/viewer.log)"
fi
"$bin/clients/wheel_input/vdyn-input" --domain "$domain" --maneuver demo --wait 30 &
input=$!
wait "$server"
kill -INT "$input" 2>/dev/null || true
wait "$input"  # 0 when stopped by Ctrl-C; 1 or 2 when it failed (set -e ends the script)
kill -INT "$recorder"
wait "$recorder"
if [ -n "$viewer" ]; then kill -INT "$viewer" 2>/dev/null || true; wait "$viewer" || true; fi
trap - EXIT
echo "live session done; run summary in out/live-stats.txt; recording in out/live.mcap"
"$rec" verify out/live.mcap
cat <<EOF
Next, with the recording:
  $rec info   out/live.mcap                      # channels, vehicles, world, gaps
  $rec export out/live.mcap --csv out/live.csv   # the columns of --batch --csv
  $rec plot   out/live.mcap                      # figures and out/live-plots/index.html
  $rec play   out/live.mcap --domain 43          # the playback on DDS; to watch it (a display):
  $bin/clients/vr_viewer/vdyn-viewer --domain 43
EOF
