#!/usr/bin/env bash
# Builds the release configuration and runs every benchmark, writing the results to
# bench/results/<date>-<machine tag>.txt. The tag is made of the CPU model and the number of CPUs
# (never the host name), so results from one kind of machine sort together.
# Usage: bench/run.sh [extra Google Benchmark flags for bench_core, e.g. --benchmark_filter=step]
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh release

bin=build/release/bench
cpu_model=$(grep -m1 '^model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ *//')
cpus=$(nproc)
tag=$(printf '%s-%scpu' "$cpu_model" "$cpus" | tr 'A-Z' 'a-z' | tr -c 'a-z0-9\n' '-' | tr -s '-')
mkdir -p bench/results
out="bench/results/$(date +%Y-%m-%d)-${tag}.txt"

run() {  # prints the command, then runs it
  echo
  echo "\$ $*"
  "$@"
}

{
  echo "vdyn benchmarks, $(date -u +%Y-%m-%dT%H:%MZ)"
  echo "commit:   $(git rev-parse --short HEAD 2>/dev/null || echo unknown)$([ -z "$(git status --porcelain -- server bench 2>/dev/null)" ] || echo ' + local changes in server/ or bench/')"
  echo "cpu:      $cpu_model, nproc $cpus"
  echo "kernel:   $(uname -sr)"
  echo "compiler: $(c++ --version | head -1)"
  run "$bin/bench_core" --benchmark_repetitions=5 --benchmark_report_aggregates_only=true "$@"
  run "$bin/step_latency" 200000
  run "$bin/batch_rtf" 5
  run "$bin/step_sweep" --model full
  run "$bin/step_sweep" --model paper
  run "$bin/net_bench" 60 20
  run "$bin/request_bench" 20 3
  run "$bin/input_bench" 30
  run "$bin/recorder_bench" 30 3
  run "$bin/follow_bench" 10 3
  run "$bin/follow_bench" 10 3 256 1,2   # 256 vehicles stepped by 1 and by 2 threads
  run bench/recorder_scale.sh 128 2 10
  run bench/rigs_and_recorder.sh 128 default 10   # the server, a recorder and 8 rigs together
  run /usr/bin/python3 bench/python_reader_cost.py build/release 128 3
  # VDYN_VIEWER_PEER: an earlier vdyn-viewer built apart, measured in the same run as the peer.
  run "$bin/viewer_bench" 3 300 ${VDYN_VIEWER_PEER:+"$VDYN_VIEWER_PEER"}
  run "$bin/foxglove_bench" 10 3
  PYTHONPATH=build/release/clients/python/package run /usr/bin/python3 bench/python_bench.py build/release 60 600
} 2>&1 | grep -v 'is not multicast-capable' | tee "$out"
echo "results written to $out"
