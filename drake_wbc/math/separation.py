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

    a_i = (v + w x r_i) . n_i,                              (approach)

(v the planar velocity, w the yaw rate, r_i the footprint's point
nearest to point i and n_i the unit direction from it to the point, all
in T_b) must not exceed

    a_i <= max(d_i - stop_distance, 0) / stop_time,         (allowed)

d_i the point's distance from the footprint. The whole command is scaled
by the largest factor in [0, 1] that meets every bound (the separation
scale), so its direction is kept, as by the velocity limits
(drake_wbc.math.command_limits.limit_base_velocity); motion away from or
along an obstacle is not limited. Approaching at the bound, the distance
decays as exp(-t / stop_time) towards stop_distance, so the base stops
stop_distance short of the obstacle; the base's own lag and the
acceleration limit take some of that margin.

The paper has no such rule; these labels, (approach) and (allowed), are
this module's. Each has one scalar-generic reference body here (float
arrays and numpy object arrays of AutoDiffXd): `approach_rows`,
`allowed_speeds`, `scale_for_rows`, and `separation_state`, what the
base command limiter keeps of a scan. The last two have a fast float
kernel each (drake_wbc.math.kernels), which the limiter runs in double.
`separation_scale` and `approach_speeds` are the checked functions to call
by hand.
"""

import math

import numpy as np

from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.repulsion import (
    RepulsiveFieldParameters,
    footprint_distance,
    footprint_gap,
    footprint_geometry,
)
from drake_wbc.math.scalar_support import value_of
from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    non_negative,
    positive,
)

NEAREST_POINTS = 16
"""How many obstacle points the base command limiter keeps, the nearest
to the footprint."""

FAR = 1e3
"""m: where `nearest_points` puts the padding when there are fewer
points."""


def _as_points(points):
    """(M, 2) points: float, or an object array of AutoDiffXd as given."""
    points = np.asarray(points)
    if points.dtype != object:
        points = points.astype(float, copy=False)
    return np.reshape(points, (-1, 2))


def nearest_points(points, half_sizes, count=NEAREST_POINTS):
    """The `count` points nearest the footprint, (count, 2) in T_b, nearest
    first (ties in their order), the rest padded with points FAR ahead
    (which never limit anything).

    Args:
        points: (M, 2) finite obstacle points in T_b, m (M may be 0);
            float, or AutoDiffXd (ranked by their values).
        half_sizes: the footprint's half-sizes (a, b), m.
        count: how many to keep, >= 1.
    """
    points = _as_points(points)
    if points.dtype == object and len(points):
        # AutoDiffXd padding (of zero derivative), not floats among them.
        kept = np.tile(0.0 * points[:1] + [FAR, 0.0], (count, 1))
    else:
        kept = np.full((count, 2), [FAR, 0.0])
    if len(points):
        kept[:min(count, len(points))] = points[_nearest_first(
            footprint_gap(value_of(points), half_sizes), count)]
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
    eq. (approach), and the points' distances d (M,) from the footprint.

    With r_i = p_i - d_i n_i the footprint's nearest point,
    a_i = (v + w x r_i) . n_i = [n_x, n_y, r_x n_y - r_y n_x] [vx, vy, wz]:
    linear in the command, so a tick that keeps its obstacle points needs
    only G and d, not the geometry again. d and n are the repulsive
    field's (drake_wbc.math.repulsion.footprint_distance): on or inside
    the footprint d = 0 and n is the outward normal of the nearest side.

    Args:
        points: (M, 2) obstacle points in T_b, m, float or AutoDiffXd.
        half_sizes: the footprint's half-sizes (a, b), m.
    """
    points = _as_points(points)
    d, n = footprint_distance(points, RepulsiveFieldParameters(
        half_sizes=half_sizes))
    # The footprint's nearest point r = p - d n.
    rx, ry = points[:, 0] - d * n[:, 0], points[:, 1] - d * n[:, 1]
    return np.column_stack([n[:, 0], n[:, 1], rx * n[:, 1] - ry * n[:, 0]]), d


def allowed_speeds(d, stop_distance, stop_time):
    """The largest approach speed max(d - stop_distance, 0) / stop_time
    to each point at distance d (M,), eq. (allowed)."""
    return np.maximum(d - stop_distance, 0.0) / stop_time


