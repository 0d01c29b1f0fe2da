#!/usr/bin/env python3
"""Reliability campaign on the running demo cell: kill a simulator at random (SIGKILL, as a
machine losing power or a cable pulled), again and again, while the cell works.

For every kill: the machine's node must report the link loss in `state` (link not UP) and in its
`link` diagnostic, and come back UP after the simulator is respawned, and no node process may die.
Meanwhile XModem transfers run against the Haas's RS-232 simulator, which is killed too: dnc_node
keeps its port open in the cell (~keep_open), so it must show that loss like the others, and every
transfer that reports success must have delivered exactly the file (checked byte for byte in the
simulated control's memory). Targets are taken round-robin, in a new shuffled order each round, so
every simulator gets its share of the kills (6 kills: each of the six once).

  cell_chaos.py --kills 50 --seed 7 --programs DIR --memory DIR      (rostest: ~kills, ~seed, ...)
"""
import argparse
import os
import random
import signal
import subprocess
import sys
import threading
import time
import unittest

import actionlib
import rosnode
import rospy

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from cnc_bridge.msg import MachineState, TransferAction, TransferGoal

# Simulator command line (as the cell launches it) -> the state topic and the node whose
# diagnostics must show its loss.
TARGETS = [
    ("sim_haas_mdc --port 25051", "/cell/haas_vf2/state", "/cell/haas_vf2/haas_mdc_node"),
    ("sim_haas_serial dprnt --tcp 25052", "/cell/haas_vf2/dprnt/state", "/cell/haas_vf2/dprnt_node"),
    ("sim_ethernut --port 26666", "/cell/ethernut_mill/state", "/cell/ethernut_mill/ethernut_node"),
    ("sim_at_controller --command-port 25000", "/cell/at_router/state", "/cell/at_router/at_controller_node"),
    ("sim_slave_bus --link", "/cell/laser/state", "/cell/laser/slave_bus_node"),
    # dnc_node finds the loss at its next read or write: the transfer loop keeps it busy.
    ("sim_haas_serial xmodem", "/cell/haas_vf2/dnc/state", "/cell/haas_vf2/dnc_node"),
]
NODES = ["/cell/haas_vf2/haas_mdc_node", "/cell/haas_vf2/dnc_node", "/cell/haas_vf2/dprnt_node",
         "/cell/ethernut_mill/ethernut_node", "/cell/at_router/at_controller_node", "/cell/laser/slave_bus_node"]


class LinkWatch:
    """Every link value a state topic carried, with its arrival time."""

    def __init__(self, topic):
        self.history = []
        self.lock = threading.Lock()
        self.sub = rospy.Subscriber(topic, MachineState, self._on_state, queue_size=100)

    def _on_state(self, state):
        with self.lock:
            self.history.append((time.time(), state.link))

    def down_then_up_after(self, since, timeout):
        """(seconds to DOWN, seconds to UP again) after `since`, or None where not seen in time."""
        deadline = since + timeout
        while True:
            down = up = None
            with self.lock:
                # In arrival order: the first state not UP, then the first UP after it.
                for stamp, link in self.history:
                    if stamp < since:
                        continue
                    if down is None:
                        if link != MachineState.LINK_UP:
                            down = stamp - since
                    elif link == MachineState.LINK_UP:
                        up = stamp - since
                        break
            if up is not None or time.time() >= deadline:
                return down, up
            time.sleep(0.05)  # poll: the states are recorded by another thread


class DiagnosticsWatch:
    """When each node's `link` diagnostic was not OK (arrival times)."""

    def __init__(self):
        self.bad = {}
        self.lock = threading.Lock()
        self.sub = rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_diagnostics, queue_size=100)

    def _on_diagnostics(self, array):
        now = time.time()
        with self.lock:
            for status in array.status:
                node, _, task = status.name.rpartition(": ")
                if task == "link" and status.level != DiagnosticStatus.OK:
                    self.bad.setdefault(node.strip("/"), []).append(now)

    def not_ok_since(self, node, since):
        """`node` fully qualified; a status names it with or without its namespace."""
        node = node.strip("/")
        with self.lock:
            return any(stamp >= since for name, stamps in self.bad.items()
                       if node == name or node.endswith("/" + name) for stamp in stamps)


