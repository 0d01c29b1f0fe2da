#!/usr/bin/env python3
"""Measures a running cell: the rate of every machine's state topics, and the CPU and resident
memory of every cnc_bridge process (nodes and simulators) over the same window. Fails (exit 1)
if a state topic is below 9 Hz or any state in the window had its link not UP (every node of the
cell keeps its link open, dnc_node with ~keep_open).

  measure_cell.py CELL_YAML SECONDS
"""
import collections
import os
import sys
import time

import rospy
import yaml

from cnc_bridge.msg import MachineState

TICKS = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")


def processes():
    """pid -> (label, cpu ticks, rss bytes) of every process running a cnc_bridge program under
    this cell's ROS master (other cells and tests on a shared machine are not counted)."""
    found = {}
    master = os.environ.get("ROS_MASTER_URI", "").encode()
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open("/proc/%s/cmdline" % pid, "rb") as f:
                argv = f.read().split(b"\0")
            with open("/proc/%s/stat" % pid) as f:
                stat = f.read().rsplit(")", 1)[1].split()
            with open("/proc/%s/environ" % pid, "rb") as f:
                if b"ROS_MASTER_URI=" + master not in f.read().split(b"\0"):
                    continue
        except OSError:
            continue
        program = os.path.basename(argv[0].decode(errors="replace"))
        if b"cnc_bridge" not in argv[0] and program not in ("robot_state_publisher",):
            continue
        if program in ("run_sim.sh", "bash"):
            continue
        name = next((a.decode()[8:] for a in argv if a.startswith(b"__name:=")), "")
        ns = next((a.decode()[6:] for a in argv if a.startswith(b"__ns:=")), "")
        label = "%s %s" % (program, name or "")
        for a in argv:
            if a.startswith(b"--link") or a.startswith(b"--port") or a.startswith(b"--tcp") or a.startswith(b"--command-port"):
                label += " " + a.decode()
        if ns:
            label = ns.rstrip("/") + "/" + label
        found[pid] = (label.strip(), int(stat[11]) + int(stat[12]), int(stat[21]) * PAGE)
    return found


def main():
    with open(sys.argv[1]) as f:
        description = yaml.safe_load(f)
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 20.0
    rospy.init_node("measure_cell", anonymous=True)
    counts = collections.Counter()
    not_up = collections.Counter()  # states in the window whose link was not UP

    def on_state(state, topic):
        counts.update([topic])
        if state.link != MachineState.LINK_UP:
            not_up.update([topic])
    topics = []
    for machine in description["machines"]:
        for node in machine["nodes"]:
            topic = "/%s/%s/%s" % (description.get("cell", "cell"), machine["name"], node.get("remap", {}).get("state", "state"))
            topics.append(topic)
            rospy.Subscriber(topic, MachineState, lambda msg, t=topic: on_state(msg, t))
    time.sleep(3.0)  # connections
    counts.clear()
    not_up.clear()
    before = processes()
    start = time.time()
    time.sleep(seconds)
    elapsed = time.time() - start
    after = processes()
    rates = {t: counts[t] / elapsed for t in topics}
    print("state topics: %d, all publishing: %s" % (len(topics), all(r > 0 for r in rates.values())))
    print("%-45s %8s %8s" % ("topic", "Hz", "not UP"))
    for topic in topics:
        print("%-45s %8.1f %8d" % (topic, rates[topic], not_up[topic]))
    print()
    print("%-70s %7s %9s" % ("process", "CPU %", "RSS MB"))
    total_cpu = total_rss = 0.0
    for pid, (label, ticks, rss) in sorted(after.items(), key=lambda kv: kv[1][0]):
        if pid not in before:
            continue
        cpu = 100.0 * (ticks - before[pid][1]) / TICKS / elapsed
        total_cpu += cpu
        total_rss += rss / 1e6
        print("%-70s %7.1f %9.1f" % (label[:70], cpu, rss / 1e6))
    print("%-70s %7.1f %9.1f" % ("total (%d processes)" % len(after), total_cpu, total_rss))
    slow = [t for t, r in rates.items() if r < 9.0]
    print("topics below 9 Hz: %s" % (", ".join(slow) if slow else "none"))
    down = [t for t in topics if not_up[t] or not counts[t]]
    print("links not UP during the window: %s" % (", ".join(down) if down else "none"))
    return 0 if not slow and not down else 1


if __name__ == "__main__":
    sys.exit(main())
