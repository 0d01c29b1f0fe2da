"""The part's frame from the probe points of its top face (surface_mapper's part frame). No ROS.

A least-squares plane z = a x + b y + c through the probe points (metres, in the frame they were
probed in: the work frame of the program) gives the part's tilt and height. The part frame:
  origin  the point of the plane above the frame's X/Y origin: (0, 0, c);
  z axis  the plane's normal (pointing up, +Z);
  x axis  the frame's X direction laid onto the plane: (1, 0, a), normalised;
  y axis  z x x.
So its yaw is 0 and, as roll/pitch/yaw (rotations about the fixed X, Y, Z axes, in that order):
pitch = -atan(a), roll = atan(b / sqrt(1 + a^2)).

Only the top face is fitted: the XY origin and the rotation about Z of the part would need edge
probes (points on two of its side faces), which the probing programs here do not print. The
residuals are the points' Z deviations from the plane (what the probe measured along), RMS and
largest absolute.
"""
import collections
import math

import numpy as np

MIN_POINTS = 3

PartFit = collections.namedtuple(
    "PartFit", "origin rotation quaternion roll pitch yaw plane residual_rms residual_max points")
PartFit.__doc__ = """The part frame in the points' frame.
origin: (x, y, z) m; rotation: 3 x 3 matrix whose columns are the part's axes; quaternion:
(x, y, z, w); roll, pitch, yaw: rad; plane: (a, b, c) of z = a x + b y + c; residual_rms,
residual_max: m; points: how many were fitted."""


class FitError(ValueError):
    """No part frame from these points; str() says why and what to check."""


def fit_plane(points):
    """(a, b, c) of the least-squares plane z = a x + b y + c and the Z deviations from it.

    points: N x 3 (m). Raises FitError for fewer than 3 points, a value that is not finite, or
    points whose X/Y lie on one line (no plane is determined by them).
    """
    xyz = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(xyz) < MIN_POINTS:
        raise FitError("a plane needs at least %d probe points, got %d" % (MIN_POINTS, len(xyz)))
    bad = np.flatnonzero(~np.isfinite(xyz).all(axis=1))
    if len(bad):
        raise FitError("probe point %d is not finite: %s" % (bad[0] + 1, xyz[bad[0]].tolist()))
    # Spread of the X/Y positions across their main direction and across the other; relative, so
    # a plate a few millimetres wide is not taken for a line (1 um across 1 m counts as a line).
    spread = np.linalg.svd(xyz[:, :2] - xyz[:, :2].mean(axis=0), compute_uv=False)
    if spread[0] == 0.0 or spread[1] <= 1e-6 * spread[0]:
        raise FitError("the %d probe points lie on one line (or one spot) in X/Y: no plane through them; "
                       "probe at least 3 points that are not in a line" % len(xyz))
    design = np.column_stack([xyz[:, 0], xyz[:, 1], np.ones(len(xyz))])
    (a, b, c), *_ = np.linalg.lstsq(design, xyz[:, 2], rcond=None)
    return (float(a), float(b), float(c)), xyz[:, 2] - design @ np.array([a, b, c])


def quaternion_from_matrix(r):
    """(x, y, z, w) of the rotation matrix r (3 x 3, proper)."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        return ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s)
    i = int(np.argmax([r[0, 0], r[1, 1], r[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
    q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
    q[i] = 0.25 * s
    q[j] = (r[j, i] + r[i, j]) / s
    q[k] = (r[k, i] + r[i, k]) / s
    return tuple(q)


def fit_part_frame(points):
    """The part frame (PartFit) of the probed top face; raises FitError with the reason."""
    (a, b, c), deviation = fit_plane(points)
    z_axis = np.array([-a, -b, 1.0]) / math.sqrt(a * a + b * b + 1.0)
    x_axis = np.array([1.0, 0.0, a]) / math.sqrt(1.0 + a * a)
    y_axis = np.cross(z_axis, x_axis)
    rotation = np.column_stack([x_axis, y_axis, z_axis])
    roll = math.atan2(rotation[2, 1], rotation[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, rotation[2, 0])))
    yaw = math.atan2(rotation[1, 0], rotation[0, 0])
    return PartFit(origin=(0.0, 0.0, c), rotation=rotation, quaternion=quaternion_from_matrix(rotation),
                   roll=roll, pitch=pitch, yaw=yaw, plane=(a, b, c),
                   residual_rms=float(math.sqrt(np.mean(deviation**2))),
                   residual_max=float(np.abs(deviation).max()), points=len(deviation))


def offset_shift(fit, units):
    """How far the G54 work offset moves, in the control's units ("inch" or "mm"), to put the work
    Z origin on the part's top face above the work X/Y origin: {axis: shift}. Only Z: without
    edge probes the part's X/Y origin is not measured. Rounded to the control's resolution
    (0.0001 in, 0.001 mm), which an MDC write also carries exactly."""
    if units == "inch":
        return {"Z": round(fit.origin[2] / 0.0254, 4)}
    if units == "mm":
        return {"Z": round(fit.origin[2] * 1000.0, 3)}
    raise ValueError("units must be inch or mm: %r" % units)
