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

    a_i <= min(g_i / stop_time, u_stop(g_i)),               (allowed)
    g_i = max(d_i - stop_distance, 0),
    u_stop(g) = a (sqrt(B^2 + 2 g / a) - B),  B = T_r + tau,

d_i the point's distance from the footprint. The first term is the
approach itself: at it the distance decays as exp(-t / stop_time) towards
stop_distance. The second is the fastest approach from which the base
still stops stop_distance short, reacting within T_r (the points are up
to a scan old, and a control period), through its velocity loop's lag
tau and braking at a, its acceleration limit: the root of
u^2 / (2 a) + B u = g, eq. (protective) with no human motion and the
stop distance as its only margin (`protective_speeds`). Slower than
2 a (stop_time - B) (0.2 m/s with the robot's limits: within 0.1 m of
the stop distance) the exponential approach binds; faster, the braking
does: the base starts to slow where it can still stop (0.9 m short of
the stop distance at 1 m/s), not where the exponential approach alone
would have it brake harder than it can (at 0.5 m, needing 2 m/s^2).
Approaching at the bound, the bound falls no faster than a (by
a u / (u + a B) per second), so the command follows it within the
acceleration limits. The whole command is scaled
by the largest factor in [0, 1] that meets every bound (the separation
scale), so its direction is kept, as by the velocity limits
(drake_wbc.math.command_limits.limit_base_velocity); motion away from or
along an obstacle is not limited.

The paper has no such rule; these labels, (approach) and (allowed), are
this module's. Each has one scalar-generic reference body here (float
arrays and numpy object arrays of AutoDiffXd): `approach_rows`,
`allowed_speeds`, `scale_for_rows`, and `separation_state`, what the
base command limiter keeps of a scan. The last two have a fast float
kernel each (drake_wbc.math.kernels), which the limiter runs in double.
`separation_scale` and `approach_speeds` are the checked functions to call
by hand.
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from drake_wbc.math.compiled import compiled, float_array
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
    in_closed_range,
    non_negative,
    positive,
    whole_number,
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


def allowed_speeds(d, stop_distance, stop_time, timing):
    """The largest approach speed to each point at distance d (M,),
    eq. (allowed): min(g / stop_time, u_stop(g)), g = max(d -
    stop_distance, 0), u_stop the fastest approach from which the base
    stops stop_distance short (`protective_speeds` with no human motion).

    Args:
        d: (M,) distances from the footprint, m (float or AutoDiffXd).
        stop_distance: m >= 0.
        stop_time: s > 0.
        timing: ProtectiveTiming, the base's reaction, lag and braking.

    Outside those ranges (not checked) a NaN or a stop_time of 0 gives
    NaN, which the minimum passes on, and an infinite stop_distance 0.
    """
    gap = np.maximum(d - stop_distance, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):  # stop_time 0
        approach = gap / stop_time
    return np.minimum(approach,
                      protective_speeds(d, 0.0, timing, stop_distance))


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


def separation_state(points, half_sizes, stop_distance, stop_time, timing,
                     count=NEAREST_POINTS):
    """The `approach_rows` (count, 3), raveled row by row, then the
    `allowed_speeds` (count,) of the `nearest_points` of `points`: what
    the base command limiter keeps of a scan, as one (4 count,) array.

    Args:
        points: (M, 2) finite obstacle points in T_b, m (M may be 0).
        half_sizes: the footprint's half-sizes (a, b), m.
        stop_distance: m >= 0 left between the footprint and an obstacle.
        stop_time: s > 0, the time constant of the approach.
        timing: ProtectiveTiming, the base's reaction, lag and braking.
        count: how many points to keep, >= 1.
    """
    rows, d = approach_rows(nearest_points(points, half_sizes, count),
                            half_sizes)
    return np.concatenate([rows.ravel(), allowed_speeds(
        d, stop_distance, stop_time, timing)])


