#!/usr/bin/env bash
# Steps per second of 8-slave step frames, PC session -> sim_slave_bus on a pty -> answers back:
# unpaced (pty speed) and at a simulated 115200 baud (both directions paced), raw and framed,
# printed side by side with the line-rate bound as a ratio. Builds nothing: runs BUILD_DIR's binaries.
# usage: BUILD_DIR=/work/main/.build bench/slave_bus/run.sh [STEPS]
set -euo pipefail
build=${BUILD_DIR:-/work/main/.build}
steps=${1:-2000}
bin() { for d in "$build/devel/lib/cnc_bridge" "$build/bin"; do [[ -x "$d/$1" ]] && { echo "$d/$1"; return; }; done; echo "missing $1 in $build" >&2; exit 1; }
sim=$(bin sim_slave_bus)
bench=$(bin bench_slave_bus)
run() { # framing baud steps
  local link=/tmp/bench_slave_bus_$$_$1_$2
  "$sim" --link "$link" --framing "$1" --baud "$2" >/tmp/bench_slave_bus_$$.log 2>&1 &
  local pid=$!
  for _ in $(seq 100); do [[ -e $link ]] && break; sleep 0.05; done
  "$bench" --port "$link" --framing "$1" --baud "$2" --steps "$3" || true
  kill "$pid"; wait "$pid" 2>/dev/null || true
}
for framing in raw framed; do
  run "$framing" 0 "$steps"
  run "$framing" 115200 $((steps / 4))
done
