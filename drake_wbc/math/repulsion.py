"""The repulsive field around the base's footprint, U_rep after eq.
(cdmp-base), and its force f_avoid on the base's CDMP.

The distance d of an obstacle point is measured from the footprint's
rectangle (not from the base's centre), so that a long base keeps its
corners clear too. The reference bodies (`footprint_distance`,
`repulsive_potential`, `repulsive_force`) accept float points and numpy
object arrays of AutoDiffXd; their parameters are checked once, in
RepulsiveFieldParameters. The distance and the force have each one float
kernel (drake_wbc.math.kernels), what the controller's tick runs on
hundreds of LIDAR points: `footprint_distance_float` (whose arithmetic,
`footprint_geometry`, and its distance alone, `footprint_gap`, the speed
and separation limits of drake_wbc.math.separation share) and
`repulsive_force_float`, each a loop compiled to machine code
(drake_wbc.math.compiled) over the points.
"""

import math
from dataclasses import dataclass

import numpy as np

from drake_wbc.math.compiled import compiled, float_array
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.scalar_support import value_of
from drake_wbc.math.validation import as_vector, non_negative, positive


@dataclass
class RepulsiveFieldParameters:
    """U_rep after eq. (cdmp-base), around the base's footprint.

    Attributes:
        k_obs: scaling factor k_obs >= 0 (paper 0.01).
        d_th: distance threshold d_th > 0, m (paper 0.5).
        half_sizes: footprint half-sizes (a, b) >= 0 along x and y of T_b,
            m, any sequence of two numbers (a list in YAML), stored as a
            tuple; None (the default): the robot's own footprint, from
            its description, filled in when the controller is built
            (drake_wbc.controller.parameters.for_robot), where a given
            one may be larger than the robot's, not smaller.
        d_min: 0 < d_min < d_th, m: distances are clamped to it, so the
            force stays finite for a point on or inside the footprint
            (default 0.05).
        max_force: the bound > 0 on |f_avoid|, the norm of the summed
            force (in the units of tau z_dot, m/s^2 at tau = 1), which
            `repulsive_force` scales down to it, its direction kept.
            The paper's field is unbounded: with its k_obs = 0.01 one point
            at d_min pushes with 72, and a person's leg seen by a dozen
            LIDAR beams with many times that, which would drive V_b' to
            tens of m/s. The default 80 is about alpha_z beta_z d_th with
            the default DMP (156 s^-2 x 0.5 m): enough to hold the base
            d_th off its path against its attractor in steady state.
    """

    k_obs: float = 0.01
    d_th: float = 0.5
    half_sizes: list[float] | None = None
    d_min: float = 0.05
    max_force: float = 80.0

    def __post_init__(self):
        non_negative("k_obs", self.k_obs)
        positive("d_th", self.d_th)
        if self.half_sizes is not None:
            self.half_sizes = tuple(
                non_negative("half_sizes", a)
                for a in as_vector("half_sizes", self.half_sizes, 2))
        if not 0.0 < positive("d_min", self.d_min) < self.d_th:
            raise ValueError(f"d_min = {self.d_min!r} is not allowed: must "
                             f"lie in (0, d_th = {self.d_th!r})")
        positive("max_force", self.max_force)


