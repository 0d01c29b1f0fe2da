#!/usr/bin/env python3
"""Checks dprnt_node and surface_mapper against sim_haas_serial running config/dprnt/grid_probe.nc.

The simulator's surface is z = -0.01 + 0.002 x + 0.001 y (inches), probed on a 10 x 10 grid of
0.5 in pitch from (0, 0); the program prints the Haas manual's example line, cycle start/end with a
part counter, every probe hit, the last Z offset and the machine position at the end (G54 X -12.5,
Y -8.25 given to the simulator). Expected numbers below are computed from that,
by hand, not by our own formatter. Every wait is on a message or a service, with a timeout.
"""
import math
import os
import sys
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from cnc_bridge.msg import CycleEvent, DprntLine, DprntValues, MachineState
from cnc_bridge.srv import DprntSaveSurface

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import dprnt_png  # noqa: E402
from topic_collector import Collector  # noqa: E402

INCH = 0.0254  # m


def surface_inch(x, y):
    return -0.01 + 0.002 * x + 0.001 * y


def dprnt_status(array):
    for status in array.status:
        if status.name.endswith(": dprnt"):
            return status, {kv.key: kv.value for kv in status.values}
    return None, None


class TestDprntNode(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.ns = rospy.get_param("~namespace")
        cls.prefix = rospy.get_param("~tf_prefix")
        cls.mode = rospy.get_param("~mode")
        cls.raw = Collector(cls.ns + "/dprnt/raw", DprntLine)
        cls.values = Collector(cls.ns + "/dprnt/values", DprntValues)
        cls.points = Collector(cls.ns + "/dprnt/probe_hit", PointStamped)
        cls.offsets = Collector(cls.ns + "/dprnt/z_offset", Float64)
        cls.events = Collector(cls.ns + "/dprnt/cycle_end", CycleEvent)
        cls.starts = Collector(cls.ns + "/dprnt/cycle_start", CycleEvent)
        cls.machine_points = Collector(cls.ns + "/dprnt/machine_position", PointStamped)
        cls.state = Collector(cls.ns + "/state", MachineState)
        cls.diagnostics = Collector("/diagnostics", DiagnosticArray)
        cls.cloud = Collector(cls.ns + "/surface/cloud", PointCloud2)

    def test_manual_example_line_becomes_values(self):
        def is_example(msg):
            return msg.text.startswith("X") and [v.label for v in msg.values] == ["X", "Z", "T"]

        msg = self.values.wait(is_example)
        self.assertIsNotNone(msg, "no values of the manual's example line")
        self.assertAlmostEqual(msg.values[0].value, 1.5436, places=9)
        self.assertAlmostEqual(msg.values[1].value, 1.544, places=9)
        self.assertAlmostEqual(msg.values[2].value, 1.0, places=9)
        self.assertEqual(msg.machine, self.prefix.rstrip("/"))
        raw = self.raw.wait(lambda m: m.line_number == msg.line_number and m.text == msg.text)
        self.assertIsNotNone(raw, "the same line on dprnt/raw")

    def test_probe_hits_are_points_in_metres_in_the_work_frame(self):
        # Grid cell (x = 0.5 in, y = 1.0 in): printed "PROBE X   0.5000 Y   1.0000 Z  -0.0080".
        def at_cell(msg):
            return abs(msg.point.x - 0.5 * INCH) < 1e-9 and abs(msg.point.y - 1.0 * INCH) < 1e-9

        msg = self.points.wait(at_cell)
        self.assertIsNotNone(msg, "no probe point at (0.5, 1.0) in")
        self.assertEqual(msg.header.frame_id, self.prefix + "work")
        self.assertAlmostEqual(msg.point.z, surface_inch(0.5, 1.0) * INCH, delta=1e-9)
        self.assertAlmostEqual(msg.point.z, -0.008 * INCH, delta=1e-9)

    def test_machine_position_is_a_point_in_the_machine_frame(self):
        # "MACHINE X -12.5000 Y  -3.2500 Z   0.0035": the end position (X0 Y5 in work) plus G54
        # (-12.5, -8.25); Z is the last probed G54 Z offset, 0.0035 in.
        msg = self.machine_points.wait(lambda m: True)
        self.assertIsNotNone(msg, "no machine position point")
        self.assertEqual(msg.header.frame_id, self.prefix + "machine")
        self.assertAlmostEqual(msg.point.x, -12.5 * INCH, delta=1e-12)
        self.assertAlmostEqual(msg.point.y, -3.25 * INCH, delta=1e-12)
        self.assertAlmostEqual(msg.point.z, 0.0035 * INCH, delta=1e-12)

    def test_machine_position_rule_sets_the_reported_position_in_state(self):
        # The shipped rule marks the MACHINE line as the position the control reported (state:
        # position): the node's state carries it, valid, and commands nothing.
        msg = self.state.wait(lambda m: m.position_valid)
        self.assertIsNotNone(msg, "no state with a valid position after the MACHINE line")
        self.assertAlmostEqual(msg.position.x, -12.5 * INCH, delta=1e-12)
        self.assertAlmostEqual(msg.position.y, -3.25 * INCH, delta=1e-12)
        self.assertAlmostEqual(msg.position.z, 0.0035 * INCH, delta=1e-12)
        self.assertFalse(msg.commanded_valid)
        self.assertEqual(msg.header.frame_id, self.prefix + "machine")

    def test_z_offset_is_the_last_cell_in_metres(self):
        msg = self.offsets.wait(lambda m: True)
        self.assertIsNotNone(msg)
        # Last probe at (4.5, 4.5) in: -0.01 + 0.009 + 0.0045 = 0.0035 in.
        self.assertAlmostEqual(msg.data, 0.0035 * INCH, delta=1e-9)

    def test_cycle_end_carries_program_and_part_count(self):
        first = self.events.wait(lambda m: True)
        self.assertIsNotNone(first, "no cycle end")
        self.assertEqual(first.event, CycleEvent.CYCLE_END)
        self.assertEqual(first.program, "O01000")
        self.assertGreaterEqual(first.part_count, 1)
        self.assertTrue(first.text.startswith("CYCLE END O01000 PARTS"))
        later = self.events.wait(lambda m: m.part_count > first.part_count, timeout=30)
        self.assertIsNotNone(later, "the part counter moves on the next cycle")
        state = self.state.wait(lambda m: m.part_count >= first.part_count)
        self.assertIsNotNone(state, "part count in state")
        self.assertEqual(state.program, "O01000")

    def test_cycle_start_carries_program_and_sets_execution_active(self):
        start = self.starts.wait(lambda m: True)
        self.assertIsNotNone(start, "no cycle start")
        self.assertEqual(start.event, CycleEvent.CYCLE_START)
        self.assertEqual(start.program, "O01000")
        self.assertEqual(start.text, "CYCLE START O01000")
        self.assertEqual(start.machine, self.prefix.rstrip("/"))
        self.assertTrue(math.isnan(start.cycle_time))
        # A start comes before its cycle's end: the end that follows it has the same program.
        end = self.events.wait(lambda m: m.header.stamp >= start.header.stamp, timeout=30)
        self.assertIsNotNone(end, "a cycle end after the start")
        self.assertEqual(end.program, start.program)
        active = self.state.wait(lambda m: m.execution == MachineState.EXECUTION_ACTIVE, timeout=30)
        self.assertIsNotNone(active, "execution ACTIVE in state after a cycle start")

    def test_latched_last_value_reaches_a_late_subscriber(self):
        self.assertIsNotNone(self.offsets.wait(lambda m: True))
        late = rospy.wait_for_message(self.ns + "/dprnt/last/z_offset", Float64, timeout=10)
        self.assertAlmostEqual(late.data, 0.0035 * INCH, delta=1e-9)
        point = rospy.wait_for_message(self.ns + "/dprnt/last/probe_hit", PointStamped, timeout=10)
        self.assertEqual(point.header.frame_id, self.prefix + "work")

    def test_grid_becomes_a_100_point_cloud_and_a_png(self):
        cloud = self.cloud.wait(lambda m: m.width * m.height == 100, timeout=60)
        self.assertIsNotNone(cloud, "no 100-point cloud")
        self.assertEqual(cloud.header.frame_id, self.prefix + "work")
        zs = [p[2] for p in point_cloud2.read_points(cloud, field_names=("x", "y", "z"))]
        self.assertAlmostEqual(min(zs), surface_inch(0, 0) * INCH, delta=1e-7)
        self.assertAlmostEqual(max(zs), surface_inch(4.5, 4.5) * INCH, delta=1e-7)

        rospy.wait_for_service(self.ns + "/surface_mapper/save", timeout=10)
        save = rospy.ServiceProxy(self.ns + "/surface_mapper/save", DprntSaveSurface)
        result = save(name="grid")
        self.assertTrue(result.success, result.message)
        self.assertEqual(result.points, 100)
        # The surface is a plane: the fit gives its slopes back (in/in = m/m) and deviations are only
        # the 0.00005 in of the printed rounding.
        self.assertAlmostEqual(result.plane_a, 0.002, delta=2e-5)
        self.assertAlmostEqual(result.plane_b, 0.001, delta=2e-5)
        self.assertAlmostEqual(result.plane_c, -0.01 * INCH, delta=2e-6)
        self.assertLess(result.flatness, 0.0001 * INCH)
        self.assertAlmostEqual(result.range, (0.0035 + 0.01) * INCH, delta=1e-7)
        with open(result.png_path, "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
        # The height map and, right of it, a colour bar running through the whole scale.
        self.assertIsNone(dprnt_png.colour_bar_problem(result.png_path))
        with open(result.csv_path) as f:
            rows = [line for line in f if line[0].isdigit() or line[0] == "-"]
        self.assertEqual(len(rows), 100)
        refused = save(name="../escape")
        self.assertFalse(refused.success)

    def test_link_is_up_and_noise_does_not_stop_the_stream(self):
        state = self.state.wait(lambda m: m.link == MachineState.LINK_UP)
        self.assertIsNotNone(state, "link never UP")
        self.assertEqual(state.header.frame_id, self.prefix + "machine")

        def noisy(array):
            _, values = dprnt_status(array)
            if not values:
                return False
            if self.mode == "pty":
                return int(values["overlong"]) > 0 and int(values["garbage bytes"]) > 0 and int(values["lines"]) > 300
            return int(values["link failures"]) >= 1 and int(values["lines"]) > 300

        array = self.diagnostics.wait(noisy, timeout=60)
        self.assertIsNotNone(array, "counters never showed the injected faults with lines flowing")
        status, values = dprnt_status(array)
        if self.mode == "pty":
            self.assertEqual(status.level, status.WARN)
            self.assertGreater(int(values["control bytes"]), 0)  # POPEN/PCLOS leaders
        # Lines keep arriving after the faults: a later cycle end.
        seen = len(self.events.messages)
        self.assertIsNotNone(self.events.wait(lambda m: True, timeout=30, start=seen + 1))

    def test_zz_clear_resets_counters(self):
        # Runs last (alphabetical): the other tests need the counters.
        self.assertIsNotNone(self.raw.wait(lambda m: m.line_number > 50))
        rospy.wait_for_service(self.ns + "/dprnt_node/clear", timeout=10)
        result = rospy.ServiceProxy(self.ns + "/dprnt_node/clear", Trigger)()
        self.assertTrue(result.success)
        restarted = self.raw.wait(lambda m: m.line_number < 50, timeout=10, start=len(self.raw.messages))
        self.assertIsNotNone(restarted, "line numbers start again after ~clear")


class TestDprntNodeOverTcp(TestDprntNode):
    """The checks of every link, and the one only a TCP link has: a dropped connection."""

    def test_tcp_drop_and_return(self):
        # The simulator dropped the connection once: the node saw the link fail and reconnected.
        def reconnected(array):
            _, values = dprnt_status(array)
            return values is not None and int(values["link failures"]) >= 1 and int(values["reconnects"]) >= 1

        self.assertIsNotNone(self.diagnostics.wait(reconnected, timeout=60), "no drop and reconnect seen")
        # Lines after the reconnect are whole: a probe line with its three values, then a full cycle.
        seen = len(self.values.messages)
        after = self.values.wait(lambda m: m.text.startswith("PROBE"), timeout=30, start=seen)
        self.assertIsNotNone(after)
        self.assertEqual([v.label for v in after.values], ["X", "Y", "Z"])
        self.assertIsNotNone(self.events.wait(lambda m: True, timeout=30, start=len(self.events.messages)))
        state = self.state.wait(lambda m: m.link == MachineState.LINK_UP, timeout=30, start=len(self.state.messages))
        self.assertIsNotNone(state, "link UP again in state")


if __name__ == "__main__":
    rospy.init_node("test_dprnt_node")
    # Each link runs the cases it has: the TCP launch file also runs the drop-and-return case.
    over_tcp = rospy.get_param("~mode") == "tcp"
    rostest.rosrun("cnc_bridge", "test_dprnt_node", TestDprntNodeOverTcp if over_tcp else TestDprntNode)