def scale_for_rows(command, rows, allowed):
    """The separation scale: the largest factor s in [0, 1] such that
    s * command approaches no point faster than it is allowed to, from the
    points' `approach_rows` G (M, 3) and `allowed_speeds` (M,):
    s = min(1, min over the closing points (G command > allowed) of
    allowed / (G command)), at least 0. The per-tick part of the rule.

    Args:
        command: (3,) [vx, vy, wz] in T_b.
        rows: (M, 3) approach rows.
        allowed: (M,) allowed approach speeds.

    Returns:
        s (1.0 when no bound acts), a float, or an AutoDiffXd where a
        bound acts on AutoDiffXd arguments.
    """
    approach = np.asarray(rows) @ np.asarray(command)
    allowed = np.asarray(allowed)
    closing = value_of(approach) > value_of(allowed)
    if not closing.any():
        return 1.0
    # A closing point at approach speed 0 has a negative bound: numpy's
    # signed infinity (which the clamp below turns into 0 or ignores).
    with np.errstate(divide="ignore"):
        ratios = allowed[closing] / approach[closing]
    return min(max(min(ratios.tolist()), 0.0), 1.0)


def separation_state(points, half_sizes, stop_distance, stop_time,
                     count=NEAREST_POINTS):
    """The `approach_rows` (count, 3), raveled row by row, then the
    `allowed_speeds` (count,) of the `nearest_points` of `points`: what
    the base command limiter keeps of a scan, as one (4 count,) array.

    Args:
        points: (M, 2) finite obstacle points in T_b, m (M may be 0).
        half_sizes: the footprint's half-sizes (a, b), m.
        stop_distance: m >= 0 left between the footprint and an obstacle.
        stop_time: s > 0, the time constant of the approach.
        count: how many points to keep, >= 1.
    """
    rows, d = approach_rows(nearest_points(points, half_sizes, count),
                            half_sizes)
    return np.concatenate([rows.ravel(),
                           allowed_speeds(d, stop_distance, stop_time)])


def separation_scale(command, points, half_sizes, stop_distance,
                     stop_time):
    """The largest factor s in [0, 1] such that s * command approaches no
    obstacle point faster than max(d_i - stop_distance, 0) / stop_time
    (eqs. (approach), (allowed)), its arguments checked.

    Args:
        command: (3,) [vx, vy, wz] in T_b, finite.
        points: (M, 2) finite obstacle points in T_b, m (M may be 0).
        half_sizes: the footprint's half-sizes (a, b) >= 0, m.
        stop_distance: m >= 0 left between the footprint and an obstacle.
        stop_time: s > 0, the time constant of the approach.

    Returns:
        s as a float (1.0 when no bound acts).

    Raises:
        ValueError: naming the argument that is not allowed.
    """
    command = as_vector("command", command, 3)
    points = _checked_points(points)
    half_sizes = _checked_half_sizes(half_sizes)
    rows, d = approach_rows(points, half_sizes)
    return scale_for_rows(command, rows, allowed_speeds(
        d, non_negative("stop_distance", stop_distance),
        positive("stop_time", stop_time)))


def approach_speeds(command, points, half_sizes):
    """The speed a_i at which the footprint approaches each point under
    `command`, eq. (approach), and the points' distances d_i, its
    arguments checked.

    Args:
        command: (3,) [vx, vy, wz] in T_b, finite.
        points: (M, 2) finite obstacle points in T_b, m.
        half_sizes: the footprint's half-sizes (a, b) >= 0, m.

    Returns:
        (a, d), two (M,) arrays; a > 0 means approaching.

    Raises:
        ValueError: naming the argument that is not allowed.
    """
    command = as_vector("command", command, 3)
    rows, d = approach_rows(_checked_points(points),
                            _checked_half_sizes(half_sizes))
    return rows @ command, d


def _checked_points(points):
    points = np.asarray(points, dtype=float)
    return as_matrix("points", points.reshape(-1, 2) if points.size == 0
                     else points, (None, 2))


def _checked_half_sizes(half_sizes):
    return tuple(non_negative("half_sizes", a)
                 for a in as_vector("half_sizes", half_sizes, 2))


# --- the fast float kernels of the tick ------------------------------------