def footprint_distance(obstacle_points, params):
    """Distance d from the footprint rectangle [-a, a] x [-b, b] (centred
    at the base's reference point) to each point, and the outward unit
    direction n from the rectangle's nearest point towards the point.

    Piecewise: outside, the Euclidean distance to the rectangle; on or
    inside it, d = 0 and n the outward normal of the nearest side (x on a
    tie); a point with a coordinate that is not finite has d and n NaN
    (it is nowhere). obstacle_points: (M, 2) points [x, y] in T_b, m;
    params: RepulsiveFieldParameters. Returns (d, n), (M,) and (M, 2).
    """
    P = np.reshape(obstacle_points, (-1, 2))
    x, y = P[:, 0], P[:, 1]
    a, b = params.half_sizes
    sx, sy = np.where(x >= 0, 1.0, -1.0), np.where(y >= 0, 1.0, -1.0)
    # A point that is not finite makes 0 * inf and inf / inf (NaN, replaced
    # below): no warning for it.
    with np.errstate(invalid="ignore"):
        qx, qy = np.abs(x) - a, np.abs(y) - b
        zero = 0.0 * qx
        # max(q, 0) as numpy's maximum (and the kernel) take it: NaN stays NaN.
        ox, oy = np.where(qx < 0, zero, qx), np.where(qy < 0, zero, qy)
        outside = (qx > 0) | (qy > 0)
        # r = |(ox, oy)|, scaled by the larger part first so that it cannot
        # underflow to 0 outside (which would make n = 0 / 0).
        m = np.where(outside, np.where(ox >= oy, ox, oy), zero + 1.0)
        r = m * np.sqrt(np.where(outside, (ox / m)**2 + (oy / m)**2,
                                 zero + 1.0))
        nearer_x = qx >= qy
        n = np.stack([
            np.where(outside, sx * ox / r, np.where(nearer_x, sx, 0.0) + zero),
            np.where(outside, sy * oy / r, np.where(nearer_x, 0.0, sy) + zero),
        ], axis=1)
    finite = np.isfinite(value_of(x)) & np.isfinite(value_of(y))
    nowhere = zero + math.nan
    return (np.where(finite, np.where(outside, r, zero), nowhere),
            np.where(finite[:, None], n, nowhere[:, None]))


def _field(rng):
    """Random RepulsiveFieldParameters: thin, point and usual footprints,
    small and large gains, bounds that act and bounds that do not."""
    half_sizes = [(0.4, 0.3), (0.0, 0.0), (1.0, 0.05),
                  tuple(rng.uniform(0.0, 1.0, 2))][rng.integers(4)]
    d_th = rng.uniform(0.05, 2.0)
    return RepulsiveFieldParameters(
        k_obs=float(rng.choice([0.0, 0.01, rng.uniform(0.0, 10.0)])),
        d_th=d_th, half_sizes=half_sizes,
        d_min=d_th * rng.uniform(1e-3, 0.99),
        max_force=float(rng.choice([80.0, 1e12, rng.uniform(0.1, 100.0)])))


def _points(rng, params):
    """(M, 2) points around the footprint of `params` (M from 0 to a
    few hundred): anywhere, inside it, on its edges and corners, just
    outside it, at the reach d_th along x or y and beyond it; in one
    case in ten a point with a coordinate (or both) NaN or infinite."""
    a, b = params.half_sizes
    count = int(rng.choice([0, 1, 2, rng.integers(3, 400)]))
    kind = rng.integers(0, 6, count)
    u = rng.uniform(-1.0, 1.0, (count, 2))
    sign = np.where(u >= 0.0, 1.0, -1.0)
    reach = params.d_th
    points = np.select(
        [kind[:, None] == k for k in range(5)],
        [u * (np.array([a, b]) + 2.0 * reach),
         u * [a, b],
         np.column_stack([a * sign[:, 0], b * u[:, 1]]),
         sign * [a, b] + sign * 1e-7 * np.abs(u),
         np.column_stack([(a + reach) * sign[:, 0], b * u[:, 1]])],
        default=u * 50.0)
    if count and rng.random() < 0.1:
        columns = [[0], [1], [0, 1]][rng.integers(3)]
        points[rng.integers(count), columns] = rng.choice(
            [np.nan, np.inf, -np.inf])
    return points


def _distance_inputs(rng):
    params = _field(rng)
    return _points(rng, params), params


@fast_kernel(footprint_distance, sample=_distance_inputs)
def footprint_distance_float(obstacle_points, params):
    """`footprint_distance` of float points, in one compiled loop
    (`footprint_geometry`)."""
    d, nx, ny = footprint_geometry(
        np.reshape(float_array(obstacle_points), (-1, 2)),
        params.half_sizes)
    return d, np.column_stack([nx, ny])


