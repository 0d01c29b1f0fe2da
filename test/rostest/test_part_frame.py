#!/usr/bin/env python3
"""The part's frame from the probe points of a plate placed with a known tilt and height, and the
G54 work offset written from it only where enabled and under the residual limit
(part_frame.test).

The plate: z = 0.5 + 0.002 x - 0.001 y + 0.0004 sin(pi x) sin(pi y) inches, probed by
config/dprnt/grid_probe.nc on 10 x 10 points 0.5 in apart from the work origin, printed to 4
decimals. Stated tolerances: the frame's origin within 3 um of (0, 0, 0.5 in), its z axis within
20 urad of the plate's normal (-0.002, 0.001, 1) (the waviness and the printed digits move the fit
by 0.05 um and 0.7 urad), the residual as the waviness makes it (rms 5.1 um, max 10.3 um). Expected
numbers come from the formula, not from the fit's code. Every wait is on a message or, for the
simulators' query logs (files another process writes), a poll with a deadline.

Edge probes, probed: a second simulated Haas (cell/sided) has a plate with sides, its corner at
SIDED_CORNER turned SIDED_YAW, and the program touches its front face twice (at X.5 and X4.) and
its left face once (at Y2.), printing the contact points to 4 decimals: its frame has that corner
within SIDED_CORNER_TOLERANCE and that yaw within SIDED_YAW_TOLERANCE (what the printed digits
allow: 0.00005 in on each coordinate, the front points 3.5 in apart), and its write moves G54 X/Y
onto the corner. Edge probes, exact: the test publishes contact points of the plate's front side
(3, the x side) and left side (2, the y side), placed with yaw EDGE_YAW and corner EDGE_CORNER, to
the edges mapper: its frame has that yaw and corner (within 1 urad and 0.1 um), and its write moves
G54 X/Y onto the corner (in the control's 0.0001 in); the same with one left side point 100 um
proud (a burr) to the burr mapper: its write is refused (the side lines' residual above
~max_residual) and its control receives no X/Y write.
"""
import math
import os
import re
import sys
import time
import unittest

import rospy
import rostest
import tf2_ros

from geometry_msgs.msg import PointStamped

from cnc_bridge.msg import PartFrame

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from topic_collector import Collector  # noqa: E402

INCH = 0.0254
HEIGHT = 0.5 * INCH
NORMAL = (-0.002, 0.001, 1.0)
HEIGHT_TOLERANCE = 3e-6  # m
TILT_TOLERANCE = 20e-6  # rad
G54_X_BEFORE, G54_Y_BEFORE, G54_Z_BEFORE = -12.5, -8.25, -2.0  # in, test/data/mdc/plate.mdcsim
EDGE_YAW = 0.01  # rad
EDGE_CORNER = (1.0 * INCH, 0.5 * INCH)  # m, in plate/work
FRONT = (0.3 * INCH, 1.5 * INCH, 3.0 * INCH)  # along the part's X from the corner
LEFT = (0.4 * INCH, 2.0 * INCH)  # along the part's Y
SIDED_CORNER = (-0.3, -0.2)  # in, part_frame.test's --part-corner
SIDED_YAW = math.radians(0.3)
SIDED_CORNER_TOLERANCE = 5e-6  # m
SIDED_YAW_TOLERANCE = 50e-6  # rad


def on_plate(u, v):
    """The point (u, v) of the part's own frame in plate/work (m)."""
    c, s = math.cos(EDGE_YAW), math.sin(EDGE_YAW)
    return EDGE_CORNER[0] + c * u - s * v, EDGE_CORNER[1] + s * u + c * v


def z_axis(q):
    """The third column of the rotation of quaternion q (geometry_msgs/Quaternion)."""
    return (2 * (q.x * q.z + q.y * q.w), 2 * (q.y * q.z - q.x * q.w), 1 - 2 * (q.x * q.x + q.y * q.y))