def same_master(pid):
    """True if the process runs under this test's ROS master: a simulator of another cell or test
    on the same machine (another rostest, a CI run) is not ours to kill."""
    try:
        with open("/proc/%d/environ" % pid, "rb") as f:
            env = dict(e.split(b"=", 1) for e in f.read().split(b"\0") if b"=" in e)
    except OSError:
        return False
    return env.get(b"ROS_MASTER_URI", b"").decode() == os.environ.get("ROS_MASTER_URI", "")


def pids_of(pattern):
    out = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True).stdout
    return [int(p) for p in out.split() if int(p) != os.getpid() and same_master(int(p))]


class TransferLoop(threading.Thread):
    """Sends a program again and again; checks each reported success against what arrived."""

    def __init__(self, programs, memory):
        super().__init__(daemon=True)
        self.programs, self.memory = programs, memory
        self.successes = self.failures = 0
        self.reasons = {}
        self.false_successes = []
        self.stop = threading.Event()

    def run(self):
        client = actionlib.SimpleActionClient("/cell/haas_vf2/dnc_node/transfer", TransferAction)
        if not client.wait_for_server(rospy.Duration(30)):
            self.false_successes.append("no transfer action server")
            return
        number = 0
        while not self.stop.is_set():
            number += 1
            name = "O%05d.nc" % (7000 + number % 1000)
            body = "%%\nO%05d (chaos %d)\n" % (7000 + number % 1000, number) + "".join(
                "N%d G01 X%.3f Y%.3f F100.\n" % (10 * i, random.uniform(-5, 5), random.uniform(-5, 5)) for i in range(60)) + "M30\n%\n"
            with open(os.path.join(self.programs, name), "w") as f:
                f.write(body)
            stored = os.path.join(self.memory, name)
            if os.path.exists(stored):
                os.unlink(stored)
            client.send_goal(TransferGoal(direction="send", protocol="xmodem", file=name))
            if not client.wait_for_result(rospy.Duration(120)):
                client.cancel_goal()
                self.failures += 1
                continue
            result = client.get_result()
            if result.success:
                self.successes += 1
                # The control files a program once the transfer has ended: give it a moment.
                arrived = None
                deadline = time.time() + 5.0
                while time.time() < deadline:
                    arrived = open(stored).read() if os.path.exists(stored) else None
                    if arrived == body:
                        break
                    time.sleep(0.05)  # poll: the simulator writes the file from another process
                if arrived != body:
                    self.false_successes.append("%s reported sent but %s" % (
                        name, "never arrived" if arrived is None else "arrived different (%d of %d bytes)" % (len(arrived), len(body))))
            else:
                self.failures += 1
                # Why, in a few words (the file name and numbers vary): shown at the end.
                reason = " ".join(w for w in result.message.split()[:8] if not any(c.isdigit() for c in w))
                self.reasons[reason] = self.reasons.get(reason, 0) + 1
                # A link that is down fails at once: do not spin on it.
                self.stop.wait(0.2)


