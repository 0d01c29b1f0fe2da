#!/usr/bin/env python3
"""Checks mtconnect_node against the reference agent's recorded answers, replayed byte for byte.

The replay (mtconnect_replay.py) is the conversation a client has with cppagent v1.8.0.3 feeding
a three-axis mill (test/data/mtconnect/README.md): probe, /current, a stream through a cycle end,
conditions and an emergency stop (cut when it was recorded: the agent vanishes mid-stream), then
again after reconnecting: a stream from older than the agent's buffer (a gap), /current, a stream
cut by the agent stopping, the restarted agent (new instanceId) and its stream; then the agent is
gone. Expected values come from what the recording's adapter sent (inches; the agent reports mm).
"""
import math
import os
import sys
import unittest

import rospy
import rostest
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from cnc_bridge.msg import CycleEvent, MachineConditions, MachineState

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mtconnect_replay import ReplayAgent  # noqa: E402
from topic_collector import Collector  # noqa: E402

INCH = 0.0254  # m
STEPS = ["probe", "current", "stream",
         "probe", "current_before_overrun", "stream_overrun", "current_after_overrun", "stream_agent_stopped",
         "probe_after_restart", "current_after_restart", "stream_after_restart"]


def mtconnect_status(array):
    for status in array.status:
        if status.name.endswith(": mtconnect"):
            return {kv.key: kv.value for kv in status.values}
    return None


class TestMtconnectNode(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        ns = rospy.get_param("~namespace")
        cls.prefix = rospy.get_param("~tf_prefix")
        cls.state = Collector(ns + "/state", MachineState)
        cls.events = Collector(ns + "/events", CycleEvent)
        cls.conditions = Collector(ns + "/conditions", MachineConditions)
        cls.joints = Collector(ns + "/joint_states", JointState)
        cls.diagnostics = Collector("/diagnostics", DiagnosticArray)
        cls.tf_buffer = tf2_ros.Buffer()
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)
        for c in (cls.state, cls.events, cls.conditions, cls.joints):
            assert c.wait_connected(30), "mtconnect_node's topics are not advertised"
        # The agent appears only now: the node has been retrying with its backoff meanwhile, and
        # every message of the replay reaches a connected subscriber.
        data = rospy.get_param("~data_dir")
        cls.agent = ReplayAgent(data, STEPS, rospy.get_param("~tcp_port"))

    def test_replay(self):
        self.assertTrue(self.agent.wait_done(90), "served only %s" % self.agent.served)
        self.assertEqual(self.agent.mismatches, [])

        # /current: the adapter's initial state, positions 1, 2, 3 inch.
        first = self.state.wait(lambda m: m.link == MachineState.LINK_UP and m.program == "O1234"
                                and m.part_count == 41 and m.position_valid)
        self.assertIsNotNone(first)
        self.assertEqual(first.mode, MachineState.MODE_AUTO)
        self.assertEqual(first.estop, MachineState.ESTOP_OFF)
        self.assertEqual(first.tool, 3)
        self.assertEqual(first.door, MachineState.DOOR_CLOSED)
        self.assertAlmostEqual(first.position.x, 1.0 * INCH, places=6)
        self.assertAlmostEqual(first.position.z, 3.0 * INCH, places=6)

        # The stream: the cycle's start and end (part counted), then a restart of the program.
        start = self.events.wait(lambda e: e.event == CycleEvent.CYCLE_START)
        self.assertIsNotNone(start)
        end = self.events.wait(lambda e: e.event == CycleEvent.CYCLE_END)
        self.assertIsNotNone(end)
        self.assertEqual(end.part_count, 42)
        self.assertEqual(end.program, "O1234")
        self.assertGreater(end.cycle_time, 0.0)
        self.assertEqual(end.machine, "mill")

        # Conditions with their codes and words, as history and as the active set.
        fault = self.conditions.wait(lambda m: any(c.native_code == "2001" and c.level == c.FAULT for c in m.changes))
        self.assertIsNotNone(fault)
        self.assertTrue(any(c.native_code == "2001" and c.text == "Spindle drive overload" for c in fault.active))
        self.assertTrue(any(c.native_code == "1010" and c.level == c.WARNING for c in fault.active))
        cleared = self.conditions.wait(lambda m: m.known and not m.active, start=self.conditions.messages.index(fault))
        self.assertIsNotNone(cleared)
        faulted = self.state.wait(lambda m: m.message.startswith("FAULT 2001"))
        self.assertIsNotNone(faulted)

        # The emergency stop with the door open ends the first stream.
        estop = self.state.wait(lambda m: m.estop == MachineState.ESTOP_ON)
        self.assertIsNotNone(estop)
        self.assertEqual(estop.execution, MachineState.EXECUTION_ALARM)
        self.assertIsNotNone(self.state.wait(lambda m: m.door == MachineState.DOOR_OPEN))

        # The restarted agent's stream: X at 5 inch.
        moved = self.state.wait(lambda m: m.position_valid and abs(m.position.x - 5.0 * INCH) < 1e-6)
        self.assertIsNotNone(moved)
        joints = self.joints.wait(lambda m: "%sx_axis" % self.prefix in m.name and
                                  abs(m.position[m.name.index("%sx_axis" % self.prefix)] - 5.0 * INCH) < 1e-6)
        self.assertIsNotNone(joints)

        # Diagnostics count the overrun and the restart.
        diag = self.diagnostics.wait(lambda a: mtconnect_status(a) is not None
                                     and int(mtconnect_status(a)["sequence gaps"]) >= 1
                                     and int(mtconnect_status(a)["agent restarts"]) >= 1)
        self.assertIsNotNone(diag)
        values = mtconnect_status(diag)
        self.assertEqual(values["sequence gaps"], "1")
        self.assertEqual(values["agent restarts"], "1")
        self.assertIn("buffer overrun", values["last gap"])

        # The agent is gone: the link is down and nothing is known, positions and conditions alike.
        gone = self.state.wait(lambda m: m.link != MachineState.LINK_UP and m.program == "" and not m.position_valid,
                               start=self.state.messages.index(moved))
        self.assertIsNotNone(gone)
        self.assertEqual(gone.mode, MachineState.MODE_UNKNOWN)
        self.assertEqual(gone.execution, MachineState.EXECUTION_UNKNOWN)
        self.assertEqual(gone.estop, MachineState.ESTOP_UNKNOWN)
        self.assertTrue(math.isnan(gone.spindle_speed))
        self.assertIsNotNone(self.conditions.wait(lambda m: not m.known))

    def test_tf(self):
        self.assertTrue(self.agent.wait_done(90))
        transform = self.tf_buffer.lookup_transform(self.prefix + "machine", self.prefix + "tool", rospy.Time(0),
                                                    rospy.Duration(30.0))
        self.assertTrue(math.isfinite(transform.transform.translation.x))


if __name__ == "__main__":
    rospy.init_node("test_mtconnect_node")
    rostest.rosrun("cnc_bridge", "mtconnect_node", TestMtconnectNode)
