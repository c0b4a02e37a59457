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
`repulsive_force_float`.
"""

from dataclasses import dataclass

import numpy as np

from drake_wbc.math.kernels import fast_kernel
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
    tie). obstacle_points: (M, 2) points [x, y] in T_b, m; params:
    RepulsiveFieldParameters. Returns (d, n), (M,) and (M, 2).
    """
    P = np.reshape(obstacle_points, (-1, 2))
    x, y = P[:, 0], P[:, 1]
    a, b = params.half_sizes
    sx, sy = np.where(x >= 0, 1.0, -1.0), np.where(y >= 0, 1.0, -1.0)
    qx, qy = np.abs(x) - a, np.abs(y) - b
    zero = 0.0 * qx
    ox, oy = np.where(qx > 0, qx, zero), np.where(qy > 0, qy, zero)
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
    return np.where(outside, r, zero), n


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
    outside it, at the reach d_th along x or y and beyond it."""
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
    return points


def _distance_inputs(rng):
    params = _field(rng)
    return _points(rng, params), params


@fast_kernel(footprint_distance, sample=_distance_inputs)
def footprint_distance_float(obstacle_points, params):
    """`footprint_distance` of float points, in few array operations
    (`footprint_geometry`): the controller's tick."""
    d, nx, ny = footprint_geometry(np.reshape(obstacle_points, (-1, 2)),
                                   params.half_sizes)
    return d, np.column_stack([nx, ny])


def footprint_geometry(points, half_sizes):
    """The arithmetic of `footprint_distance_float`: (M, 2) float points
    and the footprint's half-sizes (a, b) given directly, the direction
    in its components.

    Returns:
        (d, nx, ny), three (M,) arrays: the distance and the two
        components of the outward unit direction n.
    """
    x, y = points[:, 0], points[:, 1]
    qx, qy = np.abs(x) - half_sizes[0], np.abs(y) - half_sizes[1]
    ox, oy = np.maximum(qx, 0.0), np.maximum(qy, 0.0)
    d = np.hypot(ox, oy)  # > 0 exactly outside: no underflow to 0
    outside = d > 0.0
    if outside.all():
        return d, np.copysign(ox / d, x), np.copysign(oy / d, y)
    safe = np.where(outside, d, 1.0)
    sx, sy = np.where(x >= 0, 1.0, -1.0), np.where(y >= 0, 1.0, -1.0)
    nearer_x = qx >= qy
    nx = np.where(outside, sx * ox / safe, np.where(nearer_x, sx, 0.0))
    ny = np.where(outside, sy * oy / safe, np.where(nearer_x, 0.0, sy))
    return d, nx, ny


def footprint_gap(points, half_sizes):
    """The distance d (M,) alone of `footprint_geometry`, for (M, 2)
    float points and the footprint's half-sizes (a, b): the cheapest
    ranking of LIDAR points by how near they are."""
    qx = np.abs(points[:, 0]) - half_sizes[0]
    qy = np.abs(points[:, 1]) - half_sizes[1]
    return np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))


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
    """`force` (2,) scaled down to params.max_force if longer."""
    squared = force[0] * force[0] + force[1] * force[1]
    if squared > params.max_force**2:
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
    """`repulsive_force` of float points, in fewer array operations (the
    controller's tick; hundreds of LIDAR points): the points farther than
    d_th from the footprint along x or y, which give exact zeros, are
    dropped first; non-finite points make the force NaN."""
    points = np.reshape(obstacle_points, (-1, 2))
    if not np.isfinite(points).all():
        return np.full(2, np.nan)
    a, b = params.half_sizes
    reach = params.d_th
    near = ((np.abs(points[:, 0]) - a <= reach)
            & (np.abs(points[:, 1]) - b <= reach))
    if not near.any():
        return np.zeros(2)
    d, nx, ny = footprint_geometry(points[near], params.half_sizes)
    d = np.maximum(d, params.d_min)
    slope = params.k_obs * (1.0 / d - 1.0 / reach) / (d * d)
    slope[d > reach] = 0.0
    return _bounded(np.array([-slope @ nx, -slope @ ny]), params)


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
