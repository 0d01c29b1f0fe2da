"""The part frame from probe points (scripts/part_fit.py): a plate of known tilt and height,
probed on a grid, gives back its frame within the stated tolerances; noise; too few points or
points on a line give no frame and say why.

Tolerances: exact points 1e-9 (m, rad); 5 um of noise on a 10 x 10 grid of 12.7 mm pitch:
height within 10 um, tilt within 0.1 mrad (some 7 times the standard error of the fit).
Edge probes: a rotated, shifted plate's sides give back its yaw and corner (Edges: tolerances
there); too few or misplaced edge points give no X/Y origin and say why.
"""
import math
import unittest

import numpy as np

import part_fit

INCH = 0.0254


def plate(a, b, c, columns=10, rows=10, pitch=0.5 * INCH, x0=0.0, y0=0.0):
    """Points of z = a x + b y + c on a grid, as the grid probe program probes them (m)."""
    return np.array([(x0 + i * pitch, y0 + j * pitch, a * (x0 + i * pitch) + b * (y0 + j * pitch) + c)
                     for j in range(rows) for i in range(columns)])


def angle_between(u, v):
    return math.acos(max(-1.0, min(1.0, float(np.dot(u, v) / np.linalg.norm(u) / np.linalg.norm(v)))))


class KnownPlate(unittest.TestCase):
    A, B, C = 0.002, -0.001, 0.5 * INCH  # the simulated plate of part_frame.test

    def test_tilt_and_height_are_recovered(self):
        fit = part_fit.fit_part_frame(plate(self.A, self.B, self.C))
        self.assertEqual(fit.points, 100)
        for got, want in zip(fit.origin, (0.0, 0.0, self.C)):
            self.assertAlmostEqual(got, want, delta=1e-9)
        self.assertAlmostEqual(fit.pitch, -math.atan(self.A), delta=1e-9)
        self.assertAlmostEqual(fit.roll, math.atan(self.B / math.sqrt(1 + self.A**2)), delta=1e-9)
        self.assertAlmostEqual(fit.yaw, 0.0, delta=1e-12)
        self.assertLess(fit.residual_rms, 1e-12)
        self.assertLess(fit.residual_max, 1e-12)

    def test_the_frame_lies_in_the_plate(self):
        fit = part_fit.fit_part_frame(plate(self.A, self.B, self.C))
        r = fit.rotation
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        self.assertAlmostEqual(float(np.linalg.det(r)), 1.0, delta=1e-12)
        # Points of the part's X/Y plane are points of the plate; its Z is the plate's normal.
        for u, v in ((0.1, 0.0), (0.0, 0.1), (0.07, -0.03)):
            x, y, z = np.array(fit.origin) + r @ np.array([u, v, 0.0])
            self.assertAlmostEqual(z, self.A * x + self.B * y + self.C, delta=1e-12)
        self.assertLess(angle_between(r[:, 2], np.array([-self.A, -self.B, 1.0])), 1e-12)
        self.assertAlmostEqual(r[1, 0], 0.0, delta=1e-12)  # the x axis stays above the work X

    def test_quaternion_is_the_rotation(self):
        fit = part_fit.fit_part_frame(plate(0.3, -0.2, 0.01))
        x, y, z, w = fit.quaternion
        self.assertAlmostEqual(x * x + y * y + z * z + w * w, 1.0, delta=1e-12)
        from_q = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                           [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                           [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        np.testing.assert_allclose(from_q, fit.rotation, atol=1e-12)

    def test_level_plate_is_the_work_frame_raised(self):
        fit = part_fit.fit_part_frame(plate(0.0, 0.0, -0.004))
        np.testing.assert_allclose(fit.rotation, np.eye(3), atol=1e-15)
        self.assertEqual(fit.quaternion[3], 1.0)
        self.assertAlmostEqual(fit.origin[2], -0.004, delta=1e-12)

    def test_noise_within_tolerance_and_in_the_residual(self):
        rng = np.random.default_rng(32)
        points = plate(self.A, self.B, self.C)
        points[:, 2] += rng.normal(0.0, 5e-6, len(points))
        fit = part_fit.fit_part_frame(points)
        self.assertAlmostEqual(fit.origin[2], self.C, delta=10e-6)
        self.assertAlmostEqual(fit.pitch, -math.atan(self.A), delta=1e-4)
        self.assertAlmostEqual(fit.roll, math.atan(self.B / math.sqrt(1 + self.A**2)), delta=1e-4)
        self.assertGreater(fit.residual_rms, 3e-6)
        self.assertLess(fit.residual_rms, 7e-6)
        self.assertGreaterEqual(fit.residual_max, fit.residual_rms)

    def test_one_high_point_is_the_largest_residual(self):
        points = plate(self.A, self.B, self.C)
        points[57, 2] += 50e-6  # a chip under the probe
        fit = part_fit.fit_part_frame(points)
        self.assertGreater(fit.residual_max, 40e-6)
        self.assertLess(fit.residual_rms, fit.residual_max / 5)

    def test_three_points_make_a_frame(self):
        fit = part_fit.fit_part_frame([(0, 0, 1e-3), (0.01, 0, 1e-3 + 2e-5), (0, 0.01, 1e-3 - 1e-5)])
        self.assertAlmostEqual(fit.plane[0], 2e-3, delta=1e-12)
        self.assertAlmostEqual(fit.plane[1], -1e-3, delta=1e-12)
        self.assertEqual(fit.points, 3)


class NoFrame(unittest.TestCase):
    def assertNoFrame(self, points, *words):
        with self.assertRaises(part_fit.FitError) as raised:
            part_fit.fit_part_frame(points)
        for word in words:
            self.assertIn(word, str(raised.exception))

    def test_too_few_points(self):
        self.assertNoFrame([], "at least 3", "got 0")
        self.assertNoFrame([(0, 0, 0), (0.01, 0, 0)], "at least 3", "got 2")

    def test_points_on_a_line(self):
        self.assertNoFrame([(i * 0.0127, 0.0, 0.001 * i) for i in range(10)], "on one line", "10 probe points")
        self.assertNoFrame([(i * 0.01, i * 0.02, 0.0) for i in range(5)], "on one line")
        # One row probed twice, to the last digit a DPRNT line prints.
        self.assertNoFrame([(i * 0.0127, 0.0254 + 1e-12 * (i % 2), 0.0) for i in range(20)], "on one line")

    def test_one_spot_probed_again_and_again(self):
        self.assertNoFrame([(0.01, 0.02, 0.003)] * 5, "one spot")

    def test_a_value_that_is_not_finite(self):
        points = plate(0.0, 0.0, 0.0).tolist()
        points[4][2] = float("nan")
        self.assertNoFrame(points, "point 5", "not finite")

    def test_a_small_plate_is_a_plate(self):
        fit = part_fit.fit_part_frame(plate(0.01, 0.0, 0.0, columns=3, rows=2, pitch=0.001))
        self.assertAlmostEqual(fit.pitch, -math.atan(0.01), delta=1e-9)


def rotate(yaw, shift, points):
    """points (x, y) of the part's own frame in the work frame: rotated by yaw, then shifted."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([(shift[0] + c * u - s * v, shift[1] + s * u + c * v) for u, v in points])


class Edges(unittest.TestCase):
    """A 100 x 60 mm plate, rotated by YAW and with its corner at CORNER (m), probed on its front
    side (the x side, along the part's X: 5 points) and its left side (the y side: 3 points).

    Tolerances with 5 um of noise on the contact points: yaw within 0.5 mrad, the corner within
    20 um (some 6 times the standard error of the fit)."""
    YAW, CORNER = math.radians(1.5), (0.0123, -0.0045)
    FRONT = [(u, 0.0) for u in (0.01, 0.03, 0.05, 0.07, 0.09)]
    LEFT = [(0.0, v) for v in (0.01, 0.03, 0.05)]

    def sides(self, yaw=YAW, corner=CORNER):
        return rotate(yaw, corner, self.FRONT), rotate(yaw, corner, self.LEFT)

    def test_yaw_and_corner_are_recovered(self):
        for yaw in (self.YAW, -math.radians(20), 0.0, math.radians(80)):
            edges = part_fit.fit_edges(*self.sides(yaw))
            self.assertAlmostEqual(edges.yaw, yaw, delta=1e-9)
            self.assertTrue(edges.corner)
            np.testing.assert_allclose(edges.origin, self.CORNER, atol=1e-9)
            self.assertLess(edges.residual_max, 1e-12)
            self.assertEqual((edges.x_points, edges.y_points), (5, 3))

    def test_points_in_reverse_order_give_the_same_frame(self):
        front, left = self.sides()
        edges = part_fit.fit_edges(front[::-1], left)
        self.assertAlmostEqual(edges.yaw, self.YAW, delta=1e-9)

    def test_one_point_on_the_y_side_is_enough(self):
        front, left = self.sides()
        edges = part_fit.fit_edges(front[:2], left[1:2])
        self.assertAlmostEqual(edges.yaw, self.YAW, delta=1e-9)
        np.testing.assert_allclose(edges.origin, self.CORNER, atol=1e-9)

    def test_noise_within_tolerance_and_in_the_residual(self):
        rng = np.random.default_rng(33)
        front, left = self.sides()
        front += rng.normal(0.0, 5e-6, front.shape)
        left += rng.normal(0.0, 5e-6, left.shape)
        edges = part_fit.fit_edges(front, left)
        self.assertAlmostEqual(edges.yaw, self.YAW, delta=0.5e-3)
        np.testing.assert_allclose(edges.origin, self.CORNER, atol=20e-6)
        self.assertGreater(edges.residual_rms, 1e-6)
        self.assertLess(edges.residual_rms, 10e-6)

    def test_a_burr_on_a_side_is_the_largest_residual(self):
        front, left = self.sides()
        left[1] += 50e-6 * np.array([-math.cos(self.YAW), -math.sin(self.YAW)])  # 50 um proud of the face
        edges = part_fit.fit_edges(front, left)
        self.assertGreater(edges.residual_max, 30e-6)

    def test_x_side_only_gives_yaw_and_its_line_not_the_corner(self):
        front, _ = self.sides()
        edges = part_fit.fit_edges(front)
        self.assertFalse(edges.corner)
        self.assertAlmostEqual(edges.yaw, self.YAW, delta=1e-9)
        self.assertIn("not known", edges.message)
        # The origin is on the front side's line, nearest the work origin.
        normal = np.array([-math.sin(self.YAW), math.cos(self.YAW)])
        self.assertAlmostEqual(float(normal @ np.array(edges.origin)), float(normal @ np.array(self.CORNER)),
                               delta=1e-9)
        self.assertAlmostEqual(float(np.array([math.cos(self.YAW), math.sin(self.YAW)]) @ edges.origin), 0.0,
                               delta=1e-12)

    def test_too_few_x_side_points_no_rotation(self):
        front, left = self.sides()
        for x_side in (front[:1], []):
            with self.assertRaises(part_fit.FitError) as raised:
                part_fit.fit_edges(x_side, left)
            self.assertIn("at least 2 edge points on its x side", str(raised.exception))
            self.assertIn("no X/Y origin", str(raised.exception))

    def test_x_side_points_in_one_spot(self):
        with self.assertRaises(part_fit.FitError) as raised:
            part_fit.fit_edges([(0.01, 0.02)] * 3, [(0.0, 0.03)])
        self.assertIn("one spot", str(raised.exception))

    def test_y_side_points_on_the_x_side_line_no_corner(self):
        front, _ = self.sides()
        more = rotate(self.YAW, self.CORNER, [(0.12, 0.0), (0.14, 0.0)])
        with self.assertRaises(part_fit.FitError) as raised:
            part_fit.fit_edges(front, more)
        self.assertIn("no corner", str(raised.exception))

    def test_a_value_that_is_not_finite(self):
        front, left = self.sides()
        left[2][0] = float("inf")
        with self.assertRaises(part_fit.FitError) as raised:
            part_fit.fit_edges(front, left)
        self.assertIn("y side point 3 is not finite", str(raised.exception))

    def test_frame_with_plane_and_edges(self):
        a, b, c = KnownPlate.A, KnownPlate.B, KnownPlate.C
        fit = part_fit.fit_part_frame(plate(a, b, c), part_fit.fit_edges(*self.sides()))
        x0, y0 = self.CORNER
        np.testing.assert_allclose(fit.origin, (x0, y0, a * x0 + b * y0 + c), atol=1e-9)
        r = fit.rotation
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        self.assertAlmostEqual(math.atan2(r[1, 0], r[0, 0]), self.YAW, delta=1e-9)  # x axis above the side
        self.assertLess(angle_between(r[:, 2], np.array([-a, -b, 1.0])), 1e-12)
        self.assertAlmostEqual(fit.yaw, self.YAW, delta=1e-4)  # the tilt moves the fixed-axis yaw a little
        self.assertTrue(fit.edges.corner)


class OffsetShift(unittest.TestCase):
    def test_z_in_the_control_units_at_its_resolution(self):
        fit = part_fit.fit_part_frame(plate(0.002, -0.001, 0.5 * INCH + 1e-7))
        self.assertEqual(part_fit.offset_shift(fit, "inch"), {"Z": 0.5})
        self.assertEqual(part_fit.offset_shift(fit, "mm"), {"Z": 12.7})

    def test_x_and_y_onto_the_corner(self):
        edges = part_fit.fit_edges(*Edges().sides(corner=(1.25 * INCH, -0.5 * INCH)))
        fit = part_fit.fit_part_frame(plate(0.0, 0.0, 0.5 * INCH), edges)
        self.assertEqual(part_fit.offset_shift(fit, "inch"), {"X": 1.25, "Y": -0.5, "Z": 0.5})
        self.assertEqual(part_fit.offset_shift(fit, "mm"), {"X": 31.75, "Y": -12.7, "Z": 12.7})

    def test_x_side_only_moves_z_only(self):
        front, _ = Edges().sides()
        fit = part_fit.fit_part_frame(plate(0.0, 0.0, 0.5 * INCH), part_fit.fit_edges(front))
        self.assertEqual(part_fit.offset_shift(fit, "inch"), {"Z": 0.5})

    def test_unknown_units(self):
        fit = part_fit.fit_part_frame(plate(0.0, 0.0, 0.0))
        with self.assertRaises(ValueError):
            part_fit.offset_shift(fit, "furlong")


if __name__ == "__main__":
    unittest.main()