def angle(u, v):
    dot = sum(a * b for a, b in zip(u, v))
    norm = math.sqrt(sum(a * a for a in u) * sum(b * b for b in v))
    return math.acos(max(-1.0, min(1.0, dot / norm)))


def queries(path):
    """The queries a simulated control received so far (its --query-log)."""
    if not os.path.exists(path):
        return []
    with open(path) as f:
        return [line.strip() for line in f if line.strip()]


def wait_for_query(path, query, after, timeout=20.0):
    """True once the control received `query` after its first `after` queries."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if query in queries(path)[after:]:
            return True
        time.sleep(0.05)  # poll: the log is a file the simulator writes, no event to wait on
    return False


class TestPartFrame(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_part_frame")
        cls.ns = rospy.get_param("~namespace")
        cls.written_log = rospy.get_param("~written_queries")
        cls.refused_log = rospy.get_param("~refused_queries")
        cls.frames = Collector(cls.ns + "/part_frame", PartFrame)
        cls.off = Collector(cls.ns + "/off/part_frame", PartFrame)
        cls.strict = Collector(cls.ns + "/strict/part_frame", PartFrame)
        cls.edges_log = rospy.get_param("~edges_queries")
        cls.edges = Collector(cls.ns + "/edges/part_frame", PartFrame)
        cls.burr_log = rospy.get_param("~burr_queries")
        cls.burr = Collector(cls.ns + "/burr/part_frame", PartFrame)
        cls.sided_log = rospy.get_param("~sided_queries")
        cls.sided = Collector("/cell/sided/part_frame", PartFrame)
        cls.tf_buffer = tf2_ros.Buffer()
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)

    def complete_frame(self, collector):
        msg = collector.wait(lambda m: m.valid and m.points == 100, timeout=60.0)
        self.assertIsNotNone(msg, "no part frame of the 100 probe points")
        return msg

    def test_frame_of_the_plate_within_tolerance(self):
        msg = self.complete_frame(self.frames)
        self.assertEqual(msg.header.frame_id, "plate/work")
        self.assertEqual(msg.child_frame_id, "plate/part")
        p = msg.pose.position
        self.assertLess(math.hypot(p.x, p.y), 1e-9)  # above the work origin: no edge probes
        self.assertAlmostEqual(p.z, HEIGHT, delta=HEIGHT_TOLERANCE)
        self.assertLess(angle(z_axis(msg.pose.orientation), NORMAL), TILT_TOLERANCE)
        self.assertAlmostEqual(msg.pitch, -math.atan(0.002), delta=TILT_TOLERANCE)
        self.assertAlmostEqual(msg.roll, math.atan(-0.001), delta=TILT_TOLERANCE)
        self.assertEqual(msg.yaw, 0.0)
        self.assertAlmostEqual(msg.residual_rms, 5.1e-6, delta=0.5e-6)
        self.assertAlmostEqual(msg.residual_max, 10.3e-6, delta=0.5e-6)

    def test_frame_on_tf(self):
        self.complete_frame(self.frames)
        transform = self.tf_buffer.lookup_transform("plate/work", "plate/part", rospy.Time(0),
                                                    rospy.Duration(30.0)).transform
        self.assertAlmostEqual(transform.translation.z, HEIGHT, delta=HEIGHT_TOLERANCE)
        self.assertLess(angle(z_axis(transform.rotation), NORMAL), TILT_TOLERANCE)

    def test_work_offset_written_when_enabled(self):
        msg = self.frames.wait(lambda m: m.work_offset.startswith("written"), timeout=60.0)
        self.assertIsNotNone(msg, "no write: %s" % [m.work_offset for m in self.frames.messages if m.work_offset])
        self.assertIn("#5223", msg.work_offset)
        writes = [q for q in queries(self.written_log) if q.startswith("?E")]
        self.assertTrue(writes, "the control received no write")
        match = re.match(r"^\?E5223 (-?[0-9.]+)$", writes[0])
        self.assertTrue(match, writes)
        # The G54 Z moves up by the plate's height: work Z0 on the top face.
        self.assertAlmostEqual(float(match.group(1)), G54_Z_BEFORE + 0.5, delta=0.0001)
        # Z only: the X/Y origin is not measured without edge probes.
        self.assertEqual([q for q in writes if not q.startswith("?E5223 ")], [])

    def test_nothing_written_when_off_or_above_the_limit(self):
        off = self.off.wait(lambda m: m.work_offset != "", timeout=60.0)
        self.assertIsNotNone(off, "no cycle end reached the mapper with the write off")
        self.assertEqual(off.work_offset, "not written: ~write_work_offset is false")
        strict = self.strict.wait(lambda m: m.work_offset.startswith("refused"), timeout=60.0)
        self.assertIsNotNone(strict, "no refusal: %s" % [m.work_offset for m in self.strict.messages if m.work_offset])
        self.assertIn("~max_residual (5.0 um)", strict.work_offset)
        self.assertTrue(strict.valid)  # the frame is still published; only the write is refused
        # The control behind both received no write: a status poll after the refusals (one query
        # at a time) shows that nothing sent before it is still on its way.
        mark = len(queries(self.refused_log))
        self.assertTrue(wait_for_query(self.refused_log, "?Q500", mark), "haas_mdc_node does not poll its control")
        self.assertEqual([q for q in queries(self.refused_log) if q.startswith("?E")], [])

    def publish_edges(self, mapper="edges", burr=0.0):
        """The plate's side contact points, to a mapper (once it listens); burr: m, how far the
        first left side point stands proud of the face."""
        for side, points in (("edge_x", [on_plate(u, 0.0) for u in FRONT]),
                             ("edge_y", [on_plate(-burr if i == 0 else 0.0, v) for i, v in enumerate(LEFT)])):
            publisher = rospy.Publisher(self.ns + "/" + mapper + "/" + side, PointStamped, queue_size=10)
            deadline = time.monotonic() + 30.0
            while publisher.get_num_connections() == 0 and time.monotonic() < deadline:
                time.sleep(0.05)  # poll: a publisher has no event for a subscriber's connection
            self.assertGreater(publisher.get_num_connections(), 0, "surface_mapper does not listen on " + side)
            for x, y in points:
                msg = PointStamped()
                msg.header.frame_id = "plate/work"
                msg.point.x, msg.point.y, msg.point.z = x, y, 0.4 * INCH
                publisher.publish(msg)

    def test_edges_give_yaw_corner_and_the_xy_write(self):
        self.publish_edges()
        msg = self.edges.wait(lambda m: m.valid and m.points == 100 and m.edge_points == 5, timeout=60.0)
        self.assertIsNotNone(msg, "no frame with the 5 edge points: %s" % [m.message for m in self.edges.messages[-3:]])
        self.assertTrue(msg.xy_measured, msg.message)
        self.assertAlmostEqual(msg.pose.position.x, EDGE_CORNER[0], delta=1e-7)
        self.assertAlmostEqual(msg.pose.position.y, EDGE_CORNER[1], delta=1e-7)
        x, y = EDGE_CORNER[0] / INCH, EDGE_CORNER[1] / INCH
        self.assertAlmostEqual(msg.pose.position.z, (0.5 + 0.002 * x - 0.001 * y) * INCH, delta=HEIGHT_TOLERANCE)
        self.assertAlmostEqual(msg.yaw, EDGE_YAW, delta=20e-6)  # the tilt moves the fixed-axis yaw by ~1e-8
        self.assertLess(msg.edge_residual_max, 1e-9)
        written = self.edges.wait(lambda m: "#5221" in m.work_offset, timeout=60.0)
        self.assertIsNotNone(written, "no X/Y write: %s" % [m.work_offset for m in self.edges.messages if m.work_offset])
        self.assertTrue(written.work_offset.startswith("written"), written.work_offset)
        self.assertIn("G54 has no rotation", written.work_offset)
        writes = [q for q in queries(self.edges_log) if q.startswith("?E")]
        first = {}
        for q in writes:
            variable, value = q[2:].split()
            first.setdefault(variable, float(value))
        # G54 X/Y move onto the corner: work X0/Y0 at the corner of the plate.
        self.assertAlmostEqual(first.get("5221", float("nan")), G54_X_BEFORE + 1.0, delta=0.0001)
        self.assertAlmostEqual(first.get("5222", float("nan")), G54_Y_BEFORE + 0.5, delta=0.0001)
        self.assertIn("5223", first)

    def test_the_simulated_probe_of_a_plates_sides_gives_its_corner_and_turn(self):
        msg = self.sided.wait(lambda m: m.valid and m.points == 100 and m.edge_points == 3, timeout=60.0)
        self.assertIsNotNone(msg, "no frame with the 3 probed edge points: %s" % [m.message for m in self.sided.messages[-3:]])
        self.assertTrue(msg.xy_measured, msg.message)
        self.assertAlmostEqual(msg.pose.position.x, SIDED_CORNER[0] * INCH, delta=SIDED_CORNER_TOLERANCE)
        self.assertAlmostEqual(msg.pose.position.y, SIDED_CORNER[1] * INCH, delta=SIDED_CORNER_TOLERANCE)
        x, y = SIDED_CORNER
        self.assertAlmostEqual(msg.pose.position.z, (0.5 + 0.002 * x - 0.001 * y) * INCH, delta=HEIGHT_TOLERANCE)
        self.assertAlmostEqual(msg.yaw, SIDED_YAW, delta=SIDED_YAW_TOLERANCE)
        self.assertLess(angle(z_axis(msg.pose.orientation), NORMAL), TILT_TOLERANCE)
        written = self.sided.wait(lambda m: "#5221" in m.work_offset, timeout=60.0)
        self.assertIsNotNone(written, "no X/Y write: %s" % [m.work_offset for m in self.sided.messages if m.work_offset])
        self.assertTrue(written.work_offset.startswith("written"), written.work_offset)
        first = {}
        for q in queries(self.sided_log):
            if q.startswith("?E"):
                variable, value = q[2:].split()
                first.setdefault(variable, float(value))
        # G54 X/Y move onto the corner, Z onto the top face there (in, the control's 0.0001).
        self.assertAlmostEqual(first.get("5221", float("nan")), G54_X_BEFORE + x, delta=0.0002)
        self.assertAlmostEqual(first.get("5222", float("nan")), G54_Y_BEFORE + y, delta=0.0002)
        self.assertAlmostEqual(first.get("5223", float("nan")), G54_Z_BEFORE + 0.5 + 0.002 * x - 0.001 * y,
                               delta=0.0002)

    def test_a_burr_on_a_side_refuses_the_write(self):
        self.publish_edges("burr", burr=100e-6)
        refused = self.burr.wait(lambda m: m.work_offset.startswith("refused") and m.edge_points == 5, timeout=60.0)
        self.assertIsNotNone(refused, "no refusal: %s" % [m.work_offset for m in self.burr.messages if m.work_offset])
        self.assertIn("the side lines' largest residual", refused.work_offset)
        self.assertGreater(refused.edge_residual_max, 50e-6)
        # Before the edge points the mapper may have written Z (the plane alone is within the
        # limit); after the refusal nothing: a status poll after it (one query at a time) shows
        # that nothing sent before it is still on its way.
        before = len(queries(self.burr_log))
        self.assertTrue(wait_for_query(self.burr_log, "?Q500", before), "haas_mdc_node does not poll its control")
        after = queries(self.burr_log)
        self.assertEqual([q for q in after[before:] if q.startswith("?E")], [])
        self.assertEqual([q for q in after if q.startswith(("?E5221", "?E5222"))], [])


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_part_frame", TestPartFrame)
