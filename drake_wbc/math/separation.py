"""Speed and separation: the base never drives into an obstacle faster
than it can stop short of it.

The repulsive field of eq. (cdmp-base) is a coupling of the base's DMP,
not a constraint: a steady velocity input (a worker dragging the robot
by its tool in pHRI mode, eq. (cdmp-wb); a reference along a wall) is
integrated by the coupling C without bound, so any bounded field is
eventually overcome and the base reaches the obstacle. The controller
therefore limits the base command itself, as its last step: for every
obstacle point near the footprint, the speed at which the footprint's
nearest point approaches it,

    a_i = (v + w x r_i) . n_i,

(v the planar velocity, w the yaw rate, r_i the footprint's point
nearest to point i and n_i the unit direction from it to the point, all
in T_b) must not exceed

    a_i <= max(d_i - stop_distance, 0) / stop_time,

d_i the point's distance from the footprint. The whole command is scaled
by the largest factor in [0, 1] that meets every bound
(`separation_scale`), so its direction is kept, as by the velocity limits
(drake_wbc.math.command_limits.limit_base_velocity); motion away from or along
an
obstacle is not limited. Approaching at the bound, the distance decays
as exp(-t / stop_time) towards stop_distance, so the base stops
stop_distance short of the obstacle; the base's own lag and the
acceleration limit take some of that margin.
"""

import math

import numpy as np

from drake_wbc.math.repulsion import footprint_gap, footprint_geometry

NEAREST_POINTS = 16
"""How many obstacle points the base command limiter keeps, the nearest
to the footprint."""

FAR = 1e3
"""m: where `nearest_points` puts the padding when there are fewer
points."""


def nearest_points(points, half_sizes, count=NEAREST_POINTS):
    """The `count` points nearest the footprint, (count, 2) in T_b, the
    rest padded with points FAR ahead (which never limit anything).

    Args:
        points: (M, 2) finite obstacle points in T_b, m (M may be 0).
        half_sizes: the footprint's half-sizes (a, b), m.
        count: how many to keep, >= 1.
    """
    points = np.reshape(np.asarray(points, dtype=float), (-1, 2))
    kept = np.full((count, 2), [FAR, 0.0])
    if len(points):
        kept[:min(count, len(points))] = points[
            _nearest_first(footprint_gap(points, half_sizes), count)]
    return kept


def _nearest_first(distance, count):
    """The indices of the `count` smallest distances, nearest first, ties
    in their order: the first `count` of a stable argsort, without
    sorting the far ones."""
    if len(distance) > 2 * count:
        # Only the candidates up to the count-th smallest distance.
        bound = np.partition(distance, count - 1)[count - 1]
        candidates = (distance <= bound).nonzero()[0]
        return candidates[np.argsort(distance[candidates],
                                     kind="stable")[:count]]
    return np.argsort(distance, kind="stable")[:count]


def approach_rows(points, half_sizes):
    """The rows G (M, 3) with a = G [vx, vy, wz] the approach speeds of
    `approach_speeds`, and the points' distances d (M,).

    With r_i = p_i - d_i n_i the footprint's nearest point,
    a_i = (v + w x r_i) . n_i = [n_x, n_y, r_x n_y - r_y n_x] [vx, vy, wz]:
    linear in the command, so a tick that keeps its obstacle points needs
    only G and d, not the geometry again.

    Args:
        points: (M, 2) obstacle points in T_b, m.
        half_sizes: the footprint's half-sizes (a, b), m.
    """
    points = np.reshape(np.asarray(points, dtype=float), (-1, 2))
    d, nx, ny = footprint_geometry(points, half_sizes)
    # The footprint's nearest point r = p - d n.
    rx, ry = points[:, 0] - d * nx, points[:, 1] - d * ny
    return np.column_stack([nx, ny, rx * ny - ry * nx]), d


def approach_speeds(command, points, half_sizes):
    """The speed a_i at which the footprint approaches each point under
    `command`, and the points' distances d_i (module docstring).

    Args:
        command: (3,) [vx, vy, wz] in T_b.
        points: (M, 2) obstacle points in T_b.
        half_sizes: the footprint's half-sizes (a, b), m.

    Returns:
        (a, d), two (M,) arrays; a > 0 means approaching.
    """
    rows, d = approach_rows(points, half_sizes)
    return rows @ np.asarray(command, dtype=float), d


