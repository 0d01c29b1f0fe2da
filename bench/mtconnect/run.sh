#!/usr/bin/env bash
# bench/mtconnect: from a data item's change at a real agent to the ROS topic. Builds nothing:
# runs mtconnect_node of BUILD_DIR (default .build) and the reference agent (cppagent v1.8.0.3,
# scripts/build_cppagent.sh; CNC_MTCONNECT_AGENT overrides where it is).
#   An SHDR source (source.py) feeds the agent the mill of test/data/mtconnect/recording/ and
#   changes Xact RATE times a second; mtconnect_node follows the agent's stream (interval 10 ms)
#   and a subscriber times each change to its `state` message (node_latency.py). In the same run,
#   side by side, the peer a user would otherwise write, a Python client polling /current back to
#   back (peer_poll.py), and one polling every 100 ms, time the same changes. Reported: latency p50/p99 of each, and CPU per
#   1,000 changes delivered (the node's process CPU in the measured window; the poller's own).
# MTCONNECT_BENCH_SECONDS (default 20) and MTCONNECT_BENCH_RATE (changes/s, default 50).
set -eo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
root=$(cd "$(dirname "$0")/../.." && pwd)
source "$root/scripts/env.sh"
build=${BUILD_DIR:-$root/.build}
source "$build/devel/setup.bash"
set -u
bin="$build/devel/lib/cnc_bridge"
agent=${CNC_MTCONNECT_AGENT:-/usr/local/lib/cnc_bridge/cppagent-1.8.0.3/agent}
seconds=${MTCONNECT_BENCH_SECONDS:-20}
rate=${MTCONNECT_BENCH_RATE:-50}
warmup=5
here="$root/bench/mtconnect"
tmp=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$tmp"; }
trap cleanup EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }

[[ -x "$agent" ]] || { bench_failed "the reference agent is not at $agent (scripts/build_cppagent.sh builds it)"; bench_done; }
adapter_port=$(free_port)
agent_port=$(free_port)
cp "$root/test/data/mtconnect/recording/Devices.xml" "$tmp/"
cat >"$tmp/agent.cfg" <<CFG
Devices = Devices.xml
Port = $agent_port
ServerIp = 127.0.0.1
SchemaVersion = 1.7
ReconnectInterval = 200
MonitorConfigFiles = false
Adapters {
   mill {
      Host = 127.0.0.1
      Port = $adapter_port
   }
}
logger_config {
    output = file agent.log
    logging_level = warn
}
CFG

master_port=$(free_port)
export ROS_MASTER_URI=http://127.0.0.1:$master_port
roscore -p "$master_port" >"$tmp/roscore.log" 2>&1 &
pids+=($!)
for _ in $(seq 100); do rostopic list >/dev/null 2>&1 && break; sleep 0.1; done

python3 "$here/source.py" "$adapter_port" "$rate" "$seconds" "$warmup" "$tmp/changes.log" &
pids+=($!)
(cd "$tmp" && exec "$agent" run agent.cfg >/dev/null 2>&1) &
pids+=($!)
"$bin/mtconnect_node" __name:=mtconnect_bench __ns:=/bench _host:=127.0.0.1 _tcp_port:="$agent_port" \
  _interval:=0.01 _heartbeat:=1.0 >"$tmp/node.log" 2>&1 &
node_pid=$!
pids+=($node_pid)
python3 "$here/node_latency.py" /bench $((warmup + seconds + 3)) "$tmp/changes.log" >"$tmp/node.out" 2>&1 &
latency_pid=$!
python3 "$here/peer_poll.py" "http://127.0.0.1:$agent_port" $((warmup + seconds + 3)) 0 "$tmp/changes.log" \
  >"$tmp/peer.out" 2>&1 &
peer_pid=$!
python3 "$here/peer_poll.py" "http://127.0.0.1:$agent_port" $((warmup + seconds + 3)) 0.1 "$tmp/changes.log" \
  >"$tmp/peer_paced.out" 2>&1 &
paced_pid=$!
sleep "$warmup"  # the source's warm-up: everyone connected and reading before the first change
node_cpu_start=$(cpu_ticks "$node_pid")
sleep "$seconds"  # the measured window: the source changing Xact
node_cpu_end=$(cpu_ticks "$node_pid")
wait "$latency_pid" || bench_failed "node latency: $(cat "$tmp/node.out")"
wait "$peer_pid" || bench_failed "python poller: $(cat "$tmp/peer.out")"
wait "$paced_pid" || bench_failed "python poller every 100 ms: $(cat "$tmp/peer_paced.out")"
[[ $bench_status -eq 0 ]] || bench_done
node=$(tail -1 "$tmp/node.out")
peer=$(tail -1 "$tmp/peer.out")
paced=$(tail -1 "$tmp/peer_paced.out")
echo "--- ${rate} changes/s for ${seconds} s, agent cppagent 1.8.0.3 on loopback"
printf "%-38s %s\n" "mtconnect_node (stream, 10 ms):" "$node" "python poller (/current, no pause):" "$peer" \
  "python poller (/current every 100 ms):" "$paced"
ticks=$(getconf CLK_TCK)
python3 - "$node" "$peer" "$((node_cpu_end - node_cpu_start))" "$ticks" "$paced" <<'PY'
import re, sys
node, peer, node_ticks, hz, paced = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
def grab(text, key):
    return float(re.search(key + r" (-?[0-9.]+)", text).group(1))
node_changes, peer_changes = grab(node, "changes"), grab(peer, "changes")
node_cpu = node_ticks * 1000.0 / hz
peer_cpu = grab(peer, "cpu")
print("latency p50: node %.1f ms, poller %.1f ms (ratio poller/node %.1f)"
      % (grab(node, "p50"), grab(peer, "p50"), grab(peer, "p50") / max(grab(node, "p50"), 0.1)))
print("latency p99: node %.1f ms, poller %.1f ms (ratio poller/node %.1f)"
      % (grab(node, "p99"), grab(peer, "p99"), grab(peer, "p99") / max(grab(node, "p99"), 0.1)))
print("changes delivered: node %d, poller %d" % (node_changes, peer_changes))
print("CPU per 1,000 changes delivered: node %.0f ms, poller %.0f ms (ratio poller/node %.1f)"
      % (node_cpu * 1000 / max(node_changes, 1), peer_cpu * 1000 / max(peer_changes, 1),
         (peer_cpu / max(peer_changes, 1)) / max(node_cpu / max(node_changes, 1), 1e-9)))
print("poller every 100 ms: latency p50 %.1f ms, p99 %.1f ms, %d changes delivered, CPU per 1,000 %.0f ms"
      % (grab(paced, "p50"), grab(paced, "p99"), grab(paced, "changes"),
         grab(paced, "cpu") * 1000 / max(grab(paced, "changes"), 1)))
PY
bench_done
