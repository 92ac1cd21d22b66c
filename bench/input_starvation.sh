#!/usr/bin/env bash
# input_starvation.sh: issue 31's starved driver. One real-time vdyn-server (vehicle 1 on `flat`),
# HOGS busy-looping processes at the normal scheduler (nice 0) on this machine, and `vdyn-input
# play demo --clock wall --loop` (1 kHz) driving vehicle 1 for SECONDS, RUNS times with `--rt-priority 0` and
# RUNS times with `--rt-priority 20` (alternating, so both see the same machine). Each run prints
# the times the server's watchdog took the vehicle from the input (vdyn-input's own count: a state
# that applied its input followed by one in the watchdog's safe state); then the medians.
#   bench/input_starvation.sh [HOGS=4] [SECONDS=20] [RUNS=3]
# VDYN_SERVER and VDYN_INPUT name other binaries. SCHED_FIFO needs root or CAP_SYS_NICE / rtprio:
# the scheduling line of each run says what the loop got.
set -euo pipefail
cd "$(dirname "$0")/.."
hogs="${1:-4}"; seconds="${2:-20}"; runs="${3:-3}"
bin=build/release
tmp=$(mktemp -d)
pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; [ -n "${KEEP:-}" ] || rm -rf "$tmp"' EXIT
export CYCLONEDDS_URI="${CYCLONEDDS_URI:-<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>}"
domain=$(( 150 + $$ % 60 ))
"${VDYN_SERVER:-$bin/server/vdyn-server}" --domain "$domain" --world flat --no-status \
  > "$tmp/server.log" 2>&1 &
pids+=($!)
sleep 2
for _ in $(seq 1 "$hogs"); do
  nice -n 0 bash -c 'while :; do :; done' &
  pids+=($!)
done
one_run() {  # $1: label, rest: extra vdyn-input options
  local label=$1; shift
  timeout -s INT $(( seconds + 10 )) "${VDYN_INPUT:-$bin/clients/wheel_input/vdyn-input}" \
    --domain "$domain" --wait 30 "$@" play demo --clock wall --loop \
    > "$tmp/in.log" 2>&1 &
  local p=$!
  sleep "$seconds"; kill -INT "$p" 2>/dev/null || true; wait "$p" || true
  local n sched
  n=$(sed -n 's/.*watchdog took over \([0-9]*\) times.*/\1/p' "$tmp/in.log")
  sched=$(grep -o 'strength [0-9]*); .*' "$tmp/in.log" | sed 's/^strength [0-9]*); //' | head -1)
  echo "$label ${n:-?}  ($sched)"
}
: > "$tmp/results"
for r in $(seq 1 "$runs"); do
  one_run normal --rt-priority 0 | tee -a "$tmp/results"
  one_run rt --rt-priority 20 | tee -a "$tmp/results"
done
median() { grep "^$1 " "$tmp/results" | awk '{print $2}' | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
echo "load average $(cut -d' ' -f1-3 /proc/loadavg); $hogs hogs, $seconds s a run, $runs runs each"
echo "watchdog take-overs, median: normal scheduler $(median normal), --rt-priority 20 $(median rt)"
