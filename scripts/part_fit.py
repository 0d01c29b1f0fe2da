"""The part's frame from the probe points of its top face (surface_mapper's part frame). No ROS.

A least-squares plane z = a x + b y + c through the probe points (metres, in the frame they were
probed in: the work frame of the program) gives the part's tilt and height. The part frame:
  origin  the point of the plane above the frame's X/Y origin: (0, 0, c);
  z axis  the plane's normal (pointing up, +Z);
  x axis  the frame's X direction laid onto the plane: (1, 0, a), normalised;
  y axis  z x x.
So its yaw is 0 and, as roll/pitch/yaw (rotations about the fixed X, Y, Z axes, in that order):
pitch = -atan(a), roll = atan(b / sqrt(1 + a^2)).

The residuals are the points' Z deviations from the plane (what the probe measured along), RMS
and largest absolute.

Edge probes (fit_edges) give the part's rotation about Z and its X/Y origin: points touched on two
perpendicular side faces of a rectangular part, X/Y in the same frame as the top-face points:
  x side  the side the part's X axis runs along (e.g. its front face, touched moving in +Y): at
          least 2 points; its least-squares line gives the yaw (the part's +X is the line's
          direction pointing to +X of the frame, so the yaw lies in (-90, 90] degrees);
  y side  the perpendicular side (e.g. its left face, touched moving in +X): 1 or more points; its
          line is taken perpendicular to the x side (a square part; one point suffices).
The X/Y origin is the corner where the two lines meet. With the x side only, the yaw and the x
side's line are known, not where along it the part starts: the origin is then the foot of the
perpendicular from the frame's X/Y origin onto that line, and `corner` is False.
The points are the contact points on the faces: the probe ball's radius is not compensated here
(the program prints what its probing cycle reports; a program that prints the ball centre must
add the radius itself). The edge residuals are the points' distances from their fitted lines.
When edges are given, the frame's x axis is the x side's direction laid onto the plane and the
origin is the plane's point above the corner.
"""
import collections
import math

import numpy as np

MIN_POINTS = 3
MIN_EDGE_SPAN = 1e-6  # m: edge points closer together than this are one spot (no direction)

PartFit = collections.namedtuple(
    "PartFit", "origin rotation quaternion roll pitch yaw plane residual_rms residual_max points edges",
    defaults=(None,))
PartFit.__doc__ = """The part frame in the points' frame.
origin: (x, y, z) m; rotation: 3 x 3 matrix whose columns are the part's axes; quaternion:
(x, y, z, w); roll, pitch, yaw: rad; plane: (a, b, c) of z = a x + b y + c; residual_rms,
residual_max: m; points: how many were fitted; edges: the EdgeFit that gave the X/Y origin and
the yaw, or None (origin above the frame's X/Y origin, yaw 0)."""

EdgeFit = collections.namedtuple(
    "EdgeFit", "yaw origin corner residual_rms residual_max x_points y_points message")
EdgeFit.__doc__ = """The part's rotation about Z and X/Y origin from its side faces.
yaw: rad; origin: (x, y) m, the corner (corner True) or, with the x side only (corner False), the
point of the x side's line nearest the frame's X/Y origin; residual_rms, residual_max: m, the
points' distances from their lines (both sides); x_points, y_points: points fitted per side;
message: the fit in words (with the x side only: which coordinate is not known)."""


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


def finite_xy(points, side):
    """points (N x 2 or N x 3, m) as N x 2 X/Y; FitError for a value that is not finite."""
    xy = np.asarray(points, dtype=float)
    xy = xy.reshape(len(xy), -1)[:, :2] if xy.size else np.zeros((0, 2))
    bad = np.flatnonzero(~np.isfinite(xy).all(axis=1))
    if len(bad):
        raise FitError("%s point %d is not finite: %s" % (side, bad[0] + 1, xy[bad[0]].tolist()))
    return xy


