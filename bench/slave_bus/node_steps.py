#!/usr/bin/env python3
"""Steps per second through slave_bus_node: publish one 8-slave BusFrame on bus/frame, wait until
all eight slaves' responses are back, repeat. Needs a running master, node and simulator (run.sh
starts them). Prints steps/s and the median round trip."""
import sys
import threading
import time

import rospy
from cnc_bridge.msg import BusFrame, BusPayload, SlaveResponse

NAMES = ["x", "y", "z", "laser", "aux5", "aux6", "aux7", "aux8"]


def main():
    steps = int(sys.argv[1]) if len(sys.argv) > 1 else 500
    rospy.init_node("slave_bus_node_bench", anonymous=True)
    lock = threading.Condition()
    got = set()

    def on_response(msg):
        with lock:
            got.add(msg.name)
            lock.notify_all()

    subs = [rospy.Subscriber("slaves/%s/response" % n, SlaveResponse, on_response, queue_size=100) for n in NAMES]
    pub = rospy.Publisher("bus/frame", BusFrame, queue_size=10)
    deadline = time.time() + 20
    while (pub.get_num_connections() == 0 or any(s.get_num_connections() == 0 for s in subs)) and time.time() < deadline:
        time.sleep(0.05)
    # values 0/1 as two-byte be16s: every slave of config/slave_bus_example.yaml accepts two bytes
    latencies = []
    missing = 0
    for i in range(steps + 20):
        frame = BusFrame()
        frame.payloads = [BusPayload(address=a, data=[0, (i + a) % 2]) for a in range(1, 9)]
        with lock:
            got.clear()
        t0 = time.perf_counter()
        pub.publish(frame)
        with lock:
            if not lock.wait_for(lambda: len(got) == len(NAMES), timeout=2.0):
                missing += len(NAMES) - len(got)
        if i >= 20:  # the first 20 warm up
            latencies.append(time.perf_counter() - t0)
    total = sum(latencies)
    latencies.sort()
    median = latencies[len(latencies) // 2]
    print("node: steps=%d missing=%d steps/s: %.1f (at the median latency: %.1f)   latency us: median %.1f, p99 %.1f"
          % (steps, missing, steps / total, 1.0 / median, median * 1e6, latencies[len(latencies) * 99 // 100] * 1e6))
    return 0 if missing == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
