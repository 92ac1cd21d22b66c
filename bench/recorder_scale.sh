#!/usr/bin/env bash
# recorder_scale.sh: one real-time vdyn-server with N vehicles on `flat` and one vdyn-recorder
# recording everything, for SECONDS; prints each server thread's CPU (% of one core, from
# /proc/PID/task/TID/stat), the recorder's CPU, the server's run summary (steps due and run,
# lateness, states its writer refused) and the recorder's own summary (messages recorded, states
# lost before they reached it, samples dropped from its full buffer).
#   bench/recorder_scale.sh [VEHICLES=128] [STEP_THREADS=2] [SECONDS=10] [recorder options...]
# e.g. bench/recorder_scale.sh 128 2 10 --compression lz4
# CYCLONEDDS_URI in the environment goes to both programs; VDYN_RECORDER names another recorder
# binary (a peer: an earlier build), or `none`: the server alone (does it publish every state?);
# VDYN_SERVER names another server binary.
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:-128}"; threads="${2:-2}"; seconds="${3:-10}"; shift $(( $# < 3 ? $# : 3 ))
bin=build/release
tmp=$(mktemp -d)
trap '[ -n "${KEEP:-}" ] || rm -rf "$tmp"' EXIT
domain=$(( 150 + $$ % 60 ))
"${VDYN_SERVER:-$bin/server/vdyn-server}" --domain "$domain" --world flat --no-status --max-vehicles 256 \
  --vehicle-ids "$(seq -s, 1 "$n")" --duration $(( seconds + 11 )) --step-threads "$threads" \
  --stats-out "$tmp/stats.txt" > "$tmp/server.log" 2>&1 &
server=$!
sleep 1
if [ "${VDYN_RECORDER:-}" = none ]; then
  sleep "$(( seconds + 8 ))" &  # stands in for the recorder: its CPU is ~0
else
  "${VDYN_RECORDER:-$bin/clients/recorder/vdyn-recorder}" record --domain "$domain" --no-status \
    --duration $(( seconds + 8 )) "$@" "$tmp/rec.mcap" > "$tmp/recorder.log" 2>&1 &
fi
recorder=$!
sleep 2
ticks() { awk '{print $14 + $15}' "$1"; }  # utime + stime, fields 14-15 (proc(5))
snapshot() {
  for t in /proc/"$server"/task/*; do  # a thread may end meanwhile (Cyclone's)
    c=$(cat "$t/comm" 2>/dev/null) && s=$(ticks "$t/stat" 2>/dev/null) && echo "$(basename "$t") $c $s"
  done | sort
}
hz=$(getconf CLK_TCK)
r0=$(ticks /proc/"$recorder"/stat); snapshot > "$tmp/a"
sleep "$seconds"
r1=$(ticks /proc/"$recorder"/stat); snapshot > "$tmp/b"
echo "load average $(cut -d' ' -f1-3 /proc/loadavg); $n vehicles, $threads stepping thread(s), $seconds s"
join "$tmp/a" "$tmp/b" | awk -v s="$seconds" -v hz="$hz" \
  '{ d = 100 * ($5 - $3) / hz / s; if (d >= 0.5) printf "  server thread %s %s: %.1f %%\n", $1, $2, d }'
awk -v a="$r0" -v b="$r1" -v s="$seconds" -v hz="$hz" \
  'BEGIN { printf "  recorder: %.1f %%\n", 100 * (b - a) / hz / s }'
wait "$server" || true
grep -E "^(steps|steps_due|lateness_p50_us|lateness_p99_us|lateness_max_us|states_refused|states_pushed|states_written) " \
  "$tmp/stats.txt" | sed 's/^/  server: /'
wait "$recorder" || true
if [ -f "$tmp/recorder.log" ]; then grep -E "^recorded " "$tmp/recorder.log" | sed 's/^/  /'; fi
