#!/usr/bin/env python3
"""Latency of DPRNT lines from the simulator's write to a subscriber's callback.

sim_haas_serial runs config/dprnt/latency.nc, printing "LAT <#3001>" where #3001 is the wall-clock
millisecond (modulo 100000) taken right before the line is written to the pty. This subscriber
takes the wall clock on arrival of each dprnt/values message; the difference is the latency through
the pty, dprnt_node (assemble, parse, publish) and ROS transport into a rospy callback.
usage: latency.py NAMESPACE SAMPLES
"""
import sys
import threading
import time

import rospy

from cnc_bridge.msg import DprntValues


def main():
    ns, samples = sys.argv[1], int(sys.argv[2])
    rospy.init_node("dprnt_latency", anonymous=True)
    latencies = []
    done = threading.Event()

    def on_values(msg):
        now_ms = (time.time() * 1000.0) % 100000.0
        if msg.values and msg.values[0].label == "LAT":
            latency = (now_ms - msg.values[0].value) % 100000.0  # wraps every 100 s
            latencies.append(latency)
            if len(latencies) >= samples:
                done.set()

    rospy.Subscriber(ns + "/dprnt/values", DprntValues, on_values, queue_size=1000, tcp_nodelay=True)
    if not done.wait(samples / 50.0 + 30):
        print("only %d samples" % len(latencies))
    data = sorted(latencies[5:])  # the first lines cross a connection being set up
    if not data:
        sys.exit(1)
    pick = lambda q: data[min(len(data) - 1, int(q * len(data)))]
    print("latency_ms p50 %.3f p99 %.3f max %.3f n %d" % (pick(0.5), pick(0.99), data[-1], len(data)))


if __name__ == "__main__":
    main()
