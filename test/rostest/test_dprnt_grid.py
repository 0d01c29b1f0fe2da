#!/usr/bin/env python3
"""OpenDNC's grid probing cycle, as printed, becomes a height map (surface_mapper grid mode).

sim_haas_serial runs config/dprnt/seed_grid.nc: `CYCLE START O01001`, then for each of 10 x 10
points `G65 P9995 W54. A20. H-1.; DPRNT[#5223[44]]; G00 G91 X.5;` (rows 0.5 in apart, raster),
over z = -0.01 + 0.002 x + 0.001 y + 0.0008 sin(2 pi x / 1.5) sin(2 pi y / 1.5) inches. The lines
carry Z only; the grid parameters of the launch file must put every value back where it was
probed. Expected numbers come from that formula, not from our formatter. Every wait is on a
message or a service, with a timeout.
"""
import importlib.machinery
import importlib.util
import math
import os
import sys
import time
import unittest

import rospy
import rostest
import tf2_ros
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Float64

from cnc_bridge.msg import CycleEvent
from cnc_bridge.srv import DprntSaveSurface

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import dprnt_png  # noqa: E402
from topic_collector import Collector  # noqa: E402

INCH = 0.0254  # m
PITCH = 0.5 * INCH
# Half the last printed digit (0.00005 in), plus float32 in the cloud.
Z_TOLERANCE = 0.00005 * INCH + 1e-8


def surface_inch(x, y):
    return -0.01 + 0.002 * x + 0.001 * y + 0.0008 * math.sin(2 * math.pi * x / 1.5) * math.sin(2 * math.pi * y / 1.5)


def expected_z(x_m, y_m):
    return surface_inch(x_m / INCH, y_m / INCH) * INCH


