#!/usr/bin/env bash
# DPRNT benchmarks (builds nothing; runs binaries from BUILD_DIR, default .build/):
#   1. parser throughput on one core: bench_dprnt_parser (the parser alone, line assembly + parser,
#      and parse + rules, which is what the node does per line), side by side with the peer a shop
#      would otherwise use, a Python loop over a regular expression, and with the goal (1,000,000 lines/s);
#   2. latency from the simulator's write to a subscriber at 100 lines/s over a pty, p50/p99, against
#      the goal p99 < 2 ms.
# usage: BUILD_DIR=.build bench/dprnt/run.sh [LINES] [SAMPLES]
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${BUILD_DIR:-$root/.build}
lines=${1:-2000000}
samples=${2:-2000}
set +u  # ROS setup scripts read unset variables
source "$root/scripts/env.sh"
bin=$build/devel/lib/cnc_bridge
[[ -x $bin/bench_dprnt_parser ]] || bin=$build/bin

echo "== parser throughput (one core, taskset -c 0)"
ours=$(taskset -c 0 "$bin/bench_dprnt_parser" "$lines")
echo "$ours"
peer=$(taskset -c 0 python3 - <<'PY'
import re, time
mix = ["PROBE X   0.5000 Y   1.0000 Z  -0.0120", "X1.5436 Z 1.544 T 1", "Z OFFSET IS   -0.0125",
       "#5223   -0.0125", "  -0.0125", "CYCLE END O01000 PARTS      1"]
pair = re.compile(r"([A-Z#][A-Z0-9# ]*?)?\s*([-+]?\d*\.?\d+)")
n = 300000
start = time.perf_counter()
for i in range(n):
    [(m.group(1) or "", float(m.group(2))) for m in pair.finditer(mix[i % 6])]
print("%.0f" % (n / (time.perf_counter() - start)))
PY
)
parse=$(echo "$ours" | awk '/^parse [0-9]/ {print $2}')
full=$(echo "$ours" | awk '/^assemble\+parse/ {print $2}')
rules=$(echo "$ours" | awk '/^parse\+rules/ {print $2}')
# The node's real cost per line is the last row: parse plus the rules that turn values into topics.
# The peer is a Python loop over a regular expression (what a shop script would do), one core too.
row() { printf "%-40s %14.0f %14.1f %14.2f\n" "$1" "$2" "$(echo "$2 / $peer" | bc -l)" "$(echo "$2 / 1000000" | bc -l)"; }
echo "date $(date -u '+%Y-%m-%d %H:%M UTC'), load average $(cut -d' ' -f1-3 /proc/loadavg)"
printf "%-40s %14s %14s %14s\n" "" "lines/s" "x python loop" "x goal 1e6"
row "cnc_bridge parse (parser only)" "$parse"
row "cnc_bridge assemble+parse" "$full"
row "cnc_bridge parse + rules (node per line)" "$rules"
row "python re loop (peer)" "$peer"

echo "== latency at 100 lines/s over a pty ($samples samples)"
source "$build/devel/setup.bash"
set -u
export ROS_MASTER_URI=http://127.0.0.1:$((20000 + RANDOM % 20000))
port=${ROS_MASTER_URI##*:}
link=/tmp/bench_dprnt_$$
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT
roscore -p "$port" >/dev/null 2>&1 & pids+=($!)
until rosparam list >/dev/null 2>&1; do sleep 0.2; done
"$bin/sim_haas_serial" dprnt --program "$root/config/dprnt/latency.nc" --link "$link" --rate 100 >/dev/null & pids+=($!)
until [[ -e $link ]]; do sleep 0.05; done
"$bin/dprnt_node" __ns:=/bench __name:=dprnt_node _port:="$link" _baud:=115200 _rules:="" >/dev/null 2>&1 & pids+=($!)
result=$(python3 "$root/bench/dprnt/latency.py" /bench "$samples")
echo "$result"
p99=$(echo "$result" | awk '{print $5}')
printf "%-28s %10s %10s\n" "" "p99 ms" "x goal 2ms"
printf "%-28s %10.3f %10.2f\n" "dprnt_node over pty" "$p99" "$(echo "$p99 / 2" | bc -l)"
bench_done
