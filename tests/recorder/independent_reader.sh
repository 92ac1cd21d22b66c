#!/usr/bin/env bash
# The recordings open in the tools users already have: a live session (server, vdyn-input's demo
# drive) recorded with zstd, lz4 and no compression, split by time, and killed with SIGKILL then
# recovered, each read back by the MCAP project's own library from npm (read_mcap.js: CRCs checked,
# every message decoded by the schema in the file).
# Usage: independent_reader.sh BUILD_DIR SOURCE_DIR
set -euo pipefail
build="$1"
src="$2"
work="$build/tests/mcap_js"
mkdir -p "$work"
cp "$src/package.json" "$src/read_mcap.js" "$work/"
if ! command -v npm >/dev/null 2>&1; then
  echo "independent_reader.sh: npm is needed (Node.js 20 with npm) to install @mcap/core" >&2
  exit 1
fi
if [ ! -f "$work/node_modules/@mcap/core/package.json" ] || [ "$work/package.json" -nt "$work/node_modules/.installed" ]; then
  (cd "$work" && npm install --no-audit --no-fund --loglevel=error >npm.log 2>&1) || { cat "$work/npm.log"; exit 1; }
  touch "$work/node_modules/.installed"
fi
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>'
# A domain of 100..229 that no other test holds (the lock files tests/foxglove/run.sh and the
# C++ tests take; released when this script exits).
. "$(dirname "$0")/../domain-lock.sh"
out="$work/rec"
rm -rf "$out"
mkdir -p "$out"
rec="$build/clients/recorder/vdyn-recorder"
pids=()
cleanup() { for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
"$rec" record "$out/zstd.mcap" --domain "$domain" --duration 6 --no-status >"$out/zstd.log" 2>&1 & pids+=($!)
"$rec" record "$out/lz4.mcap" --domain "$domain" --duration 6 --compression lz4 --no-status >"$out/lz4.log" 2>&1 & pids+=($!)
"$rec" record "$out/none.mcap" --domain "$domain" --duration 6 --compression none --no-status >"$out/none.log" 2>&1 & pids+=($!)
"$rec" record "$out/split.mcap" --domain "$domain" --duration 6 --split-s 2 --no-status >"$out/split.log" 2>&1 & pids+=($!)
"$rec" record "$out/killed.mcap" --domain "$domain" --no-status >"$out/killed.log" 2>&1 & killed=$!; pids+=($killed)
"$build/server/vdyn-server" --domain "$domain" --world facility --duration 4.5 --no-status >"$out/server.log" 2>&1 & pids+=($!)
"$build/clients/wheel_input/vdyn-input" --domain "$domain" --maneuver demo --wait 20 >"$out/input.log" 2>&1 & pids+=($!)
for p in "${pids[@]:0:4}"; do wait "$p"; done
kill -9 "$killed"
wait "$killed" 2>/dev/null || true
"$rec" recover "$out/killed.mcap" -o "$out/recovered.mcap"
# A recording with a byte changed in its middle (a chunk's CRC fails), recovered.
cp "$out/zstd.mcap" "$out/damaged.mcap"
at=$(($(stat -c %s "$out/damaged.mcap") / 2))
byte=$(od -An -tu1 -j "$at" -N1 "$out/damaged.mcap" | tr -d ' ')
printf "$(printf '\\%03o' $((byte ^ 64)))" | dd of="$out/damaged.mcap" bs=1 seek="$at" conv=notrunc status=none
"$rec" recover "$out/damaged.mcap" -o "$out/damaged-recovered.mcap"
files=("$out/zstd.mcap" "$out/lz4.mcap" "$out/none.mcap" "$out"/split-*.mcap "$out/recovered.mcap"
       "$out/damaged-recovered.mcap")
node "$work/read_mcap.js" "${files[@]}" | tee "$out/read.json"
# Every file was read (the script stops at the first problem), with states in it.
test "$(grep -c '"vdyn.pb.VehicleState"\|\.vdyn\.pb\.VehicleState' "$out/read.json")" -eq "${#files[@]}"
# A drive whose chunks carry no CRC, with a byte changed: recovered, its chunks stay without a CRC
# and the copy has no data-section CRC (it would vouch for them) - which MCAP allows.
"$rec" recover "$src/../fuzz/corpus/recover_verify/drive-nocrc-flipped.mcap" -o "$out/unchecked.mcap"
NO_DATA_CRC_EXPECTED=1 node "$work/read_mcap.js" "$out/unchecked.mcap" | tee -a "$out/read.json"
echo "independent reader: $((${#files[@]} + 1)) recordings read and decoded"
