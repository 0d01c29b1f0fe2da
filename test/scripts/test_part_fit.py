"""The part frame from probe points (scripts/part_fit.py): a plate of known tilt and height,
probed on a grid, gives back its frame within the stated tolerances; noise; too few points or
points on a line give no frame and say why.

Tolerances: exact points 1e-9 (m, rad); 5 um of noise on a 10 x 10 grid of 12.7 mm pitch:
height within 10 um, tilt within 0.1 mrad (some 7 times the standard error of the fit).
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


class OffsetShift(unittest.TestCase):
    def test_z_in_the_control_units_at_its_resolution(self):
        fit = part_fit.fit_part_frame(plate(0.002, -0.001, 0.5 * INCH + 1e-7))
        self.assertEqual(part_fit.offset_shift(fit, "inch"), {"Z": 0.5})
        self.assertEqual(part_fit.offset_shift(fit, "mm"), {"Z": 12.7})

    def test_unknown_units(self):
        fit = part_fit.fit_part_frame(plate(0.0, 0.0, 0.0))
        with self.assertRaises(ValueError):
            part_fit.offset_shift(fit, "furlong")


if __name__ == "__main__":
    unittest.main()
