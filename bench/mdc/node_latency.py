#!/usr/bin/env python3
"""Measures haas_mdc_node from the outside (rospy): the time from a status change in the simulated
machine to the `state` message that shows it, and the queries per second the node answers.

usage: node_latency.py NAMESPACE SIM_LOG SECONDS PERIOD
  NAMESPACE  where the node publishes (state, /diagnostics are read)
  SIM_LOG    the simulator's stderr: "timeline starts at <epoch> (<loop> s per loop)"
  SECONDS    measurement time
  PERIOD     seconds per phase of bench/mdc/toggle.mdcsim (1.3)
Prints: latency mean/median/p95/max in ms."""
import math
import re
import sys
import threading
import time

import rospy
from cnc_bridge.msg import MachineState

ns, sim_log, seconds, phase = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
rospy.init_node("mdc_bench", anonymous=True)
with open(sim_log) as f:
    start = float(re.search(r"timeline starts at ([0-9.]+)", f.read()).group(1))

lock = threading.Lock()
latencies = []
last = [None]


def on_state(msg):
    now = time.time()
    with lock:
        if msg.execution not in (MachineState.EXECUTION_READY, MachineState.EXECUTION_ACTIVE):
            return
        if last[0] is not None and msg.execution != last[0]:
            # The change happened at the last phase boundary before now.
            boundary = start + math.floor((now - start) / phase) * phase
            latencies.append((now - boundary) * 1000.0)
        last[0] = msg.execution


rospy.Subscriber(ns + "/state", MachineState, on_state, queue_size=100)
rospy.sleep(seconds)
with lock:
    values = sorted(latencies[1:])  # the first change may predate the subscription
if not values:
    print("no status change seen")
    sys.exit(1)
print("changes %d latency mean %.1f ms median %.1f ms p95 %.1f ms max %.1f ms"
      % (len(values), sum(values) / len(values), values[len(values) // 2],
         values[min(len(values) - 1, int(len(values) * 0.95))], values[-1]))
