#!/usr/bin/env python3
"""The round trip through the reference MTConnect agent, with the nodes as a cell runs them.

The test publishes two machines' MachineState (/cell/vf2/state, /cell/laser/state) as their
nodes would; mtconnect_adapter_node serves them to the agent (cppagent v1.8.0.3, installed by
scripts/build_cppagent.sh; $CNC_MTCONNECT_AGENT overrides where it is), which this test starts on
the Devices.xml and agent.cfg the adapter node wrote; one mtconnect_node per machine follows the
agent (/mirror/<machine>). Checks: every field comes back as it was published, a cycle end is an
event, an alarm is a FAULT condition with its words, a machine whose node falls silent becomes
unknown. Without the agent the test fails, saying how to install it.
"""
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import rospy
import rostest

from cnc_bridge.msg import CycleEvent, MachineConditions, MachineState

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from topic_collector import Collector  # noqa: E402

AGENT = os.environ.get("CNC_MTCONNECT_AGENT") or "/usr/local/lib/cnc_bridge/cppagent-1.8.0.3/agent"


def machine(name, **fields):
    m = MachineState()
    m.machine = name
    m.link = MachineState.LINK_UP
    m.feed_rate = float("nan")
    m.spindle_speed = float("nan")
    m.tool = -1
    m.part_count = -1
    for key, value in fields.items():
        setattr(m, key, value)
    return m


VF2 = dict(mode=MachineState.MODE_AUTO, execution=MachineState.EXECUTION_ACTIVE, estop=MachineState.ESTOP_OFF,
           program="O1234", block=40, part_count=41, tool=3, door=MachineState.DOOR_CLOSED,
           spindle_speed=1200.0, feed_rate=0.0125, position_valid=True, commanded_valid=True)
LASER = dict(mode=MachineState.MODE_MANUAL, execution=MachineState.EXECUTION_READY, estop=MachineState.ESTOP_OFF,
             part_count=7, position_valid=True)

# What the client reads back: the fields a cell's tools see.
FIELDS = ("link", "mode", "execution", "estop", "program", "block", "part_count", "tool", "door")


def same(sent, got):
    """The fields that differ (empty: they agree)."""
    out = [f for f in FIELDS if getattr(sent, f) != getattr(got, f)]
    for f in ("spindle_speed", "feed_rate"):
        a, b = getattr(sent, f), getattr(got, f)
        if not ((math.isnan(a) and math.isnan(b)) or (not math.isnan(a) and not math.isnan(b) and abs(a - b) < 1e-9)):
            out.append(f)
    for valid, point in (("position_valid", "position"), ("commanded_valid", "commanded_position")):
        if getattr(sent, valid) != getattr(got, valid):
            out.append(valid)
        elif getattr(sent, valid):
            p, q = getattr(sent, point), getattr(got, point)
            if max(abs(p.x - q.x), abs(p.y - q.y), abs(p.z - q.z)) > 1e-9:
                out.append(point)
    return out


