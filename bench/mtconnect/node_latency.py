#!/usr/bin/env python3
"""Times mtconnect_node from the outside (rospy): for each change `Xact = n` (inches) the source
sent (its log: "<n> <epoch>"), the time until a `state` message shows position.x = n inches.

usage: node_latency.py NAMESPACE SECONDS SOURCE_LOG
Prints: changes seen of sent, latency p50/p99/max in ms."""
import sys
import threading
import time

import rospy
from cnc_bridge.msg import MachineState

INCH = 0.0254  # m: the mill's Xact has nativeUnits INCH, so the source's n is n inches
ns, seconds, log = sys.argv[1], float(sys.argv[2]), sys.argv[3]
rospy.init_node("mtconnect_bench", anonymous=True)
lock = threading.Lock()
seen = {}


def on_state(msg):
    now = time.time()
    if not msg.position_valid:
        return
    n = int(round(msg.position.x / INCH))
    with lock:
        seen.setdefault(n, now)


rospy.Subscriber(ns + "/state", MachineState, on_state, queue_size=1000, tcp_nodelay=True)
rospy.sleep(seconds)
sent = {}
with open(log) as f:
    for line in f:
        n, at = line.split()
        sent[int(n)] = float(at)
with lock:
    values = sorted((seen[n] - sent[n]) * 1000.0 for n in sent if n in seen)
if not values:
    print("no change seen of %d sent" % len(sent))
    sys.exit(1)
print("changes %d of %d latency p50 %.1f ms p99 %.1f ms max %.1f ms"
      % (len(values), len(sent), values[len(values) // 2], values[min(len(values) - 1, int(len(values) * 0.99))],
         values[-1]))
