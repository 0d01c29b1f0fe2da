#!/usr/bin/env bash
# Steps per second of 8-slave step frames to sim_slave_bus on a pty and back:
#  1. the core BusSession, unpaced (pty speed) and at a simulated 115200 baud (both directions
#     timed as a UART: a byte reaches the peer when the line would have finished it), raw and
#     framed, with the line-rate bound and the fraction of it reached over the whole run and at
#     the median step;
#  2. the same through slave_bus_node (rospy publisher -> node -> pty -> simulator -> 8 response
#     topics), raw, side by side with the core session as a ratio.
# Builds nothing: runs BUILD_DIR's binaries. usage: BUILD_DIR=.build bench/slave_bus/run.sh [STEPS]
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${BUILD_DIR:-$root/.build}
steps=${1:-2000}
bin() { for d in "$build/devel/lib/cnc_bridge" "$build/bin"; do [[ -x "$d/$1" ]] && { echo "$d/$1"; return; }; done; echo "missing $1 in $build" >&2; exit 1; }
sim=$(bin sim_slave_bus)
bench=$(bin bench_slave_bus)
tmp=$(mktemp -d /tmp/bench_slave_bus.XXXXXX)
pids=()
echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$tmp"; }
trap cleanup EXIT
start_sim() { # link framing baud
  "$sim" --link "$1" --framing "$2" --baud "$3" >"$tmp/sim.log" 2>&1 &
  pids+=($!)
  for _ in $(seq 100); do [[ -e $1 ]] && return; sleep 0.05; done
  echo "sim_slave_bus did not start" >&2; exit 1
}
run() { # framing baud steps
  local link=$tmp/link_$1_$2
  start_sim "$link" "$1" "$2"
  "$bench" --port "$link" --framing "$1" --baud "$2" --steps "$3" >"$tmp/core_$1_$2.txt" 2>&1 ||
    bench_failed "the core session ($1, $2 baud): $(tail -1 "$tmp/core_$1_$2.txt")"
  cat "$tmp/core_$1_$2.txt"
  kill "${pids[-1]}"; wait "${pids[-1]}" 2>/dev/null || true
}
for framing in raw framed; do
  run "$framing" 0 "$steps"
  run "$framing" 115200 $((steps / 4))
done

# Through the node (needs the devel space of a full build: messages for rospy, the node).
if [[ -f "$build/devel/setup.bash" && -x "$build/devel/lib/cnc_bridge/slave_bus_node" ]]; then
  set +u  # the ROS setup scripts read unset variables
  source "$root/scripts/env.sh"
  source "$build/devel/setup.bash"
  set -u
  export ROS_MASTER_URI=http://127.0.0.1:$((20000 + RANDOM % 20000))
  roscore -p "${ROS_MASTER_URI##*:}" >"$tmp/roscore.log" 2>&1 &
  pids+=($!)
  for _ in $(seq 100); do rostopic list >/dev/null 2>&1 && break; sleep 0.1; done
  link=$tmp/link_node
  start_sim "$link" raw 0
  rosparam load "$root/config/slave_bus_example.yaml" /slave_bus_node
  "$build/devel/lib/cnc_bridge/slave_bus_node" _port:="$link" _enable_motion:=true >"$tmp/node.log" 2>&1 &
  pids+=($!)
  node_steps=$((steps / 4))
  if python3 "$root/bench/slave_bus/node_steps.py" "$node_steps" >"$tmp/node.txt" 2>&1; then
    cat "$tmp/node.txt"
    core=$(grep -oE 'steps/s: [0-9.]+' "$tmp/core_raw_0.txt" | grep -oE '[0-9.]+$')
    node=$(grep -oE 'steps/s: [0-9.]+' "$tmp/node.txt" | grep -oE '[0-9.]+$')
    awk -v n="$node" -v c="$core" 'BEGIN { printf "node vs core session (raw, pty): %.1f vs %.1f steps/s = %.3f\n", n, c, n / c }'
  else
    cat "$tmp/node.txt"
    bench_failed "the steps through slave_bus_node (output above; node log $tmp/node.log)"
  fi
else
  echo "(no devel space with slave_bus_node in $build: node benchmark skipped)"
fi
bench_done