def _scan(rng, half_sizes, count):
    """Random obstacle points of a few kinds around a footprint of
    `half_sizes`: a scan, one with points inside, fewer than `count`,
    duplicates (ties), points on the edges and corners, none."""
    kind = rng.choice(["scan", "inside", "few", "ties", "edge", "none"])
    size = int(rng.integers(20, 400))
    radius = rng.uniform(0.3, 5.0, size)
    angle = rng.uniform(-np.pi, np.pi, size)
    points = np.column_stack([radius * np.cos(angle),
                              radius * np.sin(angle)])
    a, b = half_sizes
    if kind == "inside":
        points[rng.integers(0, size, 3)] = rng.uniform(
            -1.0, 1.0, (3, 2)) * [a, b]
    elif kind == "few":
        points = points[:int(rng.integers(1, count + 1))]
    elif kind == "ties":
        points = np.concatenate([points, points[::2], -points[::3]])
    elif kind == "edge":
        points[:6] = [[a, 0.0], [-a, 0.1 * b], [0.0, b], [0.5 * a, -b],
                      [a, b], [-a - 1e-12, -b]]
    elif kind == "none":
        points = np.zeros((0, 2))
    return points


def _separation_state_inputs(rng):
    half_sizes = (float(rng.uniform(0.2, 0.6)), float(rng.uniform(0.2, 0.5)))
    count = int(rng.choice([1, 4, NEAREST_POINTS]))
    return (_scan(rng, half_sizes, count), half_sizes,
            float(rng.uniform(0.0, 0.3)), float(rng.uniform(0.1, 1.0)),
            count)


@fast_kernel(separation_state, sample=_separation_state_inputs)
def separation_state_float(points, half_sizes, stop_distance, stop_time,
                           count=NEAREST_POINTS):
    """`separation_state` of float points: with at least `count` points
    all outside the footprint (the usual scan) the selected points'
    distances and offsets are taken from the ranking rather than computed
    again; otherwise the reference's steps on the float geometry."""
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
            # The geometry's outside case and approach_rows, on (count, 2)
            # blocks: n = sign(p) o / d, r = p - d n.
            near = points[kept]
            n = np.copysign(offsets[kept] / d[:, None], near)
            near -= d[:, None] * n
            state = np.empty(4 * count)
            rows = state[:3 * count].reshape(count, 3)
            rows[:, :2] = n
            rows[:, 2] = near[:, 0] * n[:, 1] - near[:, 1] * n[:, 0]
            state[3 * count:] = allowed_speeds(d, stop_distance, stop_time)
            return state
    near = nearest_points(points, half_sizes, count)
    d, nx, ny = footprint_geometry(near, half_sizes)
    rx, ry = near[:, 0] - d * nx, near[:, 1] - d * ny
    return np.concatenate([
        np.column_stack([nx, ny, rx * ny - ry * nx]).ravel(),
        allowed_speeds(d, stop_distance, stop_time)])


def _scale_inputs(rng):
    m = int(rng.integers(0, 20))
    rows = rng.normal(size=(m, 3))
    allowed = rng.uniform(0.0, 0.5, m)
    if m and rng.random() < 0.3:
        # Beyond the rule's range: a negative bound, a row that never
        # approaches, a point at its bound exactly.
        allowed[rng.integers(0, m)] = -rng.uniform(0.0, 1.0)
        rows[rng.integers(0, m)] = [0.0, 0.0, 0.0]
        allowed[rng.integers(0, m)] = 0.0
    command = rng.normal(size=3) * rng.choice([0.0, 1e-3, 0.3, 3.0])
    return command, rows, allowed


@fast_kernel(scale_for_rows, sample=_scale_inputs)
def scale_for_rows_float(command, rows, allowed):
    """`scale_for_rows` of float arrays: a few rows, so a loop in Python
    floats beats the masked arrays; the same divisions and minimum, so the
    same value."""
    approach = (rows @ command).tolist()
    scale = None
    for speed, bound in zip(approach, np.asarray(allowed).tolist(),
                            strict=True):
        if speed > bound:
            # speed 0 only with a negative bound: numpy's signed infinity
            ratio = (bound / speed if speed != 0.0
                     else -math.copysign(math.inf, speed))
            if scale is None or ratio < scale:
                scale = ratio
    return 1.0 if scale is None else min(max(scale, 0.0), 1.0)
