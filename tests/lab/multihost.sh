#!/usr/bin/env bash
# shellcheck disable=SC2016  # awk programs in single quotes are meant literally
# Several hosts over DDS, on one machine: network namespaces joined by veth pairs through a bridge
# (nothing leaves the machine). Cuts and heals links, kills rigs and a host, and measures from the
# server's published states what the lab sees:
#
#   host A  10.231.0.1   vdyn-server, an observer (test_state_subscriber --print)
#   host B  10.231.0.2   the primary rig (vdyn-input play, strength 20), vdyn-recorder, an observer
#   host C  10.231.0.3   the backup rig (vdyn-input play, strength 5), vdyn-viewer (on Xvfb; skipped
#                        with --no-viewer or where there is no viewer or Xvfb)
#   switch               a namespace holding the bridge br0; each host's eth0 is a veth whose peer is
#                        a port of br0. Cutting a host's link = setting its switch port down.
#
# Discovery is Cyclone DDS's ordinary multicast SPDP on each host's eth0 (veths carry multicast; the
# bridge floods it, IGMP snooping off), so no peers list is needed.
#
# Usage: tests/lab/multihost.sh BUILD_DIR [--no-viewer] [--keep]
#   Needs root and `ip netns` (exit 77 = skipped otherwise). Logs and the recording go to a fresh
#   directory under /tmp, removed on success unless --keep (kept and named on failure).
#   VDYN_STATE_SUBSCRIBER overrides the observer binary (default BUILD_DIR/tests/test_state_subscriber).
set -euo pipefail

SKIP=77
die() { echo "multihost: FAIL: $*" >&2; exit 1; }
skip() { echo "multihost: SKIPPED: $*"; exit "$SKIP"; }

[[ $# -ge 1 ]] || { echo "usage: $0 BUILD_DIR [--no-viewer] [--keep]" >&2; exit 2; }
BUILD=$(realpath "$1"); shift
WANT_VIEWER=1 KEEP=0
for a in "$@"; do
  case $a in
    --no-viewer) WANT_VIEWER=0 ;;
    --keep) KEEP=1 ;;
    *) echo "unknown option $a" >&2; exit 2 ;;
  esac
done

SERVER=$BUILD/server/vdyn-server
INPUT=$BUILD/clients/wheel_input/vdyn-input
RECORDER=$BUILD/clients/recorder/vdyn-recorder
VIEWER=$BUILD/clients/vr_viewer/vdyn-viewer
OBSERVER=${VDYN_STATE_SUBSCRIBER:-$BUILD/tests/test_state_subscriber}
for b in "$SERVER" "$INPUT" "$RECORDER" "$OBSERVER"; do [[ -x $b ]] || die "missing binary $b"; done

[[ $(id -u) -eq 0 ]] || skip "needs root to create network namespaces"
command -v ip >/dev/null || skip "no ip (iproute2)"

# ---------------------------------------------------------------------------------------------
# Hosts: unique names per run, everything removed on exit, whatever happens.
ID=vdyn$$
NS_A=$ID-a NS_B=$ID-b NS_C=$ID-c NS_X=$ID-sw
NAMESPACES=()
PIDS=()
WORK=$(mktemp -d /tmp/vdyn-multihost.XXXXXX)
XVFB_PID=''
TIMER_PID=''
OK=0