class CellChaos(unittest.TestCase):
    def test_nodes_survive_simulator_kills(self):
        kills = rospy.get_param("~kills", ARGS.kills)
        seed = rospy.get_param("~seed", ARGS.seed)
        recover = rospy.get_param("~recover_timeout", ARGS.recover_timeout)
        rng = random.Random(seed)
        watches = {topic: LinkWatch(topic) for _, topic, _ in TARGETS}
        diagnostics = DiagnosticsWatch()
        for node in NODES:
            self.assertTrue(rosnode.rosnode_ping(node, max_count=1), "%s is not running at the start" % node)
        # Opening its port per transfer, dnc_node would show DOWN between transfers anyway: the
        # check of its link loss means something only with the port kept open.
        self.assertTrue(rospy.get_param("/cell/haas_vf2/dnc_node/keep_open", False),
                        "the cell's dnc_node must keep its port open (~keep_open) for this campaign")
        # Transfers first: dnc_node opens its port for good at its first transfer if the simulator's
        # pty was not there yet when it started.
        transfers = TransferLoop(ARGS.programs, ARGS.memory)
        transfers.start()
        for topic in watches:
            self.wait_up(topic, 60)
        problems = []
        order = []
        killed = {}
        for kill in range(kills):
            if not order:  # a new round: every target once, in a new order
                order = rng.sample(TARGETS, len(TARGETS))
            pattern, topic, node = order.pop()
            killed[pattern] = killed.get(pattern, 0) + 1
            # A simulator killed a moment ago may still be waiting for its respawn (respawn_delay):
            # wait for it instead of counting it as lost.
            pids = pids_of(pattern)
            deadline = time.time() + recover
            while not pids and time.time() < deadline:
                time.sleep(0.1)  # poll: the process list
                pids = pids_of(pattern)
            if not pids:
                problems.append("kill %d: %s not running (not respawned?)" % (kill, pattern))
                time.sleep(2.0)  # pace: the campaign's pause before its next kill
                continue
            since = time.time()
            for pid in pids:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass  # it ended between pgrep and now
            down, up = watches[topic].down_then_up_after(since, recover)
            rospy.loginfo("kill %d: %s: link down after %s s, up again after %s s (transfers: %d ok, %d failed)",
                          kill, pattern, "%.2f" % down if down is not None else "-",
                          "%.2f" % up if up is not None else "-", transfers.successes, transfers.failures)
            if down is None:
                problems.append("kill %d: %s: %s never showed the link down" % (kill, pattern, topic))
            elif up is None:
                problems.append("kill %d: %s: %s did not come back UP within %d s" % (kill, pattern, topic, recover))
            if not diagnostics.not_ok_since(node, since):
                problems.append("kill %d: %s: the link diagnostic of %s never left OK" % (kill, pattern, node))
            for node in NODES:
                if not rosnode.rosnode_ping(node, max_count=1):
                    problems.append("kill %d: node %s died" % (kill, node))
        transfers.stop.set()
        transfers.join(150)
        rospy.loginfo("kills per simulator: %s", ", ".join("%s %d" % kv for kv in sorted(killed.items())))
        rospy.loginfo("%d kills; transfers: %d succeeded (all verified), %d failed as they should when cut",
                      kills, transfers.successes, transfers.failures)
        for reason, count in sorted(transfers.reasons.items(), key=lambda item: -item[1]):
            rospy.loginfo("  %5d failed: %s", count, reason)
        self.assertEqual(transfers.false_successes, [], "a transfer reported success for data that did not arrive")
        self.assertEqual(problems, [])
        self.assertGreater(transfers.successes, 0, "no transfer succeeded at all between kills")

    def wait_up(self, topic, timeout):
        deadline = time.time() + timeout
        while time.time() < deadline:
            state = rospy.wait_for_message(topic, MachineState, timeout=max(deadline - time.time(), 1.0))
            if state.link == MachineState.LINK_UP:
                return
            time.sleep(0.2)  # poll: until a state says UP
        self.fail("%s not UP at the start" % topic)


def parse():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--recover-timeout", type=float, default=30.0)
    parser.add_argument("--programs", default=os.path.join(os.environ.get("CNC_DEMO_DIR", "/tmp/cnc_cell"), "programs"))
    parser.add_argument("--memory", default=os.path.join(os.environ.get("CNC_DEMO_DIR", "/tmp/cnc_cell"), "haas_vf2_memory"))
    args, _ = parser.parse_known_args(rospy.myargv()[1:])
    return args


ARGS = None
if __name__ == "__main__":
    import rostest
    rospy.init_node("cell_chaos")
    ARGS = parse()
    rostest.rosrun("cnc_bridge", "cell_chaos", CellChaos, sys.argv)
