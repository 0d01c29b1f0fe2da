#!/usr/bin/env bash
# Scale of one cell on this machine: N machines (default 10) of the demo's four kinds, each with
# its simulators, nodes and model, launched together; then every state topic's rate and every
# process's CPU and memory over a window. Fails if a node's link is not UP before the window
# (60 s to connect) or at any moment in it, or a state topic is below 9 Hz.
# usage: bench/cell/run.sh [N] [SECONDS]
set -uo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
source "$root/scripts/env.sh"
set +u  # ROS setup scripts read unset variables
source "${BUILD_DIR:-$root/.build}/devel/setup.bash"
set -u
count=${1:-10}
seconds=${2:-30}
work=$(mktemp -d /tmp/cnc_scale.XXXXXX)
python3 "$here/make_cell.py" "$count" >"$work/cell.yaml"
python3 "$root/scripts/cell_launch.py" "$work/cell.yaml" -o "$work/cell.launch"
roslaunch "$work/cell.launch" >"$work/roslaunch.log" 2>&1 &
launch=$!
trap 'kill -INT $launch 2>/dev/null; wait $launch 2>/dev/null' EXIT
# Every node must connect to its simulator (link UP) before measuring.
python3 - "$work/cell.yaml" <<'PY' || { echo "FAIL: not every node's link came UP (log: $work/roslaunch.log)"; exit 1; }
import sys, time, yaml, rospy
from cnc_bridge.msg import MachineState
d = yaml.safe_load(open(sys.argv[1]))
rospy.init_node("wait_cell", anonymous=True)
deadline = time.time() + 60
down = []
for m in d["machines"]:
    for n in m["nodes"]:
        topic = "/cell/%s/%s" % (m["name"], n.get("remap", {}).get("state", "state"))
        s = None
        while time.time() < deadline:
            try:
                s = rospy.wait_for_message(topic, MachineState, timeout=max(deadline - time.time(), 0.5))
            except rospy.ROSException:
                break
            if s.link == MachineState.LINK_UP:
                break
            time.sleep(0.5)
        up = s is not None and s.link == MachineState.LINK_UP
        print("%-35s %s" % (topic, "UP" if up else "NOT UP (%s)" % (s.message if s else "no state")))
        if not up:
            down.append(topic)
sys.exit(1 if down else 0)
PY
echo "machines: $count; measuring ${seconds}s; load before: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 "$here/measure_cell.py" "$work/cell.yaml" "$seconds"
[[ $? -eq 0 ]] || bench_failed "measure_cell.py (output above)"
bench_done
