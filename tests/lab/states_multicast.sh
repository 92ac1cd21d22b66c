#!/usr/bin/env bash
# Readers on one host and the sends they cost the server (issue 37; docs/topics.md, "Several
# readers on one host"): with multicast on the interface, Cyclone DDS sends a step's vdyn/states
# sample once for all the readers on the host (its writer covers the readers' locators with as
# few as it can); without, once per reader.
#
# In a private network namespace (nothing leaves the machine), twice: `lo` with multicast on, and
# `lo` as Linux sets it up (no multicast flag: Cyclone sends to each reader's unicast address).
# Each time a real-time vdyn-server on `flat` with one vehicle, three readers of vdyn/states
# (test_state_subscriber --states) and one reader of vdyn/state in the default partition (a DDS
# tool's route). The namespace's own UDP counters (/proc/net/snmp) over the server's life: the
# datagrams received per datagram sent, which neither the machine's load nor a lagging writer's
# larger samples change (a step's datagrams are sent and received alike):
#   multicast: >= 2.5 (a send reaches the three readers, and the other sockets bound to the port:
#              Linux hands a group's datagrams to each, IP_MULTICAST_ALL being on by default);
#   unicast:   <= 1.5 (a send reaches one reader).
# Also printed, not asserted: the datagrams sent a step (1.95 against 3.98 on a quiet machine;
# fewer on a loaded one, whose writer sends several steps a sample). Every vdyn/states reader
# receives at least half the steps (the readers are reached at all; best effort loses some when
# the machine is loaded).
#
# Usage: tests/lab/states_multicast.sh BUILD_DIR
#   Needs root and unshare (exit 77 = skipped otherwise).
set -euo pipefail

SKIP=77
die() { echo "states_multicast: FAIL: $*" >&2; exit 1; }
skip() { echo "states_multicast: SKIPPED: $*"; exit "$SKIP"; }

[[ $# -eq 1 ]] || { echo "usage: $0 BUILD_DIR" >&2; exit 2; }
BUILD=$(realpath "$1")
SERVER=$BUILD/server/vdyn-server
SUBSCRIBER=$BUILD/tests/test_state_subscriber
for b in "$SERVER" "$SUBSCRIBER"; do [[ -x $b ]] || die "missing binary $b"; done
[[ $(id -u) -eq 0 ]] || skip "needs root for a private network namespace"
command -v unshare >/dev/null || skip "no unshare"
command -v ip >/dev/null || skip "no ip (iproute2)"

WORK=$(mktemp -d /tmp/vdyn-states-multicast.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
SECONDS_RUN=10

# One namespace's run; prints "steps sent received r1 r2 r3" on its last line.
run() {
  local mode=$1
  unshare -n bash -s "$mode" "$SERVER" "$SUBSCRIBER" "$WORK" "$SECONDS_RUN" <<'EOF'
set -euo pipefail
mode=$1 server=$2 subscriber=$3 work=$4 secs=$5
ip link set lo up
if [[ $mode == multicast ]]; then
  ip link set lo multicast on
  ip route add 224.0.0.0/4 dev lo
fi
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>'
udp() { awk '/^Udp: [0-9]/ { print $'"$1"' }' /proc/net/snmp; }  # 2 InDatagrams, 5 OutDatagrams
in0=$(udp 2) out0=$(udp 5)
pids=()
for i in 1 2 3; do
  "$subscriber" 7 100000000 $((secs + 4)) --states > "$work/$mode-r$i.txt" 2>&1 &
  pids+=($!)
done
"$subscriber" 7 100000000 $((secs + 4)) > "$work/$mode-tool.txt" 2>&1 &
tool=$!
"$server" --domain 7 --world flat --no-status --duration "$secs" --stats-out "$work/$mode-stats.txt" \
  > "$work/$mode-server.log" 2>&1 || { cat "$work/$mode-server.log" >&2; exit 1; }
in1=$(udp 2) out1=$(udp 5)
wait "${pids[@]}" "$tool"  # each ends $secs + 4 s after its start
steps=$(awk '$1 == "steps" { print $2 }' "$work/$mode-stats.txt")
echo "$steps $((out1 - out0)) $((in1 - in0))"
EOF
}

for mode in multicast unicast; do
  read -r steps sent received < <(run "$mode" | tail -1)
  [[ -n ${steps:-} && $steps -gt 0 ]] || die "$mode: the server ran no steps (logs in $WORK)"
  per_sent=$(awk -v a="$sent" -v s="$steps" 'BEGIN { printf "%.2f", a / s }')
  per_received=$(awk -v a="$received" -v s="$steps" 'BEGIN { printf "%.2f", a / s }')
  fanout=$(awk -v r="$received" -v o="$sent" 'BEGIN { printf "%.2f", (o > 0 ? r / o : 0) }')
  echo "states_multicast: $mode: $steps steps; UDP datagrams sent $sent ($per_sent a step), received $received ($per_received a step): $fanout received per datagram sent"
  for i in 1 2 3; do
    got=$(awk '/^received/ { print $2 }' "$WORK/$mode-r$i.txt" 2>/dev/null || true)
    echo "states_multicast: $mode: vdyn/states reader $i received ${got:-0} states"
    [[ ${got:-0} -ge $((steps / 2)) ]] || die "$mode: reader $i received ${got:-0} of $steps states"
  done
  if [[ $mode == multicast ]]; then
    awk -v x="$fanout" 'BEGIN { exit !(x >= 2.5) }' ||
      die "multicast: $fanout datagrams received per datagram sent, want >= 2.5 (one send for the three readers)"
  else
    awk -v x="$fanout" 'BEGIN { exit !(x <= 1.5) }' ||
      die "unicast: $fanout datagrams received per datagram sent, want <= 1.5 (the control: a send per reader)"
  fi
done
echo "states_multicast: passed"