@compiled
def _point_geometry(x, y, a, b):
    """(d, n_x, n_y) of one float point [x, y] and the footprint's
    half-sizes a, b: `footprint_distance`'s piecewise rule, with
    math.hypot for the distance outside (> 0 exactly there: no underflow
    to 0) and, on or inside, the outward normal of the nearest side (x on
    a tie); NaN for all three at a point that is not finite."""
    if not (math.isfinite(x) and math.isfinite(y)):
        return math.nan, math.nan, math.nan
    qx = abs(x) - a
    qy = abs(y) - b
    ox = qx if not qx < 0.0 else 0.0  # numpy's maximum: NaN stays NaN
    oy = qy if not qy < 0.0 else 0.0
    d = math.hypot(ox, oy)
    if d > 0.0:
        return d, math.copysign(ox / d, x), math.copysign(oy / d, y)
    if qx >= qy:
        return d, 1.0 if x >= 0.0 else -1.0, 0.0
    return d, 0.0, 1.0 if y >= 0.0 else -1.0


@compiled
def _geometry_loop(points, a, b):
    count = points.shape[0]
    d, nx, ny = np.empty(count), np.empty(count), np.empty(count)
    for i in range(count):
        d[i], nx[i], ny[i] = _point_geometry(points[i, 0], points[i, 1], a,
                                             b)
    return d, nx, ny


def footprint_geometry(points, half_sizes):
    """The arithmetic of `footprint_distance_float`: (M, 2) float points
    and the footprint's half-sizes (a, b) given directly, the direction
    in its components; one compiled loop (drake_wbc.math.compiled).

    Returns:
        (d, nx, ny), three (M,) arrays: the distance and the two
        components of the outward unit direction n.
    """
    return _geometry_loop(float_array(points), float(half_sizes[0]),
                          float(half_sizes[1]))


@compiled
def _gap_loop(points, a, b):
    gap = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        qx = abs(points[i, 0]) - a
        qy = abs(points[i, 1]) - b
        gap[i] = math.hypot(qx if not qx < 0.0 else 0.0,
                            qy if not qy < 0.0 else 0.0)
    return gap


def footprint_gap(points, half_sizes):
    """The distance d (M,) alone of `footprint_geometry`, for (M, 2)
    float points and the footprint's half-sizes (a, b): the cheapest
    ranking of LIDAR points by how near they are (one compiled loop)."""
    return _gap_loop(float_array(points), float(half_sizes[0]),
                     float(half_sizes[1]))


def _clamped_distance(obstacle_points, params):
    d, n = footprint_distance(obstacle_points, params)
    return np.where(d > params.d_min, d, 0.0 * d + params.d_min), n


def repulsive_potential(obstacle_points, params):
    """U_rep = sum 0.5 k_obs (1/d - 1/d_th)^2 over the points with
    d <= d_th (d clamped to d_min), 0 for the others."""
    d, _ = _clamped_distance(obstacle_points, params)
    U = 0.5 * params.k_obs * (1.0 / d - 1.0 / params.d_th) ** 2
    return np.sum(np.where(d <= params.d_th, U, 0.0 * U))


def repulsive_force(obstacle_points, params):
    """f_avoid of eq. (cdmp-base): the force pushing the base away from
    the obstacle points.

    The paper's f_avoid = grad U_rep is the gradient w.r.t. the obstacle's
    position relative to the base, p; it equals -grad U_rep w.r.t. the
    base's position, so it points from the obstacle to the base:

        f_avoid = sum -|dU/dd| n,   |dU/dd| = k_obs (1/d - 1/d_th) / d^2

    for d <= d_th (0 beyond; continuous at d_th), n from
    `footprint_distance`. Below d_min the magnitude is the one at d_min
    (along n), a bounded push out of the footprint. A sum longer than
    params.max_force is scaled down to it, its direction kept. A
    non-finite point makes the force NaN.

    obstacle_points: (M, 2) points [x, y] in T_b, m (M may be 0);
    params: RepulsiveFieldParameters. Returns the (2,) force [f_x, f_y] in
    T_b (entering tau z_dot).
    """
    d, n = _clamped_distance(obstacle_points, params)
    slope = params.k_obs * (1.0 / d - 1.0 / params.d_th) / d**2
    slope = np.where(d <= params.d_th, slope, 0.0 * slope)
    return _bounded(np.sum(-slope[:, None] * n, axis=0) + np.zeros(2),
                    params)


