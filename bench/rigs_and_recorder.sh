#!/usr/bin/env bash
# rigs_and_recorder.sh: issue 19's shared-machine load. One real-time vdyn-server with N vehicles
# on `flat`, one vdyn-recorder recording everything and RIGS one-vehicle rigs (`vdyn-input play
# demo`, 1 kHz, vehicles 1..RIGS), all on this machine over loopback, for SECONDS. Prints the CPU
# of the server (each thread and the whole), the recorder and the rigs (% of one core, from /proc),
# the context switches per second of each kind of process, the server's run summary (steps due
# and run, lateness, states its writer refused) and the recorder's (recorded, lost before it,
# dropped from its full buffer).
#   bench/rigs_and_recorder.sh [VEHICLES=128] [STEP_THREADS=default] [SECONDS=10] [RIGS=8]
# The server is started with --max-vehicles VEHICLES; STEP_THREADS `default` leaves
# --step-threads to the server. VDYN_SERVER, VDYN_RECORDER and
# VDYN_INPUT name other binaries (a peer: an earlier build); CYCLONEDDS_URI in the environment
# goes to every program (default: loopback only).
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:-128}"; threads="${2:-default}"; seconds="${3:-10}"; nrigs="${4:-8}"
[ "$nrigs" -ge 1 ] && [ "$nrigs" -le "$n" ] || { echo "RIGS must be 1 to VEHICLES ($n)" >&2; exit 2; }
bin=build/release
tmp=$(mktemp -d)
pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; [ -n "${KEEP:-}" ] || rm -rf "$tmp"' EXIT
export CYCLONEDDS_URI="${CYCLONEDDS_URI:-<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>}"
domain=$(( 150 + $$ % 60 ))
step_threads=()
[ "$threads" = default ] || step_threads=(--step-threads "$threads")
"${VDYN_SERVER:-$bin/server/vdyn-server}" --domain "$domain" --world flat --no-status \
  --max-vehicles "$n" --vehicle-ids "$(seq -s, 1 "$n")" --duration $(( seconds + 14 )) \
  "${step_threads[@]}" --stats-out "$tmp/stats.txt" > "$tmp/server.log" 2>&1 &
server=$!; pids+=("$server")
sleep 1
rigs=()
for k in $(seq 1 "$nrigs"); do
  "${VDYN_INPUT:-$bin/clients/wheel_input/vdyn-input}" --domain "$domain" --vehicle-id "$k" \
    --strength 5 --wait 30 play demo --clock wall --loop > "$tmp/rig$k.log" 2>&1 &
  rigs+=($!); pids+=($!)
done
"${VDYN_RECORDER:-$bin/clients/recorder/vdyn-recorder}" record --domain "$domain" --no-status \
  --duration $(( seconds + 8 )) "$tmp/rec.mcap" > "$tmp/recorder.log" 2>&1 &
recorder=$!; pids+=("$recorder")
sleep 3
hz=$(getconf CLK_TCK)
# "<kind>/<tid> <comm> <cpu ticks> <context switches>" for every thread of every process, one
# awk per process (a loop of small programs per thread would load the machine it measures).
snapshot() {
  for p in "server:$server" "recorder:$recorder" $(printf 'rig:%s ' "${rigs[@]}"); do
    kind=${p%%:*}; pid=${p#*:}
    awk -v kind="$kind" '
      FNR == 1 { n = split(FILENAME, f, "/"); tid = f[n - 1] }
      FILENAME ~ /stat$/ { c = $0; sub(/^[^(]*\(/, "", c); sub(/\).*$/, "", c); gsub(/ /, "_", c)
                           name[tid] = c; sub(/^.*\) /, ""); ticks[tid] = $12 + $13 }
      /^(non)?voluntary_ctxt_switches/ { sw[tid] += $2 }
      END { for (t in name) print kind "/" t, name[t], ticks[t], sw[t] + 0 }' \
      /proc/"$pid"/task/*/stat /proc/"$pid"/task/*/status 2>/dev/null || true
  done | LC_ALL=C sort -k1,1
}
t0=$(date +%s.%N); snapshot > "$tmp/a"
sleep "$seconds"
t1=$(date +%s.%N); snapshot > "$tmp/b"; [ -z "${KEEP:-}" ] || echo "kept: $tmp"
window=$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }')
echo "load average $(cut -d' ' -f1-3 /proc/loadavg); $n vehicles, step threads $threads, $nrigs rigs, $window s"
LC_ALL=C join "$tmp/a" "$tmp/b" | awk -v s="$window" -v hz="$hz" '
  { split($1, k, "/"); cpu = 100 * ($6 - $3) / hz / s; cs = ($7 - $4) / s
    total[k[1]] += cpu; sw[k[1]] += cs
    if (k[1] == "server" && cpu >= 0.5) printf "  server thread %s %s: %.1f %%\n", k[2], $2, cpu }
  END { for (x in total) printf "  %s: %.1f %% of one core, %.0f context switches/s\n", x, total[x], sw[x] }'
wait "$recorder" || true
kill "${rigs[@]}" 2>/dev/null || true
wait "$server" || true
grep -E "^(steps|steps_due|lateness_p50_us|lateness_p99_us|lateness_max_us|states_refused|states_written) " \
  "$tmp/stats.txt" 2>/dev/null | sed 's/^/  server: /' || echo "  server: no run summary (see $tmp/server.log with KEEP=1)"
grep -E "^recorded " "$tmp/recorder.log" | sed 's/^/  /' || echo "  recorder: no summary line (see $tmp/recorder.log with KEEP=1)"
