#!/usr/bin/env bash
# ROS as the distributed engine: the master and a checker on one host, a machine node on another,
# as two network namespaces joined by a veth pair (addresses of our own test hosts only). The
# machine's state and tf must cross. Writes JUnit XML to $1.
#
#   host "cell" 10.251.0.1: roscore, checker        host "machine" 10.251.0.2: demo_motion_node
set -uo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
source "$root/scripts/env.sh"
junit=${1:?usage: test_two_hosts.sh RESULT.xml}
build=${BUILD_DIR:-$root/.build}
suffix=$$
cell=cnc_cell_$suffix
machine=cnc_machine_$suffix
log=$(mktemp -d /tmp/cnc_two_hosts.XXXXXX)

passed=0
cleanup() {
  ip netns pids "$cell" 2>/dev/null | xargs -r kill 2>/dev/null
  ip netns pids "$machine" 2>/dev/null | xargs -r kill 2>/dev/null
  ip netns del "$cell" 2>/dev/null
  ip netns del "$machine" 2>/dev/null
  [[ $passed == 1 ]] && rm -rf "$log"  # a failure's message names its logs: kept then
}
trap cleanup EXIT

result() {  # name, failure message (empty = pass)
  if [[ -z "$2" ]]; then
    passed=1
    echo "<testsuite name=\"two_hosts\"><testcase classname=\"net.two_hosts\" name=\"$1\"/></testsuite>" >"$junit"
  else
    echo "two_hosts: $2 (logs in $log)"
    echo "<testsuite name=\"two_hosts\"><testcase classname=\"net.two_hosts\" name=\"$1\"><failure message=\"$2\"/></testcase></testsuite>" >"$junit"
  fi
}

if ! ip netns add "$cell" 2>"$log/netns.err" || ! ip netns add "$machine"; then
  result state_and_tf_cross_hosts "cannot create network namespaces: $(cat "$log/netns.err")"
  exit 1
fi
ip link add "veth_c$suffix" type veth peer name "veth_m$suffix"
ip link set "veth_c$suffix" netns "$cell"
ip link set "veth_m$suffix" netns "$machine"
ip -n "$cell" addr add 10.251.0.1/24 dev "veth_c$suffix"
ip -n "$machine" addr add 10.251.0.2/24 dev "veth_m$suffix"
for ns in "$cell" "$machine"; do
  ip -n "$ns" link set lo up
done
ip -n "$cell" link set "veth_c$suffix" up
ip -n "$machine" link set "veth_m$suffix" up

master=http://10.251.0.1:11311
on_cell() { ip netns exec "$cell" env ROS_IP=10.251.0.1 ROS_MASTER_URI=$master bash -c "source $build/devel/setup.bash; $*"; }
on_machine() { ip netns exec "$machine" env ROS_IP=10.251.0.2 ROS_MASTER_URI=$master bash -c "source $build/devel/setup.bash; $*"; }

on_cell "roscore -p 11311" >"$log/roscore.log" 2>&1 &
# poll: the master answers rostopic list once it is up
on_cell "for i in \$(seq 100); do rostopic list >/dev/null 2>&1 && exit 0; sleep 0.1; done; exit 1" \
  || { result state_and_tf_cross_hosts "the master did not come up on the cell host"; exit 1; }
on_machine "ROS_NAMESPACE=/cell/remote_mill rosrun cnc_bridge demo_motion_node _machine:=remote_mill _tf_prefix:=remote_mill/" \
  >"$log/machine.log" 2>&1 &

if on_cell "python3 $root/test/net/check_remote_machine.py /cell/remote_mill remote_mill/" >"$log/check.log" 2>&1; then
  cat "$log/check.log"
  result state_and_tf_cross_hosts ""
else
  cat "$log/check.log"
  result state_and_tf_cross_hosts "state or tf did not cross from the machine host to the cell host"
  exit 1
fi