def _bounded(force, params):
    """`force` (2,) scaled down to params.max_force if longer (a bound so
    large that its square overflows to inf bounds nothing)."""
    squared = force[0] * force[0] + force[1] * force[1]
    if squared > params.max_force * params.max_force:
        force = force * (params.max_force / np.sqrt(squared))
    return force


def _force_inputs(rng):
    """Points around the footprint (crowds whose force is bounded
    included), for repulsive_force_float."""
    params = _field(rng)
    points = _points(rng, params)
    if len(points) and rng.random() < 0.2:  # a crowd on a corner
        a, b = params.half_sizes
        points[:] = np.array([a, -b]) + rng.uniform(-0.1, 0.1,
                                                    points.shape)
    return points, params


@fast_kernel(repulsive_force, sample=_force_inputs)
def repulsive_force_float(obstacle_points, params):
    """`repulsive_force` of float points, in one compiled loop (the
    controller's tick; hundreds of LIDAR points): the points farther than
    d_th from the footprint along x or y, which give exact zeros, are
    skipped before their geometry; a non-finite point makes the force
    NaN."""
    a, b = params.half_sizes
    return _force_loop(np.reshape(float_array(obstacle_points), (-1, 2)),
                       float(a), float(b), float(params.k_obs),
                       float(params.d_th), float(params.d_min),
                       float(params.max_force))


@compiled
def _force_loop(points, a, b, k_obs, reach, d_min, max_force):
    fx = 0.0
    fy = 0.0
    for i in range(points.shape[0]):
        x, y = points[i, 0], points[i, 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            return np.full(2, np.nan)
        if abs(x) - a <= reach and abs(y) - b <= reach:
            d, nx, ny = _point_geometry(x, y, a, b)
            if d < d_min:
                d = d_min
            if d <= reach:
                slope = k_obs * (1.0 / d - 1.0 / reach) / (d * d)
                fx += slope * nx
                fy += slope * ny
    force = np.array([-fx, -fy])
    squared = force[0] * force[0] + force[1] * force[1]
    if squared > max_force * max_force:
        force *= max_force / math.sqrt(squared)
    return force


class LastPoints:
    """A float function of obstacle points that remembers its result for
    the last points it was given.

    The LIDARs scan at 15 Hz and the controller ticks at 100 Hz, so most
    ticks see the very points of the tick before; Drake's caches cannot
    tell (every input is invalidated each step), so the stages that work
    on the points ask this instead. The points are compared by value
    (a copy is kept), so an array changed in place is seen as new.

    Args:
        function: maps (M, 2) float points to a float array.
    """

    def __init__(self, function):
        self._function = function
        self._points = None
        self._result = None
        self.changed = True
        """Whether the last call's points differed from the call's
        before (or it was the first)."""

    def __call__(self, points):
        """function(points), a fresh copy."""
        self.changed = not self._same(points)
        if self.changed:
            self._result = np.asarray(self._function(points))
            self._points = np.array(points, dtype=float)
        return self._result.copy()

    def _same(self, points):
        """Whether `points` equal the last ones by value (np.array_equal,
        without its conversions for an array of the same shape)."""
        last = self._points
        if last is None:
            return False
        if type(points) is np.ndarray and points.shape == last.shape:
            return bool((last == points).all())
        return np.array_equal(last, points)