def allowed_speeds(d, stop_distance, stop_time):
    """The largest approach speed max(d - stop_distance, 0) / stop_time
    to each point at distance d (M,)."""
    return np.maximum(d - stop_distance, 0.0) / stop_time


def separation_scale(command, points, half_sizes, stop_distance,
                     stop_time):
    """The largest factor s in [0, 1] such that s * command approaches no
    point faster than max(d_i - stop_distance, 0) / stop_time.

    Args:
        command: (3,) [vx, vy, wz] in T_b, finite.
        points: (M, 2) obstacle points in T_b (e.g. `nearest_points`).
        half_sizes: the footprint's half-sizes (a, b), m.
        stop_distance: m >= 0 left between the footprint and an obstacle.
        stop_time: s > 0, the time constant of the approach.

    Returns:
        s as a float (1.0 when no bound acts).
    """
    rows, d = approach_rows(points, half_sizes)
    return scale_for_rows(command, rows,
                          allowed_speeds(d, stop_distance, stop_time))


def scale_for_rows(command, rows, allowed):
    """`separation_scale` from the points' `approach_rows` (M, 3) and
    `allowed_speeds` (M,): the per-tick part, a product and a minimum."""
    approach = (rows @ command).tolist()
    scale = None
    # A few rows: a loop in Python floats beats the masked arrays; the
    # same divisions and minimum, so the same value.
    for speed, bound in zip(approach, np.asarray(allowed).tolist(),
                            strict=True):
        if speed > bound:
            # speed 0 only with a negative bound: numpy's signed infinity
            ratio = (bound / speed if speed != 0.0
                     else -math.copysign(math.inf, speed))
            if scale is None or ratio < scale:
                scale = ratio
    return 1.0 if scale is None else min(max(scale, 0.0), 1.0)


def separation_state(points, half_sizes, stop_distance, stop_time,
                     count=NEAREST_POINTS):
    """The `approach_rows` (count, 3), raveled row by row, then the
    `allowed_speeds` (count,) of the `nearest_points` of `points`: what
    the base command limiter keeps of a scan, as one (4 count,) array.

    The same values, bit for bit, as composing those functions; with at
    least `count` points all outside the footprint (the usual scan) the
    selected points' distances and offsets are taken from the ranking
    rather than computed again.

    Args:
        points: (M, 2) finite obstacle points in T_b, m (M may be 0).
        half_sizes: the footprint's half-sizes (a, b), m.
        stop_distance: m >= 0 left between the footprint and an obstacle.
        stop_time: s > 0, the time constant of the approach.
        count: how many points to keep, >= 1.
    """
    points = np.reshape(np.asarray(points, dtype=float), (-1, 2))
    if len(points) >= count:
        offsets = np.abs(points)
        offsets[:, 0] -= half_sizes[0]  # no (2,) array made of a tuple
        offsets[:, 1] -= half_sizes[1]
        np.maximum(offsets, 0.0, out=offsets)
        gap = np.hypot(offsets[:, 0], offsets[:, 1])
        kept = _nearest_first(gap, count)
        d = gap[kept]
        if d.min() > 0.0:
            # footprint_geometry's outside case and approach_rows, on
            # (count, 2) blocks: n = sign(p) o / d, r = p - d n.
            near = points[kept]
            n = np.copysign(offsets[kept] / d[:, None], near)
            near -= d[:, None] * n
            state = np.empty(4 * count)
            rows = state[:3 * count].reshape(count, 3)
            rows[:, :2] = n
            rows[:, 2] = near[:, 0] * n[:, 1] - near[:, 1] * n[:, 0]
            state[3 * count:] = allowed_speeds(d, stop_distance, stop_time)
            return state
    rows, d = approach_rows(nearest_points(points, half_sizes, count),
                            half_sizes)
    return np.concatenate([rows.ravel(),
                           allowed_speeds(d, stop_distance, stop_time)])
