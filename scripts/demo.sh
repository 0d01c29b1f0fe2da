#!/usr/bin/env bash
# The simulated cell (`make demo`): the machines of config/cell.yaml with their simulators, nodes
# and models (launch/cell.launch), a rosbag of the run, and the scripted scenario of
# scripts/cell_demo.py printing what happens. Ctrl-C, or SIGTERM to this script, stops everything.
#   GUI=1          also open rviz with rviz/cell.rviz
#   DEMO_ONCE=1    stop after the scenario (exit status: the scenario's)
#   DEMO_OUTPUT=D  output folder (default output/demo-<time>)
set -eo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/env.sh"
source "$root/.build/devel/setup.bash"
# The cell's mtconnect_mill is served by the reference MTConnect agent, which scripts/setup.sh builds.
agent=${CNC_MTCONNECT_AGENT:-/usr/local/lib/cnc_bridge/cppagent-1.8.0.3/agent}
if [[ ! -x "$agent" ]]; then
  echo "demo: the MTConnect agent (cppagent 1.8.0.3) is not at $agent, and the cell's mtconnect_mill needs it:" \
    "run scripts/setup.sh (it builds the agent with scripts/build_cppagent.sh) or set CNC_MTCONNECT_AGENT" >&2
  exit 1
fi
gui=false
[[ "${GUI:-0}" == "1" ]] && gui=true
out=${DEMO_OUTPUT:-$root/output/demo-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$out/programs" "$out/haas_vf2_memory"
# The program the VF-2 runs (sim_mdc names it O01000, sim_dprnt prints its probe output) in the
# cell's program folder, as a shop keeps its machines' programs: cell_monitor's countdown looks it up.
cp "$root/config/dprnt/grid_probe.nc" "$out/programs/O01000.nc"
out=$(cd "$out" && pwd)
export CNC_DEMO_DIR=$out
echo "demo: output folder $out (rosbag, surface map, logs)"

export ROS_LOG_DIR=$out/logs
roslaunch cnc_bridge cell.launch gui:=$gui record:=true bag:="$out/cell.bag" >"$out/roslaunch.log" 2>&1 &
launch_pid=$!
stop() {
  kill -INT "$launch_pid" 2>/dev/null || true
  wait "$launch_pid" 2>/dev/null || true
}
trap stop EXIT

once=()
[[ "${DEMO_ONCE:-0}" == "1" ]] && once=(--once)
set +e
# The scenario runs in the background and this script waits for it, so that a SIGTERM or SIGINT
# sent to this script alone (kill PID, not only Ctrl-C at the terminal) stops it at once: bash runs
# a trap only once the foreground command has ended, but it interrupts a `wait`.
python3 "$root/scripts/cell_demo.py" --cell "$root/config/cell.yaml" --output "$out" --programs "$out/programs" \
  --program "$root/config/demo/O05555.nc" --job "$root/config/demo/ethernut_job.nc" \
  --path-program "$root/config/demo/at_path.nc" \
  --drip-program "$root/test/data/gcode/cam/autodesk_fanuc_post_o0123.nc" --recorded "${once[@]}" &
scenario_pid=$!
stop_scenario() {
  kill -TERM "$scenario_pid" 2>/dev/null  # rospy shuts the scenario down on SIGTERM
  wait "$scenario_pid" 2>/dev/null
  exit 130
}
trap stop_scenario INT TERM
wait "$scenario_pid"
status=$?
trap - INT TERM
set -e
echo "demo: rosbag $out/cell.bag, surface map $(ls "$out"/*.png 2>/dev/null | head -1)"
exit $status