class TestMtconnectRoundTrip(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.pub = {name: rospy.Publisher("/cell/%s/state" % name, MachineState, queue_size=10, latch=True)
                   for name in ("vf2", "laser")}
        cls.state = {name: Collector("/mirror/%s/state" % name, MachineState) for name in ("vf2", "laser")}
        cls.events = Collector("/mirror/vf2/events", CycleEvent)
        cls.conditions = Collector("/mirror/laser/conditions", MachineConditions)
        cls.agent = None
        cls.work = None
        cls.addClassCleanup(cls.cleanup)
        cls.current = {}
        cls.timer = rospy.Timer(rospy.Duration(0.2), cls.republish)
        if not os.access(AGENT, os.X_OK):
            raise AssertionError("the reference MTConnect agent (cppagent v1.8.0.3) is not at %s: run scripts/setup.sh "
                                 "(it builds the agent with scripts/build_cppagent.sh) or set CNC_MTCONNECT_AGENT" % AGENT)
        config = rospy.get_param("~agent_config")
        deadline = time.time() + 30
        while not os.path.exists(config) and time.time() < deadline:
            time.sleep(0.1)  # polling for the file the adapter node writes when it starts
        assert os.path.exists(config), "mtconnect_adapter_node did not write %s" % config
        cls.work = tempfile.mkdtemp(prefix="mtconnect_round_trip_")
        cls.agent = subprocess.Popen([AGENT, "run", config], cwd=cls.work, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        for c in list(cls.state.values()) + [cls.events, cls.conditions]:
            assert c.wait_connected(30), "mtconnect_node's topics are not advertised"

    @classmethod
    def cleanup(cls):
        """Stops the agent and removes the files, also when setUpClass failed."""
        if cls.agent:
            cls.agent.kill()
            cls.agent.wait()
        if cls.work:
            shutil.rmtree(cls.work, ignore_errors=True)
        for param in ("~agent_config", "~devices_file"):
            path = rospy.get_param(param)
            if os.path.exists(path):
                os.remove(path)

    def publish(self, name, m):
        """Publishes m now and then at 5 Hz, as a node republishes its state; None falls silent."""
        self.current[name] = m
        if m is not None:
            m.header.stamp = rospy.Time.now()
            self.pub[name].publish(m)

    @classmethod
    def republish(cls, _event):
        for name, m in list(cls.current.items()):
            if m is not None:
                cls.pub[name].publish(m)

    def expect_read(self, name, sent, what, start=0):
        got = self.state[name].wait(lambda m: not same(sent, m), timeout=30.0, start=start)
        last = self.state[name].messages[-1] if self.state[name].messages else None
        self.assertIsNotNone(got, "%s: %s reads differently: %s" % (what, name, same(sent, last) if last else "nothing"))
        return got

    def test_round_trip(self):
        vf2 = machine("vf2", **VF2)
        vf2.position.x, vf2.position.y, vf2.position.z = 0.1234567, -0.2, 0.0305
        vf2.commanded_position.x, vf2.commanded_position.y, vf2.commanded_position.z = 0.1234, -0.2, 0.03
        laser = machine("laser", **LASER)
        laser.position.x, laser.position.y = 0.5, 0.25
        self.publish("vf2", vf2)
        self.publish("laser", laser)
        self.expect_read("vf2", vf2, "running")
        self.expect_read("laser", laser, "ready")

        # The cycle ends: the part is counted, the client sees the cycle end.
        vf2.execution = MachineState.EXECUTION_READY
        vf2.part_count = 42
        vf2.spindle_speed = 0.0
        vf2.door = MachineState.DOOR_OPEN
        self.publish("vf2", vf2)
        self.expect_read("vf2", vf2, "cycle end")
        end = self.events.wait(lambda e: e.event == CycleEvent.CYCLE_END)
        self.assertIsNotNone(end)
        self.assertEqual(end.part_count, 42)

        # The laser's alarm: execution STOPPED with a FAULT condition carrying its words.
        laser.execution = MachineState.EXECUTION_ALARM
        laser.message = "slave 2 (X axis) does not answer"
        self.publish("laser", laser)
        fault = self.conditions.wait(lambda m: any(c.level == c.FAULT and c.text == laser.message for c in m.active))
        self.assertIsNotNone(fault, "no FAULT condition with the alarm's words")
        stopped = self.state["laser"].wait(lambda m: m.execution == MachineState.EXECUTION_STOPPED)
        self.assertIsNotNone(stopped)

        # The laser's node falls silent: after ~stale_after the agent knows nothing of it.
        start = len(self.state["laser"].messages)
        self.publish("laser", None)
        lost = self.state["laser"].wait(lambda m: m.link != MachineState.LINK_UP or m.execution ==
                                        MachineState.EXECUTION_UNKNOWN, timeout=30.0, start=start)
        self.assertIsNotNone(lost, "a silent machine stays known")
        self.assertFalse(lost.position_valid)
        # The vf2, still published, stays as it was.
        self.expect_read("vf2", vf2, "vf2 unchanged", start=len(self.state["vf2"].messages) - 1)


if __name__ == "__main__":
    rospy.init_node("test_mtconnect_round_trip")
    rostest.rosrun("cnc_bridge", "mtconnect_round_trip", TestMtconnectRoundTrip)
