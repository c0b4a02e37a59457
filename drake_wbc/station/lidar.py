"""The station's simulated 2-D LIDARs (SICK TiM571).

A LIDAR sees a planar cut through the world at its height, with shapes in
the world frame: circles (people, columns), (K, 3) rows [cx, cy, r], and
boxes (tables, walls), (L, 5) rows [cx, cy, half_x, half_y, yaw], i.e.
rectangles with half sizes along their own axes, yawed by `yaw`. Each beam
reports the distance to the nearest shape along it; `inf` is no return.
Pure numpy math first, then the Drake systems, thin over it.

Sampling at t = 0 (drake 1.51.1): `Simulator.Initialize()` runs no
periodic update; the one due at t = 0 runs at the start of the first
`AdvanceTo` (even `AdvanceTo(0)`), and one due when an `AdvanceTo` ends,
at the start of the next. What reads the outputs at initialisation (a
logger's first sample) would see the default state, so the sensors also
store a reading in an initialization event.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    checked_instance,
    in_closed_range,
    non_negative,
    positive,
    whole_number,
)
from drake_wbc.station.sampling import SampledReading

MAX_BEAMS = 10_000
"""The most beams a scan may have (the TiM571 has 811)."""


@dataclass
class LidarParameters:
    """Parameters of one 2-D LIDAR; the defaults are the SICK TiM571's
    field, beams, ranges and rate, without range noise (the TiM571's
    statistical error, about 20 mm, is not in the robot's facts: give
    range_noise_std to simulate it).

    Attributes:
        field_of_view: rad, from the first beam to the last, in (0, 2 pi];
            270 degrees.
        num_beams: beams a scan, 1 to MAX_BEAMS, evenly spread (811:
            0.333 degree; over a whole turn, 2 pi / num_beams apart).
        min_range: m, >= 0; closer objects give no return (0.05).
        max_range: m, > min_range; farther objects give no return (25).
        rate: scans a second, Hz, > 0 (15).
        range_noise_std: m, >= 0, of a Gaussian error on each range (0).
        seed: a whole number >= 0; the noise of scan k is drawn from
            np.random.default_rng([seed, k]), whatever came before.
    """

    field_of_view: float = float(np.radians(270.0))
    num_beams: int = 811
    min_range: float = 0.05
    max_range: float = 25.0
    rate: float = 15.0
    range_noise_std: float = 0.0
    seed: int = 0

    def __post_init__(self):
        self.field_of_view = in_closed_range(
            "field_of_view", self.field_of_view, 0.0, 2.0 * np.pi)
        positive("field_of_view", self.field_of_view)
        self.num_beams = whole_number("num_beams", self.num_beams, 1)
        if self.num_beams > MAX_BEAMS:
            raise ValueError(
                f"num_beams = {self.num_beams!r} is not allowed: must be at "
                f"most {MAX_BEAMS} (0.036 degree over a full turn, finer "
                "than any planar scanner; each beam is cast every scan)")
        self.min_range = non_negative("min_range", self.min_range)
        self.max_range = positive("max_range", self.max_range)
        if self.max_range <= self.min_range:
            raise ValueError(
                f"max_range = {self.max_range!r} is not allowed: must be "
                f"greater than min_range = {self.min_range!r}")
        self.rate = positive("rate", self.rate)
        self.range_noise_std = non_negative("range_noise_std",
                                            self.range_noise_std)
        self.seed = whole_number("seed", self.seed)

    @property
    def full_turn(self):
        """Whether the field of view is a whole turn (2 pi): its first
        and last beams are then neighbours, not one direction twice."""
        return self.field_of_view >= 2.0 * np.pi

    @property
    def beam_angles(self):
        """(num_beams,) beam directions in the scanner frame, rad, evenly
        from -field_of_view / 2 to +field_of_view / 2 about its x axis (a
        single beam points along x); over a whole turn, from -pi on at
        beam_spacing, so that no direction is scanned twice."""
        if self.full_turn and self.num_beams > 1:
            return -np.pi + self.beam_spacing * np.arange(self.num_beams)
        half = 0.5 * self.field_of_view if self.num_beams > 1 else 0.0
        return np.linspace(-half, half, self.num_beams)

    @property
    def beam_spacing(self):
        """Angle between neighbouring beams, rad (0 for a single beam):
        field_of_view / (num_beams - 1), or 2 pi / num_beams over a whole
        turn."""
        if self.full_turn:
            return self.field_of_view / self.num_beams
        return self.field_of_view / max(self.num_beams - 1, 1)


def shapes_array(name, value, columns):
    """`value` checked as circles (columns = 3) or boxes (columns = 5),
    see the module notes; None or empty gives no shapes."""
    if value is None or np.size(value) == 0:
        return np.zeros((0, columns))
    shapes = as_matrix(name, value, (None, columns))
    sizes = [2] if columns == 3 else [2, 3]
    bad = np.argwhere(shapes[:, sizes] <= 0.0)
    if bad.size:
        row, column = int(bad[0, 0]), sizes[int(bad[0, 1])]
        raise ValueError(
            f"{name}[{row}, {column}] = {float(shapes[row, column])!r} is "
            "not allowed: radii and half sizes must be greater than 0")
    return shapes


def _rotation(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _circle_distances(origin, cos, sin, circles):
    """(K, N) distance along each ray to each circle (inf: missed): the
    first root of |m + t d|^2 = r^2, m = origin - centre, with the
    discriminant from the ray's perpendicular offset d x m (no
    cancellation). The rays' directions d are [cos, sin], (N,) each.

    A shape a row, the rays along it: every operation runs along the N
    rays (numpy is slow along a short last axis)."""
    m = origin - circles[:, :2]                                 # (K, 2)
    # d . m, (K, N): by the matrix product (N, 2) (2, K) the ranges were
    # always computed with, so that they keep every bit.
    b = np.ascontiguousarray((np.stack([cos, sin], axis=1) @ m.T).T)
    offset = cos * m[:, 1:] - sin * m[:, :1]
    r = circles[:, 2:]                                          # (K, 1)
    disc = r * r - offset * offset
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    distances = np.where((disc >= 0.0) & (t >= 0.0), t, np.inf)
    inside = np.sum(m * m, axis=1, keepdims=True) <= r * r
    distances[inside[:, 0]] = 0.0
    return distances


def _box_distances(origin, cos, sin, boxes):
    """(L, N) distance along each ray to each box (inf: missed), by the
    slab method in each box's own frame, one axis at a time; a shape a
    row, as `_circle_distances`."""
    yaw = boxes[:, 4:]
    c, s = np.cos(yaw), np.sin(yaw)                             # (L, 1)
    p = origin - boxes[:, :2]
    px, py = p[:, :1], p[:, 1:]
    local = (c * px + s * py, -s * px + c * py)
    # The rays in each box's frame, (L, N) each.
    along = (cos * c + sin * s, -cos * s + sin * c)
    enter, leave = None, None
    for d, x, half in ((along[0], local[0], boxes[:, 2:3]),
                       (along[1], local[1], boxes[:, 3:4])):
        with np.errstate(divide="ignore", invalid="ignore"):
            t_low, t_high = (-half - x) / d, (half - x) / d
        low, high = np.minimum(t_low, t_high), np.maximum(t_low, t_high)
        parallel = d == 0.0
        if parallel.any():  # within the slab: no bound; outside: missed
            within = np.broadcast_to(np.abs(x) <= half, d.shape)
            low[parallel] = np.where(within[parallel], -np.inf, np.inf)
            high[parallel] = np.where(within[parallel], np.inf, -np.inf)
        enter = low if enter is None else np.maximum(enter, low)
        leave = high if leave is None else np.minimum(leave, high)
    distances = np.where((enter <= leave) & (leave >= 0.0), enter, np.inf)
    inside = (np.abs(local[0]) <= boxes[:, 2:3]) & (
        np.abs(local[1]) <= boxes[:, 3:4])
    distances[inside[:, 0]] = 0.0
    return distances


def cast_rays(origin, angles, circles, boxes, max_range):
    """Distances along rays in the plane to the nearest circle or box.

    Args:
        origin: (2,) the rays' common start, world frame, m.
        angles: (N,) ray directions in the world plane, rad.
        circles: (K, 3) [cx, cy, r] rows, or None.
        boxes: (L, 5) [cx, cy, half_x, half_y, yaw] rows, or None.
        max_range: m, > 0; farther hits are not reported.

    Returns:
        (N,) the distance to the nearest hit along each ray (a grazing ray
        hits), `inf` where nothing is hit within max_range; 0 on every ray
        when the origin is inside or on a shape (the scanner is blocked).
    """
    return _cast_rays(as_vector("origin", origin, 2),
                      as_vector("angles", np.atleast_1d(angles)),
                      shapes_array("circles", circles, 3),
                      shapes_array("boxes", boxes, 5),
                      positive("max_range", max_range))


def _cast_rays(origin, angles, circles, boxes, max_range):
    """`cast_rays` of checked arguments."""
    cos, sin = np.cos(angles), np.sin(angles)
    ranges = np.full(angles.size, np.inf)
    for shapes, distances_to in ((circles, _circle_distances),
                                 (boxes, _box_distances)):
        if len(shapes):  # none: nothing to cast against
            np.minimum(ranges, distances_to(origin, cos, sin, shapes).min(
                axis=0), out=ranges)
    ranges[ranges > max_range] = np.inf
    return ranges


def scan(base_pose, mount, params, circles, boxes, tick):
    """The ranges of one scan of a LIDAR on the base.

    Args:
        base_pose: (3,) [x, y, yaw] of T_b in the world.
        mount: (3,) [x, y, yaw] of the scanner frame in T_b.
        params: LidarParameters (TiM571 defaults if None).
        circles, boxes: the shapes in the world (see `cast_rays`).
        tick: the scan's index, a whole number >= 0; with `params.seed` it
            fixes the range noise, if any.

    Returns:
        (num_beams,) ranges, m, in the order of `params.beam_angles`; `inf`
        (no return) where the true distance is below min_range (so for a
        blocked scanner) or the reading, noise included, leaves
        [min_range, max_range].
    """
    params = checked_instance("params", params, LidarParameters,
                              LidarParameters)
    return _scan(as_vector("base_pose", base_pose, 3),
                 as_vector("mount", mount, 3), params, params.beam_angles,
                 shapes_array("circles", circles, 3),
                 shapes_array("boxes", boxes, 5), whole_number("tick", tick))


def _scan(base_pose, mount, params, beam_angles, circles, boxes, tick):
    """`scan` of checked arguments, with params.beam_angles given."""
    origin = base_pose[:2] + _rotation(base_pose[2]) @ mount[:2]
    ranges = _cast_rays(origin, base_pose[2] + mount[2] + beam_angles,
                        circles, boxes, params.max_range)
    too_close = ranges < params.min_range
    if params.range_noise_std > 0.0:
        rng = np.random.default_rng([params.seed, tick])
        ranges += params.range_noise_std * rng.standard_normal(ranges.size)
    outside = (ranges < params.min_range) | (ranges > params.max_range)
    ranges[too_close | outside] = np.inf
    return ranges


def scan_points(ranges, angles_in_scanner, mount):
    """The returns of a scan as (M, 2) points [x, y] in T_b, one per
    finite range (`inf`, no return, is skipped).

    Args:
        ranges: (N,) ranges, m, >= 0 or inf.
        angles_in_scanner: (N,) the beams' angles in the scanner frame.
        mount: (3,) [x, y, yaw] of the scanner frame in T_b.
    """
    angles = as_vector("angles_in_scanner", np.atleast_1d(angles_in_scanner))
    ranges = np.atleast_1d(np.asarray(ranges, dtype=float))
    if ranges.shape != angles.shape or not np.all(ranges >= 0.0):
        raise ValueError(
            f"ranges (shape {ranges.shape}) is not allowed: must be "
            f"{angles.size} numbers >= 0 or inf, one per angle")
    return _scan_points(ranges, angles, as_vector("mount", mount, 3))


def _scan_points(ranges, angles_in_scanner, mount):
    """`scan_points` of checked arguments."""
    hit = np.isfinite(ranges)
    r, a = ranges[hit], angles_in_scanner[hit]
    in_scanner = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    return mount[:2] + in_scanner @ _rotation(mount[2]).T


def _no_points():
    return AbstractValue.Make(np.zeros((0, 2)))


class PlanarLidar(SampledReading, LeafSystem):
    """A simulated 2-D LIDAR on the base, scanning a planar scene.

    ::

                              ┌─────────────┐
            base_pose ───────►│             ├──► ranges
            moving_positions ►│ PlanarLidar ├──► points
                              └─────────────┘

    - base_pose: (3) [x, y, yaw] of T_b in the world.
    - moving_positions: (2 n) [x0, y0, x1, y1, ...], the world centres of
      the n moving circular obstacles (walking people). Declared only
      when `moving_radii` is not empty, and then it must be connected.
    - ranges: (num_beams) the last scan, m, `inf` = no return.
    - points: abstract, an (M, 2) float array, the last scan's returns as
      points in T_b (what the controller's `lidar.obstacle_points` takes),
      read-only, the same array until the next scan changes the ranges.

    A plain double `LeafSystem` (a sensor with an abstract output is no
    part of what the controller linearises). A periodic discrete update
    at 1 / rate, offset 0, stores the ranges and a scan counter (the
    noise's tick); the outputs come from that state alone, so they hold
    between scans, with no direct feedthrough. The default state is no
    return on every beam, counter 0. An initialization event (see the
    module notes) and `initialize_scan` store the scan of the current
    inputs without advancing the counter: the update at t = 0 then
    stores that very scan again.

    Args:
        params: LidarParameters (TiM571 defaults if None).
        mount: (3,) [x, y, yaw] of the scanner frame in T_b.
        circles, boxes: the static shapes in the world, or None.
        moving_radii: radii (m, > 0) of the moving circular obstacles.
    """

    def __init__(self, params=None, mount=(0.0, 0.0, 0.0), circles=None,
                 boxes=None, moving_radii=()):
        super().__init__()
        self.params = checked_instance("params", params, LidarParameters,
                                       LidarParameters)
        self.mount = as_vector("mount", mount, 3)
        self.circles = shapes_array("circles", circles, 3)
        self.boxes = shapes_array("boxes", boxes, 5)
        self.moving_radii = as_vector("moving_radii", np.ravel(moving_radii))
        for i, radius in enumerate(self.moving_radii):
            positive(f"moving_radii[{i}]", radius)
        self._beam_angles = self.params.beam_angles
        n, count = self.params.num_beams, self.moving_radii.size
        self._base_pose = self.DeclareVectorInputPort("base_pose", 3)
        self._moving = (self.DeclareVectorInputPort("moving_positions",
                                                    2 * count)
                        if count else None)
        state = self._declare_sampling(np.full(n, np.inf), self.params.rate)
        self.DeclareVectorOutputPort("ranges", n, self._output_ranges,
                                     prerequisites_of_calc=state)
        self.DeclareAbstractOutputPort("points", _no_points,
                                       self._output_points,
                                       prerequisites_of_calc=state)

    def _read(self, context, tick):
        circles = self.circles
        if self._moving is not None:
            centres = self._moving.Eval(context).reshape(-1, 2)
            circles = np.vstack([circles, np.column_stack(
                [centres, self.moving_radii])])
        # Checked at construction: the inputs have their ports' sizes.
        return _scan(self._base_pose.Eval(context), self.mount, self.params,
                     self._beam_angles, circles, self.boxes, int(tick))

    def initialize_scan(self, context):
        """Stores in `context` the scan of its current inputs, at the
        current scan counter (left as it is)."""
        self.initialize_reading(context)

    def _output_ranges(self, context, output):
        output.set_value(self._stored_reading_view(context))

    def _output_points(self, context, output):
        # Computed again only when the reading changes (its prerequisite):
        # once a scan, read-only for the stages that share it.
        points = _scan_points(self._stored_reading_view(context),
                              self._beam_angles, self.mount)
        points.flags.writeable = False
        output.set_value(points)


class ObstaclePointMerger(LeafSystem):
    """Concatenates the points of several LIDARs into one array.

    ::

                        ┌─────────────────────┐
            points_0 ──►│                     │
            ...         │ ObstaclePointMerger ├──► points
            points_n-1 ►│                     │
                        └─────────────────────┘

    - points_i: abstract, an (M_i, 2) float array of points in T_b; each
      must be connected (a forgotten scanner is an error, not a blind
      side).
    - points: abstract, their (sum M_i, 2) concatenation, in input order,
      read-only; computed again only when an input changes (the
      PlanarLidars' points change at their scan rate, not at each step).

    Args:
        num_inputs: n, a whole number >= 1.
    """

    def __init__(self, num_inputs=2):
        super().__init__()
        self.num_inputs = whole_number("num_inputs", num_inputs, 1)
        self._inputs = [self.DeclareAbstractInputPort(f"points_{i}",
                                                      _no_points())
                        for i in range(self.num_inputs)]
        self.DeclareAbstractOutputPort(
            "points", _no_points, self._merge,
            prerequisites_of_calc={self.all_input_ports_ticket()})

    def _merge(self, context, output):
        merged = np.concatenate(
            [_checked_points(port.get_name(), port.Eval(context))
             for port in self._inputs], axis=0)
        merged.flags.writeable = False
        output.set_value(merged)


def _checked_points(name, points):
    """`points` as an (M, 2) float array, checked unless it is one."""
    if (type(points) is np.ndarray and points.dtype == np.float64
            and points.ndim == 2 and points.shape[1] == 2):
        return points
    return as_matrix(name, points, (None, 2))