def load_surface_mapper():
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "surface_mapper")
    loader = importlib.machinery.SourceFileLoader("surface_mapper", path)
    spec = importlib.util.spec_from_loader("surface_mapper", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def cloud_matches_the_surface(cloud):
    """True when the cloud has the 100 grid cells, each at its place with the surface's height."""
    points = list(point_cloud2.read_points(cloud, field_names=("x", "y", "z")))
    cells = set()
    for x, y, z in points:
        i, j = round(x / PITCH), round(y / PITCH)
        if abs(x - i * PITCH) > 1e-7 or abs(y - j * PITCH) > 1e-7 or not (0 <= i < 10 and 0 <= j < 10):
            return False
        if abs(z - expected_z(i * PITCH, j * PITCH)) > Z_TOLERANCE:
            return False
        cells.add((i, j))
    return len(cells) == 100 == len(points)


class TestDprntGrid(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_dprnt_grid")
        cls.ns = rospy.get_param("~namespace")
        cls.starts = Collector(cls.ns + "/dprnt/cycle_start", CycleEvent)
        cls.values = Collector(cls.ns + "/dprnt/bare_z", Float64)
        cls.cloud = Collector(cls.ns + "/surface/cloud", PointCloud2)

    def test_cycle_start_event(self):
        start = self.starts.wait(lambda m: True)
        self.assertIsNotNone(start, "no CYCLE_START")
        self.assertEqual(start.event, CycleEvent.CYCLE_START)
        self.assertEqual(start.program, "O01001")
        self.assertEqual(start.machine, "seed")
        self.assertEqual(start.text, "CYCLE START O01001")

    def test_bare_values_are_metres(self):
        # The first probe of a cycle, at (0, 0): -0.0100 in.
        first = self.values.wait(lambda m: abs(m.data - (-0.01 * INCH)) < 1e-12)
        self.assertIsNotNone(first, "the value of the first cell, in metres")

    def test_grid_becomes_cloud_csv_and_png_with_the_right_coordinates(self):
        cloud = self.cloud.wait(cloud_matches_the_surface, timeout=60)
        self.assertIsNotNone(cloud, "no 100-point cloud with every value at its grid cell")
        self.assertEqual(cloud.header.frame_id, "seed/work")

        rospy.wait_for_service(self.ns + "/surface_mapper/save", timeout=10)
        result = rospy.ServiceProxy(self.ns + "/surface_mapper/save", DprntSaveSurface)(name="seed_grid")
        self.assertTrue(result.success, result.message)
        self.assertEqual(result.points, 100)
        self.assertAlmostEqual(result.min_z, min(expected_z(i * PITCH, j * PITCH) for i in range(10) for j in range(10)),
                               delta=Z_TOLERANCE)
        self.assertAlmostEqual(result.max_z, max(expected_z(i * PITCH, j * PITCH) for i in range(10) for j in range(10)),
                               delta=Z_TOLERANCE)
        with open(result.csv_path) as f:
            rows = [line.split(",") for line in f if line[0].isdigit() or line[0] == "-"]
        self.assertEqual(len(rows), 100)
        for x, y, z, _ in ((float(v) for v in row) for row in rows):
            i, j = round(x / PITCH), round(y / PITCH)
            self.assertAlmostEqual(x, i * PITCH, delta=1e-9)
            self.assertAlmostEqual(y, j * PITCH, delta=1e-9)
            self.assertAlmostEqual(z, expected_z(x, y), delta=0.00005 * INCH + 1e-12)
        self.assertEqual({(round(float(r[0]) / PITCH), round(float(r[1]) / PITCH)) for r in rows},
                         {(i, j) for i in range(10) for j in range(10)})
        self.assertIsNone(dprnt_png.colour_bar_problem(result.png_path))

    def test_zz_cycle_start_realigns_the_grid(self):
        # Runs last (alphabetical). A stray CYCLE_START 30 values into a cycle makes the mapper put
        # the next values from the first cell on: the map goes wrong. The machine's next CYCLE_START
        # puts it right again.
        self.assertIsNotNone(self.cloud.wait(cloud_matches_the_surface, timeout=60))
        stray = rospy.Publisher(self.ns + "/dprnt/cycle_start", CycleEvent, queue_size=1)
        deadline = time.monotonic() + 10
        # Two subscribers: this test's own collector and surface_mapper.
        while stray.get_num_connections() < 2 and time.monotonic() < deadline:
            time.sleep(0.01)  # poll: rospy offers no wait for a subscriber
        self.assertEqual(stray.get_num_connections(), 2, "surface_mapper subscribes to cycle_start")
        self.assertIsNotNone(self.starts.wait(lambda m: True, timeout=30, start=self.starts.count()))
        self.assertIsNotNone(self.values.wait(lambda m: True, timeout=30, start=self.values.count() + 29))
        stray.publish(CycleEvent(event=CycleEvent.CYCLE_START, machine="stray", text="stray"))
        wrong = self.cloud.wait(lambda m: not cloud_matches_the_surface(m), timeout=30, start=self.cloud.count())
        self.assertIsNotNone(wrong, "the stray cycle start restarted the grid")
        right = self.cloud.wait(cloud_matches_the_surface, timeout=30, start=self.cloud.count())
        self.assertIsNotNone(right, "the next real cycle start realigned the grid")

    def test_work_offset_parameter_publishes_the_work_frame(self):
        buffer = tf2_ros.Buffer()
        listener = tf2_ros.TransformListener(buffer)  # noqa: F841 (must live while we look up)
        t = buffer.lookup_transform("seed/machine", "seed/work", rospy.Time(0), rospy.Duration(10))
        self.assertAlmostEqual(t.transform.translation.x, -0.3175, delta=1e-12)
        self.assertAlmostEqual(t.transform.translation.y, -0.20955, delta=1e-12)
        self.assertAlmostEqual(t.transform.translation.z, 0.0, delta=1e-12)
        self.assertAlmostEqual(t.transform.rotation.w, 1.0, delta=1e-12)


class TestGridPlacer(unittest.TestCase):
    """surface_mapper's GridPlacer alone: orders, restart, new pass, refused parameters."""

    @classmethod
    def setUpClass(cls):
        cls.GridPlacer = load_surface_mapper().GridPlacer

    def places(self, grid, count):
        return [grid.place(0.0)[1][:2] for _ in range(count)]

    def test_raster_steps_x_then_returns_for_the_next_row(self):
        grid = self.GridPlacer(3, 2, 0.5, 0.25, origin_x=1.0, origin_y=-1.0)
        self.assertEqual(self.places(grid, 6), [(1.0, -1.0), (1.5, -1.0), (2.0, -1.0),
                                                (1.0, -0.75), (1.5, -0.75), (2.0, -0.75)])

    def test_serpentine_runs_odd_rows_back(self):
        grid = self.GridPlacer(3, 3, 0.5, 0.25, order="serpentine")
        self.assertEqual(self.places(grid, 9), [(0.0, 0.0), (0.5, 0.0), (1.0, 0.0),
                                                (1.0, 0.25), (0.5, 0.25), (0.0, 0.25),
                                                (0.0, 0.5), (0.5, 0.5), (1.0, 0.5)])

    def test_negative_pitch(self):
        grid = self.GridPlacer(2, 2, -0.5, -0.25)
        self.assertEqual(self.places(grid, 4), [(0.0, 0.0), (-0.5, 0.0), (0.0, -0.25), (-0.5, -0.25)])

    def test_restart_and_new_pass(self):
        grid = self.GridPlacer(2, 2, 1.0, 1.0)
        self.places(grid, 3)
        grid.restart()  # a CYCLE_START mid-grid: the next value is the first cell again
        self.assertEqual(grid.place(-2.0), ((0, 0), (0.0, 0.0, -2.0)))
        self.places(grid, 3)
        self.assertEqual(grid.place(7.0), ((0, 0), (0.0, 0.0, 7.0)))  # past the last cell: a new pass
        self.assertEqual(grid.passes, 1)

    def test_bad_parameters_are_refused(self):
        for args, kwargs in (((0, 2, 1.0, 1.0), {}), ((2, 2, 0.0, 1.0), {}), ((2, 2, 1.0, 1.0), {"order": "spiral"})):
            with self.assertRaises(ValueError):
                self.GridPlacer(*args, **kwargs)
        self.GridPlacer(1, 5, 0.0, 1.0)  # a single column needs no X pitch


def all_tests():
    return unittest.TestSuite(unittest.defaultTestLoader.loadTestsFromTestCase(c) for c in (TestGridPlacer, TestDprntGrid))


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_dprnt_grid", "__main__.all_tests")
