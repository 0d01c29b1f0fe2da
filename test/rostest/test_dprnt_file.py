#!/usr/bin/env python3
"""dprnt_node with ~input file: the test is the control appending DPRNT output to a file (NGC
setting 262). The file does not exist when the node starts; lines appended later arrive; a
truncated file is read again from its start, and a line the control left unfinished before the
truncation is dropped (counted), not glued to the new content; a rotated file is read to its end,
then the new one.
Lengths are millimetres here (~program_units mm). Every wait is on a message, with a timeout.
"""
import os
import sys
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped

from cnc_bridge.msg import DprntLine, MachineState

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from topic_collector import Collector  # noqa: E402


def dprnt_counter(array, key):
    """A counter of the node's dprnt diagnostics task, or -1 when this array does not carry it."""
    for status in array.status:
        if status.name.endswith(": dprnt"):
            for kv in status.values:
                if kv.key == key:
                    return int(kv.value)
    return -1


class TestDprntFile(unittest.TestCase):
    def test_file_followed_through_creation_truncation_and_rotation(self):
        rospy.init_node("test_dprnt_file")
        ns = rospy.get_param("~namespace")
        path = rospy.get_param("~file")
        raw = Collector(ns + "/dprnt/raw", DprntLine)
        points = Collector(ns + "/dprnt/probe_hit", PointStamped)
        state = Collector(ns + "/state", MachineState)
        diagnostics = Collector("/diagnostics", DiagnosticArray)
        for collector in (raw, points, state):
            self.assertTrue(collector.wait_connected(), "the node publishes " + collector.sub.name)

        # The node waits for the file: the link is not up before the control creates it.
        self.assertIsNotNone(state.wait(lambda m: m.link != MachineState.LINK_UP))
        with open(path, "w") as f:
            f.write("CYCLE START O02000\r")
        self.assertIsNotNone(state.wait(lambda m: m.link == MachineState.LINK_UP), "link UP once the file exists")
        self.assertIsNotNone(raw.wait(lambda m: m.text == "CYCLE START O02000"))

        # Appended in two writes, the second finishing the line: one whole line.
        with open(path, "a") as f:
            f.write("PROBE X  12.500 Y")
        with open(path, "a") as f:
            f.write("   3.000 Z  -0.125\r")
        point = points.wait(lambda m: True)
        self.assertIsNotNone(point)
        self.assertAlmostEqual(point.point.x, 0.0125, delta=1e-12)  # mm -> m
        self.assertAlmostEqual(point.point.z, -0.000125, delta=1e-12)

        # The control is cut off mid-line; wait until the node has read those bytes (diagnostics).
        written = len("CYCLE START O02000\r") + len("PROBE X  12.500 Y   3.000 Z  -0.125\r")
        with open(path, "a") as f:
            f.write("HALF LINE ")
        written += len("HALF LINE ")
        self.assertIsNotNone(
            diagnostics.wait(lambda a: dprnt_counter(a, "bytes") >= written), "the unfinished line read")

        # Truncation: the control starts the file again; wait until the node noticed (state message).
        open(path, "w").close()
        self.assertIsNotNone(state.wait(lambda m: "truncated" in m.message), "truncation noticed")
        with open(path, "a") as f:
            f.write("AFTER TRUNCATION 1\r")
        self.assertIsNotNone(raw.wait(lambda m: m.text.endswith("AFTER TRUNCATION 1")))
        self.assertEqual([m.text for m in raw.messages if "AFTER TRUNCATION" in m.text], ["AFTER TRUNCATION 1"],
                         "the unfinished line before the truncation is not glued to the new one")
        self.assertIsNotNone(
            diagnostics.wait(lambda a: dprnt_counter(a, "partial lines dropped") >= 1), "the dropped line counted")

        # Rotation: a last line, the file renamed away, a new file under the old name.
        with open(path, "a") as f:
            f.write("LAST OF OLD 2\r")
        os.rename(path, path + ".1")
        with open(path, "w") as f:
            f.write("FIRST OF NEW 3\r")
        self.assertIsNotNone(raw.wait(lambda m: m.text == "FIRST OF NEW 3"))
        texts = [m.text for m in raw.messages]
        self.assertLess(texts.index("LAST OF OLD 2"), texts.index("FIRST OF NEW 3"))
        self.assertEqual(texts.count("CYCLE START O02000"), 1, "nothing read twice")
        os.remove(path + ".1")
        os.remove(path)


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_dprnt_file", TestDprntFile)
