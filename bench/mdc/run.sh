#!/usr/bin/env bash
# bench/mdc: Haas MDC polling. Builds nothing: runs the binaries of BUILD_DIR (default .build).
#   1. poll rate of the MDC core (bench_mdc_poll: the poller haas_mdc_node runs, periods 0) against
#      sim_haas_mdc, side by side with the reference peer, a plain blocking Python poller
#      (peer_poll.py, the way small MTConnect adapters poll MDC): ratio core / peer.
#   2. haas_mdc_node under ROS: status-change-to-`state`-message latency at the default poll period
#      (0.25 s), compared with the expected half period; and the queries per second the node has
#      answered (counted by the simulator) with every period at 1 ms.
# MDC_BENCH_SECONDS (default 10) sets the length of each measurement.
set -eo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
root=$(cd "$(dirname "$0")/../.." && pwd)
source "$root/scripts/env.sh"
build=${BUILD_DIR:-$root/.build}
source "$build/devel/setup.bash"
set -u
bin="$build/devel/lib/cnc_bridge"
seconds=${MDC_BENCH_SECONDS:-10}
here="$root/bench/mdc"
tmp=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$tmp"; }
trap cleanup EXIT

start_sim() {  # start_sim NAME -> port in $port
  "$bin/sim_haas_mdc" --script "$here/toggle.mdcsim" >"$tmp/$1.out" 2>"$tmp/$1.err" &
  pids+=($!)
  for _ in $(seq 100); do [[ -s "$tmp/$1.out" ]] && break; sleep 0.05; done
  port=$(head -1 "$tmp/$1.out" | sed 's/.*://')
}

echo "--- poll rate against sim_haas_mdc (Q500, Q104 and 6 position variables, back to back, ${seconds} s)"
start_sim rate_core
core=$("$bin/bench_mdc_poll" 127.0.0.1 "$port" "$seconds" 6)
start_sim rate_peer
peer=$(python3 "$here/peer_poll.py" 127.0.0.1 "$port" "$seconds")
printf "%-28s %s\n" "cnc_bridge mdc core:" "$core" "python blocking peer:" "$peer"
core_rate=$(sed -E 's/.* ([0-9]+) queries\/s.*/\1/' <<<"$core")
peer_rate=$(sed -E 's/.* ([0-9]+) queries\/s.*/\1/' <<<"$peer")
python3 -c "print('ratio core/peer (queries/s): %.2f' % ($core_rate / max($peer_rate, 1)))"

echo "--- haas_mdc_node: status change -> state message (default periods), ${seconds}x3 s"
master_port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
export ROS_MASTER_URI=http://127.0.0.1:$master_port
roscore -p "$master_port" >"$tmp/roscore.log" 2>&1 &
pids+=($!)
for _ in $(seq 100); do rostopic list >/dev/null 2>&1 && break; sleep 0.1; done
start_sim latency
"$bin/haas_mdc_node" __name:=mdc_default __ns:=/bench_default _host:=127.0.0.1 _tcp_port:="$port" \
  >"$tmp/node_default.log" 2>&1 &
pids+=($!)
default=$(python3 "$here/node_latency.py" /bench_default "$tmp/latency.err" $((seconds * 3)) 1.3)
echo "node (status_period 0.25 s): $default"
mean=$(sed -E 's/.*latency mean ([0-9.]+) ms.*/\1/' <<<"$default")
python3 -c "print('ratio mean latency / expected (half period 125 ms): %.2f' % ($mean / 125.0))"

echo "--- haas_mdc_node: queries answered per second with every period at 1 ms, ${seconds} s"
start_sim fast
sim_pid=${pids[-1]}
"$bin/haas_mdc_node" __name:=mdc_fast __ns:=/bench_fast _host:=127.0.0.1 _tcp_port:="$port" \
  _status_period:=0.001 _variables_period:=0.001 _counters_period:=0.001 >"$tmp/node_fast.log" 2>&1 &
pids+=($!)
sleep "$seconds"
kill "$sim_pid"
wait "$sim_pid" 2>/dev/null || true
fast=$(grep -E "answered [0-9]+ queries" "$tmp/fast.err" | sed -E 's/.*answered ([0-9]+) queries in ([0-9.]+) s.*/\1 \2/')
node_rate=$(python3 -c "n, t = '$fast'.split(); print('%.0f' % (int(n) / float(t)))")
echo "node (periods 1 ms, 11 queries): $node_rate queries/s answered by the simulator"
python3 -c "print('ratio node/peer (queries/s): %.2f' % ($node_rate / max($peer_rate, 1)))"
bench_done