def fit_edges(x_side, y_side=()):
    """EdgeFit of the points on the x side (>= 2, not all in one spot) and the y side (>= 0).

    Raises FitError (no rotation, no X/Y origin) for fewer than 2 x side points, x side points in
    one spot, or a value that is not finite."""
    xs, ys = finite_xy(x_side, "x side"), finite_xy(y_side, "y side")
    if len(xs) < 2:
        raise FitError("the part's rotation needs at least 2 edge points on its x side, got %d: "
                       "no rotation and no X/Y origin" % len(xs))
    centre = xs.mean(axis=0)
    _, spread, axes = np.linalg.svd(xs - centre)
    if spread[0] < MIN_EDGE_SPAN:
        raise FitError("the %d x side edge points lie in one spot: no direction of the side; touch the "
                       "side at points some distance apart" % len(xs))
    direction = axes[0] if axes[0][0] > 0 or axes[0][0] == 0 and axes[0][1] > 0 else -axes[0]
    normal = np.array([-direction[1], direction[0]])
    x_offset = float(normal @ centre)  # the x side's line: normal . p = x_offset
    distances = list(xs @ normal - x_offset)
    yaw = math.atan2(direction[1], direction[0])
    if len(ys) >= 2:
        _, y_spread, y_axes = np.linalg.svd(ys - ys.mean(axis=0))
        if y_spread[0] >= MIN_EDGE_SPAN and abs(y_axes[0] @ direction) > math.cos(math.pi / 4):
            raise FitError("the %d y side edge points run along the x side (%d points), on one line with it, not "
                           "across it: no corner; touch the perpendicular side" % (len(ys), len(xs)))
    if len(ys):
        y_offset = float(np.mean(ys @ direction))  # the y side's line: direction . p = y_offset
        distances += list(ys @ direction - y_offset)
        origin = x_offset * normal + y_offset * direction
        message = "corner (%.4f, %.4f) mm, yaw %.4f mrad" % (origin[0] * 1e3, origin[1] * 1e3, yaw * 1e3)
    else:
        origin = x_offset * normal
        message = ("x side only: yaw %.4f mrad and the side's line through (%.4f, %.4f) mm; where the part "
                   "starts along it (its X origin) is not known: no y side edge points"
                   % (yaw * 1e3, origin[0] * 1e3, origin[1] * 1e3))
    distances = np.array(distances)
    return EdgeFit(yaw=yaw, origin=(float(origin[0]), float(origin[1])), corner=bool(len(ys)),
                   residual_rms=float(math.sqrt(np.mean(distances**2))),
                   residual_max=float(np.abs(distances).max()), x_points=len(xs), y_points=len(ys),
                   message=message)


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


def fit_part_frame(points, edges=None):
    """The part frame (PartFit) of the probed top face; raises FitError with the reason.

    edges: an EdgeFit (fit_edges) for the X/Y origin and the yaw, or None (origin above the
    frame's X/Y origin, yaw 0)."""
    (a, b, c), deviation = fit_plane(points)
    x0, y0 = edges.origin if edges else (0.0, 0.0)
    along = np.array([math.cos(edges.yaw), math.sin(edges.yaw)]) if edges else np.array([1.0, 0.0])
    z_axis = np.array([-a, -b, 1.0]) / math.sqrt(a * a + b * b + 1.0)
    x_axis = np.array([along[0], along[1], a * along[0] + b * along[1]])
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    rotation = np.column_stack([x_axis, y_axis, z_axis])
    roll = math.atan2(rotation[2, 1], rotation[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, rotation[2, 0])))
    yaw = math.atan2(rotation[1, 0], rotation[0, 0])
    return PartFit(origin=(x0, y0, a * x0 + b * y0 + c), rotation=rotation, quaternion=quaternion_from_matrix(rotation),
                   roll=roll, pitch=pitch, yaw=yaw, plane=(a, b, c),
                   residual_rms=float(math.sqrt(np.mean(deviation**2))),
                   residual_max=float(np.abs(deviation).max()), points=len(deviation), edges=edges)


def offset_shift(fit, units):
    """How far the G54 work offset moves, in the control's units ("inch" or "mm"), to put the work
    origin on the part: {axis: shift}. Z onto the top face (above the corner when there is one),
    and X and Y onto the corner when the edges gave one (fit.edges.corner); otherwise only Z (the
    part's X/Y origin is not measured). The yaw is not in it: G54 has no rotation. Rounded to the
    control's resolution (0.0001 in, 0.001 mm), which an MDC write also carries exactly."""
    if units not in ("inch", "mm"):
        raise ValueError("units must be inch or mm: %r" % units)
    scale, decimals = (1 / 0.0254, 4) if units == "inch" else (1000.0, 3)
    axes = ("X", "Y", "Z") if fit.edges is not None and fit.edges.corner else ("Z",)
    return {axis: round(fit.origin["XYZ".index(axis)] * scale, decimals) for axis in axes}