cleanup() {
  set +e
  local p ns
  {  # quietly: the shell's "Killed" notices are expected here
    kill -TERM "$TIMER_PID" && wait "$TIMER_PID"
    for p in "${PIDS[@]}" $XVFB_PID; do kill -KILL "$p" && wait "$p"; done
    for ns in "${NAMESPACES[@]}"; do
      # Anything still running inside a namespace this run made (its processes only).
      for p in $(ip netns pids "$ns"); do kill -KILL "$p"; done
    done
    for ns in "${NAMESPACES[@]}"; do ip netns del "$ns"; done
  } 2>/dev/null
  if [[ $OK -eq 1 && $KEEP -eq 0 ]]; then
    rm -rf "$WORK"
  else
    echo "multihost: logs and recording kept in $WORK"
  fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM
# A deadline of our own, well inside ctest's (which would kill us without a chance to clean up).
DEADLINE_S=${VDYN_MULTIHOST_DEADLINE_S:-600}
(
  trap 'kill "$s" 2>/dev/null; exit 0' TERM
  sleep "$DEADLINE_S" & s=$!
  wait "$s" && echo "multihost: FAIL: no result after $DEADLINE_S s" >&2 && kill -TERM $$
) &
TIMER_PID=$!

# Hosts left by a run that was killed outright (SIGKILL gives no chance to clean up): this script's
# names, of a process that no longer exists.
for ns in $(ip netns list 2>/dev/null | grep -oE '^vdyn[0-9]+-(a|b|c|sw)\b' || true); do
  pid=${ns#vdyn}; pid=${pid%%-*}
  kill -0 "$pid" 2>/dev/null || ip netns del "$ns" 2>/dev/null || true
done

ip netns add "$NS_X" 2>/dev/null || skip "cannot create a network namespace (ip netns add failed)"
NAMESPACES+=("$NS_X")
ip -n "$NS_X" link set lo up
ip -n "$NS_X" link add br0 type bridge mcast_snooping 0 stp_state 0
ip -n "$NS_X" link set br0 up

# add_host NS PORT ADDRESS: a namespace whose eth0 is plugged into the switch's port PORT.
add_host() {
  local ns=$1 port=$2 addr=$3
  ip netns add "$ns"
  NAMESPACES+=("$ns")
  ip -n "$NS_X" link add "$port" type veth peer name eth0 netns "$ns"
  ip -n "$NS_X" link set "$port" master br0 up
  ip -n "$ns" link set lo up
  ip -n "$ns" addr add "$addr/24" dev eth0
  ip -n "$ns" link set eth0 up
  ip -n "$ns" route add 224.0.0.0/4 dev eth0
}
add_host "$NS_A" pa 10.231.0.1
add_host "$NS_B" pb 10.231.0.2
add_host "$NS_C" pc 10.231.0.3

# Every process uses its host's eth0 only. The domain is private to this run's namespaces.
DOMAIN=17
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="eth0"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>'

now_ns() { date +%s%N; }

# run_on NS NAME CMD...: starts CMD on host NS, output to $WORK/NAME.log; sets LAST_PID.
run_on() {
  local ns=$1 name=$2; shift 2
  ip netns exec "$ns" "$@" >"$WORK/$name.log" 2>&1 &
  LAST_PID=$!
  PIDS+=("$LAST_PID")
}

# Observer lines (tests/state_subscriber_main.cc --print), named for the awk conditions below:
#   TAKE_NS PUBLISH_NS VEHICLE STEP SOURCE_ID SEQUENCE SAFE SPEED_KMH
# take: when the observer took the state; pub: when the server wrote it (both this machine's wall
# clock, as `date +%s%N`); src/seq: the input the step applied; safe: the watchdog's safe state.
FIELDS='{ take = $1; pub = $2; step = $4 + 0; src = $5; seq = $6; safe = $7 + 0; ok = (NF == 8) }'

# wait_line FILE FROM_BYTE AWK_CONDITION TIMEOUT_S: polls FILE (bounded) for the first whole line
# after byte FROM_BYTE meeting the condition, and prints it.
wait_line() {
  local file=$1 from=$2 cond=$3 line deadline=$((SECONDS + $4))
  while :; do
    line=$(tail -c +$((from + 1)) "$file" 2>/dev/null | awk "$FIELDS ok && ($cond) { print; exit }" || true)
    [[ -n $line ]] && { echo "$line"; return 0; }
    ((SECONDS < deadline)) || return 1
    sleep 0.05
  done
}
size_of() { stat -c %s "$1"; }

# after_event FILE T0 SOURCE AWK_COND: the first state the server wrote after T0 meeting the
# condition, and the step of the last *new* sample of SOURCE before it (the last input of that rig
# the server applied): prints "EVENT_STEP ANCHOR_STEP EVENT_PUB_NS".
after_event() {
  awk -v t0="$2" -v anchor_src="$3" "$FIELDS
    ok && pub > t0 && ($4) { print step, last, pub; found = 1; exit }
    ok && src == anchor_src && seq != last_seq { last_seq = seq; last = step }
    END { if (!found) print \"none\" }" "$1"
}
# after_time FILE T0 AWK_COND: the first state the server wrote after T0 meeting the condition,
# and the last step it wrote at or before T0: prints "EVENT_STEP STEP_AT_T0 EVENT_PUB_NS".
after_time() {
  awk -v t0="$2" "$FIELDS
    ok && pub <= t0 { at = step }
    ok && pub > t0 && ($3) { print step, at, pub; found = 1; exit }
    END { if (!found) print \"none\" }" "$1"
}
# first_taken FILE T0: the first state the observer took after T0: prints "STEP TAKE_NS".
first_taken() {
  awk -v t0="$2" "$FIELDS
    ok && take > t0 { print step, take; found = 1; exit }
    END { if (!found) print \"none\" }" "$1"
}
ms_between() { echo $((($2 - $1) / 1000000)); }
in_range() { [[ $1 -ge $2 && $1 -le $3 ]]; }

FIGURES=$WORK/figures.txt
: >"$FIGURES"
figure() { echo "  $*" | tee -a "$FIGURES"; }

cut_link() { ip -n "$NS_X" link set "$1" down; }
heal_link() { ip -n "$NS_X" link set "$1" up; }

# ---------------------------------------------------------------------------------------------
# The lab.
echo "multihost: hosts $NS_A (server), $NS_B (primary rig, recorder), $NS_C (backup rig) on 10.231.0.0/24, domain $DOMAIN"
# A long constant maneuver each (a circle at cruise speed), paced by the rig's own clock: a rig cut
# off from the server keeps sending.
printf 't_s,steer_deg,throttle,brake,cruise_kmh\n0,8,0,0,25\n3600,8,0,0,25\n' >"$WORK/primary.csv"
printf 't_s,steer_deg,throttle,brake,cruise_kmh\n0,-8,0,0,15\n3600,-8,0,0,15\n' >"$WORK/backup.csv"

run_on "$NS_A" server "$SERVER" --domain "$DOMAIN" --world flat --no-status
SERVER_PID=$LAST_PID
run_on "$NS_A" observer-a "$OBSERVER" "$DOMAIN" 1000000000 600 --print
OBS_A=$WORK/observer-a.log
run_on "$NS_B" observer-b "$OBSERVER" "$DOMAIN" 1000000000 600 --print
OBS_B=$WORK/observer-b.log
run_on "$NS_B" recorder "$RECORDER" record "$WORK/lab.mcap" --domain "$DOMAIN" --status
RECORDER_PID=$LAST_PID

start_primary() {
  run_on "$NS_B" "primary$1" "$INPUT" --domain "$DOMAIN" --source-id primary --strength 20 --wait 120 \
    play "$WORK/primary.csv" --clock wall
  PRIMARY_PID=$LAST_PID
}
start_backup() {
  run_on "$NS_C" backup "$INPUT" --domain "$DOMAIN" --source-id backup --strength 5 --wait 120 \
    play "$WORK/backup.csv" --clock wall
}
# The backup first: driving alone, it shows the server hears host C before any cut; then the
# primary, stronger, takes the vehicle, and states reach host B across the switch.
start_backup
wait_line "$OBS_A" 0 'src == "backup"' 120 >/dev/null || die "the backup rig never drove (host A's observer: $(tail -n 2 "$OBS_A"))"
FROM=$(size_of "$OBS_A")
start_primary 1
wait_line "$OBS_A" "$FROM" 'src == "primary"' 120 >/dev/null || die "the primary rig never drove (host A's observer: $(tail -n 2 "$OBS_A"))"
wait_line "$OBS_B" 0 'src == "primary"' 60 >/dev/null || die "states never reached host B"
kill -0 "$SERVER_PID" 2>/dev/null || die "the server stopped: $(tail -n 5 "$WORK/server.log")"
echo "multihost: the primary drives; the backup waits on host C"

if [[ $WANT_VIEWER -eq 1 ]]; then
  if [[ -x $VIEWER ]] && command -v Xvfb >/dev/null; then
    # A viewer on host C renders the world and the vehicle it receives across the switch.
    # (The file exists before Xvfb starts: the background shell may not have opened it yet.)
    : >"$WORK/xvfb.display"
    Xvfb -displayfd 1 -screen 0 1280x720x24 -nolisten tcp >>"$WORK/xvfb.display" 2>"$WORK/xvfb.log" &
    XVFB_PID=$!
    XDISP=''
    for _ in $(seq 1 300); do XDISP=$(head -n 1 "$WORK/xvfb.display"); [[ -n $XDISP ]] && break; sleep 0.1; done
    [[ -n $XDISP ]] || die "Xvfb did not report its display"
    run_on "$NS_C" viewer env DISPLAY=":$XDISP" "$VIEWER" --domain "$DOMAIN" --follow 1 \
      --camera chase --width 640 --height 480 --msaa 0 --frames 10 --wait 60 \
      --screenshot "$WORK/viewer-host-c.png" --stats-out "$WORK/viewer-stats.txt"
    VIEWER_PID=$LAST_PID
  else
    echo "multihost: no viewer or Xvfb: the viewer part is skipped"
    WANT_VIEWER=0
  fi
fi

if [[ $WANT_VIEWER -eq 1 ]]; then
  # The viewer ends by itself after its frames: wait for it before the first cut. Starting (its
  # world, its textures) is the heaviest work of the lab's processes; under the sanitizers, beside
  # other tests, it starved the server's state writer during a cut for seconds, the cut outlasted
  # Cyclone's participant lease (10 s) and the recorder lost events (2026-12-06).
  for _ in $(seq 1 1200); do kill -0 "$VIEWER_PID" 2>/dev/null || break; sleep 0.1; done
  wait "$VIEWER_PID" || die "the viewer on host C failed: $(tail -n 5 "$WORK/viewer.log")"
  [[ -s $WORK/viewer-host-c.png ]] || die "the viewer on host C wrote no screenshot"
  # It drew the world and the vehicle that came across the switch, and refused nothing.
  for kv in "frames 10" "worlds_accepted 1" "worlds_refused 0" "vehicles 1" "states_refused 0" "drops_total 0"; do
    grep -qx "$kv" "$WORK/viewer-stats.txt" || die "viewer on host C: expected '$kv' in $(tr '\n' ' ' <"$WORK/viewer-stats.txt")"
  done
  figure "viewer on host C: screenshot $WORK/viewer-host-c.png"
fi

# ---------------------------------------------------------------------------------------------
echo "multihost: 1. cut host B's link with the backup live on host C"
FROM=$(size_of "$OBS_A")
T_CUT1=$(now_ns); cut_link pb
wait_line "$OBS_A" "$FROM" "src == \"backup\" && pub > $T_CUT1" 60 >/dev/null || die "the backup never drove after the cut"
T_HEAL1=$(now_ns)
read -r EV ANCHOR RECV <<<"$(after_event "$OBS_A" "$T_CUT1" primary 'src == "backup"')"
CUT_BACKUP_MS=$((EV - ANCHOR)); CUT_BACKUP_WALL_MS=$(ms_between "$T_CUT1" "$RECV")
figure "cut -> backup driving: $CUT_BACKUP_MS ms simulated after the primary's last sample (the server wrote it $CUT_BACKUP_WALL_MS ms after the cut)"
# The lease follows the watchdog (75 ms for its 100 ms): the backup, live all along, drives before
# the watchdog would brake. Should the server's receiver run late (a loaded machine), the safe
# state may come first for a few steps: reported, not an error. Before the backup, every step
# applies the primary's last input or the safe state, nothing else.
read -r SAFE1 ANCHOR1 _ <<<"$(after_event "$OBS_A" "$T_CUT1" primary 'safe == 1 || src == "backup"')"
OTHER=$(awk -v a="$T_CUT1" -v s="$EV" "$FIELDS"' ok && pub > a && step < s && src != "primary" && !(src == "watchdog" && safe == 1)' "$OBS_A" | wc -l)
[[ $OTHER -eq 0 ]] || die "$OTHER steps applied neither the primary's input nor the safe state before the backup"
if [[ $SAFE1 -lt $EV ]]; then
  CUT_SAFE1_MS=$((SAFE1 - ANCHOR1))
  figure "  meanwhile: safe state from $CUT_SAFE1_MS ms simulated after the primary's last sample until the backup drove"
  in_range "$CUT_SAFE1_MS" 100 1000 || die "cut -> safe state $CUT_SAFE1_MS ms, expected 100..1000 (watchdog 100 ms)"
else
  figure "  meanwhile: no safe state (the backup drove before the watchdog)"
fi

echo "multihost: 2. heal host B's link"
FROM=$(size_of "$OBS_A"); FROM_B=$(size_of "$OBS_B")
T_HEAL1=$(now_ns); heal_link pb
wait_line "$OBS_A" "$FROM" "src == \"primary\" && pub > $T_HEAL1" 60 >/dev/null || die "the primary did not take the vehicle back after the heal"
# A state taken after the heal (one taken before it but written after FROM_B's offset would end
# the wait with nothing for first_taken below: "none", 2026-12-05).
wait_line "$OBS_B" "$FROM_B" "take > $T_HEAL1" 60 >/dev/null || die "states did not reach host B again after the heal"
read -r EV AT RECV <<<"$(after_time "$OBS_A" "$T_HEAL1" 'src == "primary"')"
HEAL_PRIMARY_MS=$(ms_between "$T_HEAL1" "$RECV")
read -r EVB RECVB <<<"$(first_taken "$OBS_B" "$T_HEAL1")"
HEAL_FLOW_MS=$(ms_between "$T_HEAL1" "$RECVB")
figure "heal -> primary's input applied again: $HEAL_PRIMARY_MS ms after the heal ($((EV - AT)) steps)"
figure "heal -> states taken on host B (the recorder's host) again: $HEAL_FLOW_MS ms after the heal"
GAP1_FROM=$(after_time "$OBS_A" "$T_CUT1" 'ok' | cut -d' ' -f2)
GAP1_TO=$EVB

echo "multihost: 3. SIGKILL the primary rig on host B"
FROM=$(size_of "$OBS_A")
T_KILL=$(now_ns); kill -KILL "$PRIMARY_PID"
wait "$PRIMARY_PID" 2>/dev/null || true  # reaped quietly
wait_line "$OBS_A" "$FROM" "src == \"backup\" && pub > $T_KILL" 60 >/dev/null || die "the backup never drove after the primary died"
read -r EV ANCHOR RECV <<<"$(after_event "$OBS_A" "$T_KILL" primary 'src == "backup"')"
DEATH_BACKUP_MS=$((EV - ANCHOR)); DEATH_BACKUP_WALL_MS=$(ms_between "$T_KILL" "$RECV")
figure "primary's death -> backup driving: $DEATH_BACKUP_MS ms simulated after the primary's last sample (the server wrote it $DEATH_BACKUP_WALL_MS ms after the kill)"

echo "multihost: 4. the primary rig comes back on host B; then host C dies (SIGKILL, every process)"
FROM=$(size_of "$OBS_A")
start_primary 2
wait_line "$OBS_A" "$FROM" 'src == "primary"' 120 >/dev/null || die "the restarted primary never drove"
C_PIDS=$(ip netns pids "$NS_C")
[[ -n $C_PIDS ]] || die "nothing runs on host C"
# shellcheck disable=SC2086
kill -KILL $C_PIDS
for p in $C_PIDS; do wait "$p" 2>/dev/null || true; done  # our children: reaped quietly
for _ in $(seq 1 100); do [[ -z $(ip netns pids "$NS_C") ]] && break; sleep 0.1; done
[[ -z $(ip netns pids "$NS_C") ]] || die "host C's processes did not die"

echo "multihost: 5. cut host B's link with no backup"
# The primary still drives (it is the strongest), whatever host C's death.
FROM=$(size_of "$OBS_A")
wait_line "$OBS_A" "$FROM" 'src == "primary"' 30 >/dev/null || die "the primary stopped driving when host C died"
T_CUT2=$(now_ns); cut_link pb
wait_line "$OBS_A" "$FROM" "safe == 1 && pub > $T_CUT2" 60 >/dev/null || die "no safe state after the cut"
read -r EV ANCHOR RECV <<<"$(after_event "$OBS_A" "$T_CUT2" primary 'safe == 1')"
CUT_SAFE_MS=$((EV - ANCHOR))
figure "cut -> safe state (watchdog 100 ms): $CUT_SAFE_MS ms simulated after the primary's last sample (the server wrote it $(ms_between "$T_CUT2" "$RECV") ms after the cut)"
# Nobody else drove in between.
OTHER=$(awk -v a="$T_CUT2" -v s="$EV" "$FIELDS"' ok && pub > a && step < s && src != "primary"' "$OBS_A" | wc -l)
[[ $OTHER -eq 0 ]] || die "$OTHER steps applied another source before the safe state"

echo "multihost: 6. heal host B's link"
FROM=$(size_of "$OBS_A"); FROM_B=$(size_of "$OBS_B")
T_HEAL2=$(now_ns); heal_link pb
wait_line "$OBS_A" "$FROM" "src == \"primary\" && pub > $T_HEAL2" 60 >/dev/null || die "the primary did not take the vehicle back after the second heal"
wait_line "$OBS_B" "$FROM_B" "take > $T_HEAL2" 60 >/dev/null || die "states did not reach host B again after the second heal"
read -r EV AT RECV <<<"$(after_time "$OBS_A" "$T_HEAL2" 'src == "primary"')"
HEAL2_PRIMARY_MS=$(ms_between "$T_HEAL2" "$RECV")
read -r EVB RECVB <<<"$(first_taken "$OBS_B" "$T_HEAL2")"
HEAL2_FLOW_MS=$(ms_between "$T_HEAL2" "$RECVB")
figure "heal -> primary's input applied again (from the safe state): $HEAL2_PRIMARY_MS ms after the heal ($((EV - AT)) steps)"
figure "heal -> states taken on host B again: $HEAL2_FLOW_MS ms after the heal"
GAP2_FROM=$(after_time "$OBS_A" "$T_CUT2" 'ok' | cut -d' ' -f2)
GAP2_TO=$EVB
# The vehicle is driven again: no safe state a little after the primary is back.
FROM=$(size_of "$OBS_A")
wait_line "$OBS_A" "$FROM" 'src == "primary" && safe == 0' 30 >/dev/null || die "the vehicle stayed in its safe state"

# The recorder keeps receiving: a second of states after the heal.
FROM_B=$(size_of "$OBS_B")
wait_line "$OBS_B" "$FROM_B" "step > $((GAP2_TO + 1000))" 60 >/dev/null || die "states stopped on host B after the heal"

# ---------------------------------------------------------------------------------------------
echo "multihost: 7. the recording"
kill -INT "$RECORDER_PID"
for _ in $(seq 1 600); do kill -0 "$RECORDER_PID" 2>/dev/null || break; sleep 0.1; done
wait "$RECORDER_PID" || die "the recorder failed: $(tail -n 5 "$WORK/recorder.log")"
"$RECORDER" info "$WORK/lab.mcap" >"$WORK/info.txt" 2>&1 || die "info failed: $(cat "$WORK/info.txt")"
sed 's/^/    /' "$WORK/info.txt"
# The recorder names the gaps the cuts made: vehicle 1's missing states, the largest starting
# inside one of the cuts (as host A's observer places them in steps).
GAPLINE=$(grep -E '^  vehicle 1: [0-9]+ states missing \(largest gap [0-9]+ steps, from step [0-9]+\)' "$WORK/info.txt") ||
  die "info lists no missing states for vehicle 1"
read -r MISSING LARGEST GAP_AT <<<"$(sed -E 's/.*: ([0-9]+) states missing \(largest gap ([0-9]+) steps, from step ([0-9]+)\).*/\1 \2 \3/' <<<"$GAPLINE")"
figure "recorder (host B): $MISSING states missing, largest gap $LARGEST steps from step $GAP_AT (cuts at steps ~$GAP1_FROM..$GAP1_TO and ~$GAP2_FROM..$GAP2_TO)"
# The cut without a backup lasts at least until the safe state (100 ms), and no cut lasts past
# its heal plus host B's first state.
[[ $LARGEST -ge 100 ]] || die "the largest gap ($LARGEST steps) is shorter than a cut"
in_range "$GAP_AT" $((GAP1_FROM - 50)) "$GAP1_TO" || in_range "$GAP_AT" $((GAP2_FROM - 50)) "$GAP2_TO" ||
  die "the largest gap (from step $GAP_AT) is in neither cut"
# The cuts are short (well under Cyclone's 10 s lease): the reliable events were resent after
# each heal, so the recording still re-simulates, bit for bit over every state it holds. Had
# events been lost, verify must say which and not pass.
if grep -q 'events missing' "$WORK/info.txt"; then
  if "$RECORDER" verify "$WORK/lab.mcap" >"$WORK/verify.txt" 2>&1; then die "verify passed with events missing"; fi
  grep -q 'cannot re-simulate: .*events .* missing' "$WORK/verify.txt" || die "verify: $(cat "$WORK/verify.txt")"
  figure "verify: $(head -n 1 "$WORK/verify.txt")"
else
  "$RECORDER" verify "$WORK/lab.mcap" >"$WORK/verify.txt" 2>&1 || die "verify failed: $(cat "$WORK/verify.txt")"
  grep -q 'bit-exact' "$WORK/verify.txt" || die "verify: $(cat "$WORK/verify.txt")"
  figure "verify: $(grep 'bit-exact' "$WORK/verify.txt" | head -n 1)"
fi

# The server went through it all and stops cleanly when asked.
kill -INT "$SERVER_PID"
for _ in $(seq 1 600); do kill -0 "$SERVER_PID" 2>/dev/null || break; sleep 0.1; done
wait "$SERVER_PID" || die "the server did not stop cleanly (exit $?): $(tail -n 5 "$WORK/server.log")"

# ---------------------------------------------------------------------------------------------
# Bounds that hold on a loaded 2-core machine. The lease counts in the server's wall clock from
# the primary's last sample's arrival: a server loop running behind real time (seconds, under
# the sanitizers beside other tests) catches up through the lease in a few steps (3 simulated ms
# after a kill, 2.2 s after it in wall time, CI 2026-12-05). So the backup must not have driven
# early by either clock: at least half the lease in simulated time after the primary's last
# sample, or in wall time after the cut or kill (the last sample left at most a tick before it).
# Upper bound: simulated time only (the watchdog's 100 ms counts in steps).
backup_not_early() { [[ $1 -ge 37 || $2 -ge 37 ]] && [[ $1 -le 2000 ]]; }
backup_not_early "$CUT_BACKUP_MS" "$CUT_BACKUP_WALL_MS" ||
  die "cut -> backup $CUT_BACKUP_MS ms simulated, $CUT_BACKUP_WALL_MS ms wall, expected 37..2000 simulated or at least 37 wall (lease 75 ms)"
backup_not_early "$DEATH_BACKUP_MS" "$DEATH_BACKUP_WALL_MS" ||
  die "death -> backup $DEATH_BACKUP_MS ms simulated, $DEATH_BACKUP_WALL_MS ms wall, expected 37..2000 simulated or at least 37 wall (lease 75 ms)"
in_range "$CUT_SAFE_MS" 100 1000 || die "cut -> safe state $CUT_SAFE_MS ms, expected 100..1000 (watchdog 100 ms)"
for v in "$HEAL_PRIMARY_MS" "$HEAL_FLOW_MS" "$HEAL2_PRIMARY_MS" "$HEAL2_FLOW_MS"; do
  in_range "$v" 0 30000 || die "a heal took $v ms to show (expected under 30 s)"
done

echo "multihost: figures"
cat "$FIGURES"
OK=1
echo "multihost: PASS"