def separation_scale(command, points, half_sizes, stop_distance,
                     stop_time, timing):
    """The largest factor s in [0, 1] such that s * command approaches no
    obstacle point faster than eq. (allowed) lets it (eq. (approach)), its
    arguments checked.

    Args:
        command: (3,) [vx, vy, wz] in T_b, finite.
        points: (M, 2) finite obstacle points in T_b, m (M may be 0).
        half_sizes: the footprint's half-sizes (a, b) >= 0, m.
        stop_distance: m >= 0 left between the footprint and an obstacle.
        stop_time: s > 0, the time constant of the approach.
        timing: ProtectiveTiming (`protective_timing`): the base's
            reaction time, velocity lag and braking.

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
        positive("stop_time", stop_time), _checked_timing(timing)))


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


def _checked_timing(timing):
    reaction, lag, deceleration = as_vector("timing", timing, 3)
    return ProtectiveTiming(non_negative("timing.reaction_time", reaction),
                            non_negative("timing.lag", lag),
                            positive("timing.deceleration", deceleration))


# --- the fast float kernels of the tick ------------------------------------


def _scan(rng, half_sizes, count):
    """Random obstacle points of a few kinds around a footprint of
    `half_sizes`: a scan, one with points inside, fewer than `count`,
    duplicates (ties), points on the edges and corners, none; in one case
    in ten with a few points of a coordinate (or both) NaN or infinite."""
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
    if len(points) and rng.random() < 0.1:
        for i in rng.integers(0, len(points), rng.integers(1, 4)):
            points[i, [[0], [1], [0, 1]][rng.integers(3)]] = rng.choice(
                [np.nan, np.inf, -np.inf])
    return points


def _separation_state_inputs(rng):
    """Random arguments of separation_state (`_scan`'s points); in one
    case in ten the stop distance or the stop time NaN, 0 or infinite,
    outside their checked ranges."""
    half_sizes = (float(rng.uniform(0.2, 0.6)), float(rng.uniform(0.2, 0.5)))
    count = int(rng.choice([1, 4, NEAREST_POINTS]))
    timing = ProtectiveTiming(float(rng.uniform(0.0, 0.2)),
                              float(rng.uniform(0.0, 0.5)),
                              float(rng.uniform(0.3, 3.0)))
    points = _scan(rng, half_sizes, count)
    stop = [float(rng.uniform(0.0, 0.3)), float(rng.uniform(0.1, 1.0))]
    if rng.random() < 0.1:
        stop[rng.integers(2)] = float(rng.choice(
            [np.nan, 0.0, np.inf, -np.inf]))
    return (points, half_sizes, *stop, timing, count)


@fast_kernel(separation_state, sample=_separation_state_inputs)
def separation_state_float(points, half_sizes, stop_distance, stop_time,
                           timing, count=NEAREST_POINTS):
    """`separation_state` of float points, in compiled loops: the
    footprint gaps (drake_wbc.math.repulsion.footprint_gap), the `count`
    nearest kept in one pass (the first `count` of a stable sort, padded
    with FAR points), their geometry (repulsion.footprint_geometry), then
    their rows and allowed speeds."""
    points = np.reshape(float_array(points), (-1, 2))
    near = _nearest_loop(points, footprint_gap(points, half_sizes),
                         int(count))
    d, nx, ny = footprint_geometry(near, half_sizes)
    reaction, lag, deceleration = timing
    return _state_loop(near, d, nx, ny, float(stop_distance),
                       float(stop_time), float(reaction + lag),
                       float(deceleration))


@compiled
def _nearest_loop(points, gap, count):
    """The `count` rows of `points` of smallest `gap`, nearest first, ties
    (and NaNs, after every number) in their order, then FAR points: one
    pass, each point inserted into the sorted few kept so far."""
    kept = np.empty(count, np.int64)
    kept_gap = np.empty(count)
    size = 0
    for i in range(gap.shape[0]):
        g = gap[i]
        if size < count:
            j = size
            size += 1
        elif g < kept_gap[count - 1] or (
                kept_gap[count - 1] != kept_gap[count - 1] and g == g):
            j = count - 1
        else:
            continue
        while j > 0 and (g < kept_gap[j - 1] or (
                kept_gap[j - 1] != kept_gap[j - 1] and g == g)):
            kept[j] = kept[j - 1]
            kept_gap[j] = kept_gap[j - 1]
            j -= 1
        kept[j] = i
        kept_gap[j] = g
    near = np.empty((count, 2))
    for k in range(count):
        if k < size:
            near[k, 0] = points[kept[k], 0]
            near[k, 1] = points[kept[k], 1]
        else:
            near[k, 0] = FAR
            near[k, 1] = 0.0
    return near


@compiled
def _state_loop(near, d, nx, ny, stop_distance, stop_time, b,
                deceleration):
    """The rows of eq. (approach) at the footprint's nearest points
    r = p - d n, then the allowed speeds of eq. (allowed), b = T_r + tau
    and a = deceleration (`protective_speeds`' order of operations)."""
    count = near.shape[0]
    state = np.empty(4 * count)
    for k in range(count):
        rx = near[k, 0] - d[k] * nx[k]
        ry = near[k, 1] - d[k] * ny[k]
        state[3 * k] = nx[k]
        state[3 * k + 1] = ny[k]
        state[3 * k + 2] = rx * ny[k] - ry * nx[k]
        gap = d[k] - stop_distance
        gap = gap if not gap < 0.0 else 0.0
        braking = deceleration * (
            np.sqrt(b * b + 2.0 * gap / deceleration) - b)
        approach = gap / stop_time
        # The minimum as numpy's: a NaN of either side is the result.
        state[3 * count + k] = (approach if approach < braking
                                or approach != approach else braking)
    return state


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
    """`scale_for_rows` of float arrays, in one compiled loop: the same
    divisions and minimum, so the same value (the approach speeds' sums
    may round differently from numpy's matrix product)."""
    return _scale_loop(float_array(command),
                       np.reshape(float_array(rows), (-1, 3)),
                       float_array(allowed))


@compiled
def _scale_loop(command, rows, allowed):
    scale = 1.0
    found = False
    for i in range(rows.shape[0]):
        # From +0.0, as a matrix product sums: a sum of zeros is +0.0.
        speed = (0.0 + rows[i, 0] * command[0] + rows[i, 1] * command[1]
                 + rows[i, 2] * command[2])
        bound = allowed[i]
        if speed > bound:
            # speed 0 only with a negative bound: a signed infinity
            ratio = bound / speed
            if not found or ratio < scale:
                scale = ratio
                found = True
    if not found:
        return 1.0
    return min(max(scale, 0.0), 1.0)


# --- the protective separation distance of ISO/TS 15066 (moving people) ---

HUMAN_SPEED = 1.6
"""m/s: ISO 13855's approach speed of a walking person (K = 1600 mm/s),
for a separation beyond NEAR_DISTANCE."""

HUMAN_SPEED_NEAR = 2.0
"""m/s: ISO 13855's approach speed within NEAR_DISTANCE (K = 2000 mm/s for
S <= 500 mm)."""

NEAR_DISTANCE = 0.5
"""m: where ISO 13855's approach speed changes from HUMAN_SPEED_NEAR to
HUMAN_SPEED."""


SETTLING = 3.0
"""The base's velocity lag tau settles in SETTLING tau (to 5%): its
stopping time in eq. (protective)."""


@dataclass
class PeopleSeparationParameters:
    """Speed and separation from tracked moving people (ISO/TS 15066's
    speed and separation monitoring; drake_wbc.math.people tracks them).

    The times and distances of the protective separation distance,
    eq. (protective): the human's approach speed (ISO 13855's values,
    which may be raised, not lowered), the sensor's latency (the scan
    period, a point up to one scan old, plus the processing) and the
    margins C, Z_d and Z_r. The base's own reaction and stopping come from
    its limits (`ProtectiveTiming`).

    Attributes:
        human_speed: m/s >= HUMAN_SPEED (1.6), a person's approach speed
            beyond near_distance.
        human_speed_near: m/s >= HUMAN_SPEED_NEAR (2.0), within it.
        near_distance: m >= NEAR_DISTANCE (0.5).
        scan_period: s > 0, the LIDARs' scan period (1 / 15 Hz): a
            person is seen up to one scan late. At least the LIDARs'
            (checked where the scenario is built).
        processing_time: s >= 0, from the end of a scan to the points at
            the controller (the driver's and the tracking's share):
            0.02 s, the TiM571's output delay is under 10 ms and the
            tracking runs in the tick that receives the scan.
        intrusion: C, m >= 0: how far a body part may reach towards the
            base beyond the points the LIDAR sees. The LIDARs cut the
            scene at the legs; a walking person's hands and torso lead
            the legs by about a forearm: 0.2 m (ISO 13855's reach-over
            allowances for a 2-D field are 0.85 m and more, but they
            guard a fixed hazard against a reach into it; here what is
            seen is the person's whole outline at knee height, and what
            it misses is the arm's swing ahead of it).
        sensor_uncertainty: Z_d, m >= 0: the LIDAR's range error and the
            beams' spacing at the range where a person is tracked: the
            TiM571's systematic error is +-60 mm, 0.05 m is its typical
            value plus 0.33 degree at 3 m (0.017 m).
        robot_uncertainty: Z_r, m >= 0: the base's position uncertainty
            over a stop (odometry, the footprint's tolerance): 0.02 m.
        min_speed: m/s in (0, 0.5], the filtered speed above which a
            tracked cluster is a moving person (0.15 m/s: a shuffle, a
            third of a slow walk). A static shape's apparent motion as
            the base drives by is told apart by the other tests, not by
            this speed: the piece of a wall at the edge of a scanner's
            field of view slides along the wall with the base (up to
            0.45 m/s at 1 m/s) but not relative to it, and a crate's
            centroid shifts by less than min_travel. It may be lowered,
            not raised. A person slower keeps the static rule (what a
            standing person has too): in the closed loop a base from full
            speed meets a 0.1 m/s walker at 0.02 m/s.
        moving_scans: scans, >= 1, in a row with the speed above
            min_speed before the cluster counts as moving (3: 0.2 s at
            15 Hz; one jump of a box's visible side is not a walk).
        min_travel: m >= 0, how far from where its track started a
            cluster must be to count as moving (0.5 m: more than the
            shift of a crate's centroid as its visible sides change; at
            1.6 m/s a walker covers it in 0.3 s).
        moving_hold: s >= 0 for which a person who stopped still counts
            as moving (1.0 s).
        cluster_gap: m > 0, the largest step between consecutive points
            of one cluster (0.2 m: a person's legs; more than the 0.017 m
            beam spacing at 3 m).
        max_cluster_size: m > 0, the largest size of a cluster that may
            be a person, from its first point to its last (0.8 m; walls
            and long edges are not tracked and keep the static rule).
        gate: m > 0, the farthest a cluster may be from a track's
            prediction to continue it (0.5 m: 2 m/s over a scan plus a
            person's width).
        tracked_range: m > 0, the farthest from the footprint a cluster
            is tracked (6 m: beyond the largest separation at full
            speed, 4.36 m with the defaults, plus the tracking's start:
            0.5 m of travel).
        alpha, beta: the alpha-beta filter's gains of position and
            velocity, in (0, 1] and (0, 2) (0.5 and 0.3); its
            velocity starts from the finite difference of the first two
            scans.
    """

    human_speed: float = HUMAN_SPEED
    human_speed_near: float = HUMAN_SPEED_NEAR
    near_distance: float = NEAR_DISTANCE
    scan_period: float = 1.0 / 15.0
    processing_time: float = 0.02
    intrusion: float = 0.2
    sensor_uncertainty: float = 0.05
    robot_uncertainty: float = 0.02
    min_speed: float = 0.15
    moving_scans: int = 3
    min_travel: float = 0.5
    moving_hold: float = 1.0
    cluster_gap: float = 0.2
    max_cluster_size: float = 0.8
    gate: float = 0.5
    tracked_range: float = 6.0
    alpha: float = 0.5
    beta: float = 0.3

    def __post_init__(self):
        for name, floor in (("human_speed", HUMAN_SPEED),
                            ("human_speed_near", HUMAN_SPEED_NEAR),
                            ("near_distance", NEAR_DISTANCE)):
            value = positive(name, getattr(self, name))
            if value < floor:
                raise ValueError(
                    f"{name} = {value!r} is not allowed: must be at least "
                    f"ISO 13855's {floor!r} (a limit may be tightened, not "
                    "widened)")
        if not 0.0 < positive("min_speed", self.min_speed) <= 0.5:
            raise ValueError(
                f"min_speed = {self.min_speed!r} is not allowed: must be in "
                "(0, 0.5] m/s (a person walking slowly is still tracked; "
                "it may be lowered, not raised)")
        for name in ("scan_period", "cluster_gap",
                     "max_cluster_size", "gate", "tracked_range"):
            positive(name, getattr(self, name))
        for name in ("processing_time", "intrusion", "sensor_uncertainty",
                     "robot_uncertainty", "moving_hold", "min_travel"):
            non_negative(name, getattr(self, name))
        self.moving_scans = whole_number("moving_scans", self.moving_scans,
                                         1)
        self.alpha = in_closed_range("alpha", self.alpha, 0.0, 1.0)
        positive("alpha", self.alpha)
        if not 0.0 < positive("beta", self.beta) < 2.0:
            raise ValueError(f"beta = {self.beta!r} is not allowed: must "
                             "be in (0, 2) (a stable alpha-beta filter)")

    @property
    def margin(self):
        """C + Z_d + Z_r, m."""
        return self.intrusion + self.sensor_uncertainty + \
            self.robot_uncertainty


class ProtectiveTiming(NamedTuple):
    """The base's side of eqs. (protective) and (allowed).

    Attributes:
        reaction_time: T_r, s: from a person's step (or the base's
            advance towards a point) to the base's command reacting: the
            scan period (a point is up to a scan old), the processing
            time and one control period (the limiter's state is the
            tick's).
        lag: tau, s: the base's velocity loop lag (its drive starts to
            brake within it).
        deceleration: a, m/s^2 > 0: the base's braking (the smaller
            planar acceleration limit).
    """

    reaction_time: float
    lag: float
    deceleration: float


def protective_timing(people, time_step, acceleration_limits, lag):
    """ProtectiveTiming from the PeopleSeparationParameters `people`, the
    control period, the base's acceleration limits [x, y, yaw] and its
    velocity loop lag (its description's base.velocity_lag)."""
    return ProtectiveTiming(
        people.scan_period + people.processing_time + time_step, lag,
        min(acceleration_limits[0], acceleration_limits[1]))


def protective_separation(robot_speed, human_speed, timing, margin):
    """The protective separation distance of ISO/TS 15066 (5.5.4.2),
    eq. (protective) (this module's label; the paper has none):

        S_p = S_h + S_r + S_s + C + Z_d + Z_r,
        S_h = v_h (T_r + T_s),  S_r = v_r T_r,
        T_s = SETTLING tau + v_r / a,  S_s = v_r tau + v_r^2 / (2 a),

    the base's stop distance modelled as its lag tau (coasting) then
    braking at a: the lagged loop's stop when its command ramps down at a
    (the ramp's v_r^2 / (2 a), and v_r tau that a first-order lag adds
    to any ramp), and a bound of its stop when the command is cut to zero
    at once (u tau for u <= a tau, u^2 / (2 a) + a tau^2 / 2 above, the
    loop saturated at a). Its
    stopping time, which the person walks on for, is the braking's v_r / a
    and the lag's settling: a first-order lag never quite ends, and
    SETTLING tau (3 tau: down to 5%, under 1 cm/s from the 0.2 m/s a lag
    of 0.2 s holds at 1 m/s^2) is when the base is at rest.

    Args:
        robot_speed: v_r >= 0, the base's approach speed, m/s.
        human_speed: v_h >= 0, the person's, m/s.
        timing: ProtectiveTiming.
        margin: C + Z_d + Z_r, m.

    Float or AutoDiffXd arguments alike.
    """
    reaction, lag, a = timing
    stopping_time = SETTLING * lag + robot_speed / a
    return (human_speed * (reaction + stopping_time)
            + robot_speed * reaction
            + robot_speed * lag + robot_speed * robot_speed / (2.0 * a)
            + margin)


def check_people_coverage(people, timing, speed, path="safety.people"):
    """Checks that the tracking of `people` (PeopleSeparationParameters)
    can protect them from a base approaching at `speed` (m/s, its rated
    planar speed) with `timing` (ProtectiveTiming): parameters that are
    each legal but together leave a walker unprotected are refused.

    - tracked_range: a person walking straight at the base is tracked
      from tracked_range off the footprint and counts as moving once it
      has walked max(min_travel, human_speed moving_scans scan_period);
      it must be farther off then than the protective separation S_p of
      eq. (protective) at `speed` (4.36 m with the defaults and the
      shipped base, so at least 4.86 m), or the base, at full speed, is
      first told of the person where it can no longer stop short.
    - gate: a person walks up to human_speed_near scan_period between
      two scans (a new track's velocity is not known until its second),
      so a smaller gate would lose every walker's track at each scan.

    Not covered: a command along both planar axes at both limits is
    faster than either (1.41 m/s for the shipped base's 1.0 and 1.0;
    the hardware interface holds the planar speed to the smaller limit,
    a simulation does not), and needs 1.3 m more.

    Raises:
        ValueError: naming the field (under `path`), its value and the
            least that protects.
    """
    walked = max(people.min_travel,
                 people.human_speed * people.moving_scans
                 * people.scan_period)
    needed = protective_separation(speed, people.human_speed, timing,
                                   people.margin) + walked
    if people.tracked_range < needed:
        raise ValueError(
            f"{path}.tracked_range = {people.tracked_range!r} is not "
            f"allowed: must be at least {needed:.3g} m, the protective "
            f"separation at the base's {speed:g} m/s plus the "
            f"{walked:.3g} m a person walks before counting as moving "
            "(a person first seen closer is met at a speed the base "
            "cannot stop from in time)")
    step = people.human_speed_near * people.scan_period
    if people.gate < step:
        raise ValueError(
            f"{path}.gate = {people.gate!r} is not allowed: must be at "
            f"least {step:.3g} m, the step of a person at "
            f"{people.human_speed_near:g} m/s between two scans (a "
            "smaller gate loses every walker's track)")


def protective_speeds(d, human_speed, timing, margin):
    """The largest approach speeds v_r >= 0 of the base to people at the
    separations d that keep d >= S_p(v_r), eq. (protective) solved for
    v_r: S_p is a quadratic

        v_r^2 / (2 a) + B v_r + v_h (T_r + SETTLING tau) + margin - d = 0,
        B = v_h / a + T_r + tau,

    so v_r = a (sqrt(B^2 + 2 K / a) - B),
    K = d - margin - v_h (T_r + SETTLING tau),
    and 0 where K <= 0 (the person closer than the base's stop from rest).

    Args:
        d: (M,) separations, m (float or AutoDiffXd object array).
        human_speed: (M,) the people's approach speeds, m/s.
        timing: ProtectiveTiming.
        margin: C + Z_d + Z_r, m.
    """
    reaction, lag, a = timing
    d = np.asarray(d)
    v_h = np.asarray(human_speed)
    b = v_h / a + reaction + lag
    k = d - margin - v_h * (reaction + SETTLING * lag)
    # max(K, 0), NaN staying NaN, its zero of d's type: 0 K would make an
    # infinite margin's K = -inf a NaN (where K < 0, d is finite).
    k = np.where(value_of(k) < 0.0, 0.0 * d, k)
    return a * (np.sqrt(b * b + 2.0 * k / a) - b)


def iso_human_speed(d, people):
    """ISO 13855's approach speed (m/s) at the separations d (M,):
    human_speed_near within near_distance, human_speed beyond."""
    return np.where(value_of(np.asarray(d)) <= people.near_distance,
                    people.human_speed_near, people.human_speed)


def people_rows(nearest, velocities, half_sizes, people, timing, count):
    """The approach rows (count, 3) and allowed approach speeds (count,)
    of moving people: for each, the `approach_rows` of its point nearest
    the footprint and the largest approach speed that keeps the
    separation at least S_p, eq. (protective) (`protective_speeds`), the
    rest padded with rows that never limit (zero rows, FAR allowed).

    The person's approach speed is ISO 13855's (`iso_human_speed`), or its
    measured speed towards the footprint where that is faster. A person
    walking away or along uses ISO's speed too, not the measured one: the
    measurement is a few scans old and a person turns round within a
    step, well inside the reaction and stopping time of the base. The
    rows bound only the base's approach: moving away from or along a
    person is never limited, whatever the separation.

    Args:
        nearest: (P, 2) the people's nearest points in T_b, P <= count.
        velocities: (P, 2) their velocities in T_b (the world's, rotated).
        half_sizes: the footprint's half-sizes (a, b), m.
        people: PeopleSeparationParameters.
        timing: ProtectiveTiming.
        count: rows kept.

    Returns:
        ((count, 3) rows, (count,) allowed speeds), float.
    """
    rows = np.zeros((count, 3))
    allowed = np.full(count, FAR)
    if not len(nearest):
        return rows, allowed
    nearest = np.asarray(nearest, dtype=float).reshape(-1, 2)[:count]
    if len(nearest):
        g, d = approach_rows(nearest, half_sizes)
        velocities = np.asarray(velocities, dtype=float).reshape(-1, 2)
        closing = -(velocities[:len(nearest)] * g[:, :2]).sum(axis=1)
        speed = np.maximum(iso_human_speed(d, people), closing)
        rows[:len(g)] = g
        allowed[:len(g)] = protective_speeds(d, speed, timing,
                                             people.margin)
    return rows, allowed
