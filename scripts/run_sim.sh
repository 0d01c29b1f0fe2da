#!/usr/bin/env bash
# Runs a ROS-free simulator from a launch file: roslaunch appends __name:= and __log:= to every
# node's command line, which a plain program would take for its own options; drop them.
# usage (launch): <node pkg="cnc_bridge" type="run_sim.sh" name="sim" args="sim_ethernut --port 6666"/>
args=()
for a in "$@"; do
  case "$a" in __name:=* | __log:=* | __ns:=*) ;; *) args+=("$a") ;; esac
done
program=${args[0]:?usage: run_sim.sh SIMULATOR [options]}
here=$(cd "$(dirname "$0")" && pwd)
# The simulator is built beside the nodes: find it through the catkin devel/install space.
for dir in ${CMAKE_PREFIX_PATH//:/ }; do
  if [[ -x "$dir/lib/cnc_bridge/$program" ]]; then
    exec "$dir/lib/cnc_bridge/$program" "${args[@]:1}"
  fi
done
[[ -x "$here/../.build/devel/lib/cnc_bridge/$program" ]] && exec "$here/../.build/devel/lib/cnc_bridge/$program" "${args[@]:1}"
echo "run_sim.sh: simulator $program not found in CMAKE_PREFIX_PATH" >&2
exit 1
