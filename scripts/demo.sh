#!/usr/bin/env bash
# The simulated cell: starts a roscore if none is running, the machines of the cell with their
# simulators and models, and prints what they do. Ctrl-C stops everything.
# GUI=1 also opens rviz with rviz/cell.rviz.
set -eo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/env.sh"
source "$root/.build/devel/setup.bash"
gui=false
[[ "${GUI:-0}" == "1" ]] && gui=true
out=${DEMO_OUTPUT:-$root/output/demo-$(date +%Y%m%d-%H%M%S)}
mkdir -p "$out"
echo "demo: output in $out"
exec roslaunch --screen cnc_bridge demo_machine.launch gui:=$gui
