#!/usr/bin/env bash
# Scale of one cell on this machine: N machines (default 10) of the demo's four kinds, each with
# its simulators, nodes and model, launched together; then every state topic's rate and every
# process's CPU and memory over a window. usage: bench/cell/run.sh [N] [SECONDS]
set -uo pipefail
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
# Give every node time to connect to its simulator before measuring.
python3 - "$work/cell.yaml" <<'PY'
import sys, time, yaml, rospy
from cnc_bridge.msg import MachineState
d = yaml.safe_load(open(sys.argv[1]))
rospy.init_node("wait_cell", anonymous=True)
for m in d["machines"]:
    for n in m["nodes"]:
        topic = "/cell/%s/%s" % (m["name"], n.get("remap", {}).get("state", "state"))
        deadline = time.time() + 60
        while time.time() < deadline:
            s = rospy.wait_for_message(topic, MachineState, timeout=60)
            if s.link == MachineState.LINK_UP or n["launch"] == "dnc_node":
                break
            time.sleep(0.5)
        print("%-35s link %d" % (topic, s.link))
PY
echo "machines: $count; measuring ${seconds}s; load before: $(cut -d' ' -f1-3 /proc/loadavg)"
python3 "$here/measure_cell.py" "$work/cell.yaml" "$seconds"
