"""Speed and separation (drake_wbc.math.separation): the footprint's approach
speed to each obstacle point against finite differences of its distance,
the scale that bounds it, and the closed loop that a bounded field alone
lost (a worker dragging the robot into a crate)."""

import numpy as np
import pytest

from drake_wbc.math import repulsion
from drake_wbc.math.repulsion import (
    RepulsiveFieldParameters,
    footprint_distance,
)
from drake_wbc.math.separation import (
    FAR,
    ProtectiveTiming,
    allowed_speeds,
    approach_speeds,
    nearest_points,
    separation_scale,
)

HALF = (0.4, 0.3)
TIMING = ProtectiveTiming(reaction_time=0.097, lag=0.3, deceleration=1.0)
"""The shipped robot's: a scan, the processing and a tick; its lag and
1 m/s^2."""


def braking_speed(gap, timing=TIMING):
    """The root u >= 0 of u^2 / (2 a) + (T_r + tau) u = gap, by bisection
    (independent of the closed form in the module)."""
    reaction, lag, a = timing
    low, high = 0.0, 100.0
    for _ in range(200):
        u = 0.5 * (low + high)
        if u * u / (2.0 * a) + (reaction + lag) * u > gap:
            high = u
        else:
            low = u
    return 0.5 * (low + high)


def distance_after(points, command, dt):
    """The points' footprint distances after the base moves by command dt
    (the points, fixed in the world, move the other way in T_b)."""
    vx, vy, wz = command
    c, s = np.cos(-wz * dt), np.sin(-wz * dt)
    moved = (points - np.array([vx, vy]) * dt) @ np.array([[c, s], [-s, c]])
    return footprint_distance(moved, RepulsiveFieldParameters(
        half_sizes=HALF))[0]


def test_the_approach_speed_is_the_rate_at_which_the_distance_falls():
    rng = np.random.default_rng(5)
    points = rng.uniform(-1.2, 1.2, (200, 2))
    d0 = footprint_distance(points, RepulsiveFieldParameters(
        half_sizes=HALF))[0]
    points = points[d0 > 0.02]  # outside, off the footprint's edge
    for _ in range(10):
        command = rng.uniform(-0.8, 0.8, 3)
        approach, d = approach_speeds(command, points, HALF)
        dt = 1e-6
        rate = (distance_after(points, command, -dt)
                - distance_after(points, command, dt)) / (2 * dt)
        np.testing.assert_allclose(approach, rate, atol=1e-6)


def test_the_scale_meets_every_bound_and_keeps_the_direction():
    rng = np.random.default_rng(6)
    for _ in range(50):
        points = rng.uniform(-1.0, 1.0, (30, 2))
        command = rng.uniform(-1.0, 1.0, 3)
        s = separation_scale(command, points, HALF, 0.1, 0.5, TIMING)
        assert 0.0 <= s <= 1.0
        approach, d = approach_speeds(s * command, points, HALF)
        allowed = allowed_speeds(d, 0.1, 0.5, TIMING)
        assert np.all(approach <= allowed + 1e-12)
        if s < 1.0:  # the largest such factor: one bound is tight
            assert np.any(np.isclose(approach, allowed, atol=1e-12)
                          & (approach > 0.0)) or s == 0.0


def test_moving_away_or_along_is_not_limited():
    wall = np.array([[0.9, y] for y in np.linspace(-1.0, 1.0, 21)])
    for command in ([-0.8, 0.0, 0.0], [0.0, 0.8, 0.0]):
        assert separation_scale(command, wall, HALF, 0.1, 0.5, TIMING) == 1.0
    # Straight at it, 0.5 m away: the approach alone would allow
    # (0.5 - 0.1) / 0.5 = 0.8 m/s, but the base brakes from no faster
    # than the root of u^2 / 2 + 0.397 u = 0.4: 0.582 m/s.
    assert separation_scale([1.0, 0.0, 0.0], wall, HALF, 0.1, 0.5,
                            TIMING) == pytest.approx(braking_speed(0.4))
    assert braking_speed(0.4) == pytest.approx(0.582, abs=1e-3)
    # At the stop distance, nothing towards it.
    near = wall - [0.4, 0.0]
    assert separation_scale([0.3, 0.1, 0.0], near, HALF, 0.1, 0.5,
                            TIMING) == 0.0


@pytest.mark.parametrize("timing", [TIMING, ProtectiveTiming(0.0, 0.0, 0.5),
                                    ProtectiveTiming(0.2, 0.8, 3.0)])
def test_the_allowed_speed_is_the_approach_or_the_stop_whichever_is_slower(
        timing):
    """Eq. (allowed) against its two parts computed independently: the
    exponential approach g / stop_time and the braking root; slow near
    the obstacle it is the approach, fast the braking, and they cross at
    g = 2 a stop_time (stop_time - B)."""
    gaps = np.linspace(0.0, 3.0, 61)
    allowed = allowed_speeds(gaps + 0.1, 0.1, 0.5, timing)
    expected = [min(g / 0.5, braking_speed(g, timing)) for g in gaps]
    np.testing.assert_allclose(allowed, expected, rtol=1e-12, atol=1e-12)
    reaction, lag, a = timing
    crossing = 2.0 * a * 0.5 * (0.5 - reaction - lag)
    if crossing > 0.0:
        assert braking_speed(crossing, timing) == pytest.approx(
            crossing / 0.5, rel=1e-9)
    # Inside the stop distance, nothing.
    assert np.all(allowed_speeds(np.array([0.0, 0.05, 0.1]), 0.1, 0.5,
                                 timing) == 0.0)


def test_approaching_at_the_bound_never_asks_for_more_than_the_braking():
    """An ideal base approaching a wall at the bound, d' = -u(d): the
    bound's rate of fall (finite differences along the approach) stays
    below the deceleration a, so the acceleration limits can follow it;
    the exponential approach alone asks for up to u / stop_time."""
    d = np.linspace(0.1, 2.0, 4001)
    u = allowed_speeds(d, 0.1, 0.5, TIMING)
    fall = np.gradient(u, d) * u  # du/dt = du/dd * (-d') = u'(d) u
    assert fall.max() <= TIMING.deceleration * (1.0 + 1e-6)
    exponential = np.maximum(d - 0.1, 0.0) / 0.5
    assert (exponential / 0.5).max() > 3.0 * TIMING.deceleration


def test_nearest_points_keeps_the_closest_and_pads_far():
    points = np.array([[2.0, 0.0], [0.5, 0.0], [0.0, 0.9], [3.0, 3.0]])
    kept = nearest_points(points, HALF, count=3)
    np.testing.assert_array_equal(kept, [[0.5, 0.0], [0.0, 0.9],
                                         [2.0, 0.0]])
    padded = nearest_points(np.zeros((0, 2)), HALF, count=2)
    np.testing.assert_array_equal(padded, [[FAR, 0.0], [FAR, 0.0]])
    assert separation_scale([1.0, 1.0, 1.0], padded, HALF, 0.1, 0.5,
                            TIMING) == 1.0


def test_the_footprint_gap_is_the_footprint_distance():
    """footprint_gap (the distance alone, which ranks the points) against
    footprint_distance, on points outside, inside, on the edges and
    corners and on the axes (footprint_geometry, the arithmetic of the
    float kernel of footprint_distance, is held to it by
    tests/test_kernels.py)."""
    rng = np.random.default_rng(8)
    a, b = HALF
    special = np.array([[a, 0.0], [-a, b], [0.0, 0.0], [0.0, -b], [a, -b],
                        [0.1, 0.1], [-0.35, 0.29], [2.0, 0.0], [0.0, -3.0],
                        [a + 1e-300, b]])
    points = np.vstack([rng.uniform(-1.5, 1.5, (500, 2)),
                        rng.uniform(-0.45, 0.45, (200, 2)), special])
    d, _ = footprint_distance(points, RepulsiveFieldParameters(
        half_sizes=HALF))
    np.testing.assert_allclose(repulsion.footprint_gap(points, HALF), d,
                               rtol=1e-14, atol=1e-300)


@pytest.mark.parametrize("count", [1, 5, 16, 40])
def test_nearest_points_is_a_stable_sort_by_distance(count):
    """The partial selection keeps exactly the first `count` of a stable
    argsort, ties (inside points, equal distances) in their order."""
    rng = np.random.default_rng(count)
    points = np.vstack([rng.uniform(-2.0, 2.0, (300, 2)),
                        np.zeros((20, 2)),          # 20 ties at d = 0
                        np.tile([[1.0, 0.0]], (20, 1))])  # 20 more
    rng.shuffle(points)
    d = footprint_distance(points, RepulsiveFieldParameters(
        half_sizes=HALF))[0]
    expected = points[np.argsort(d, kind="stable")[:count]]
    np.testing.assert_array_equal(nearest_points(points, HALF, count),
                                  expected)


def test_a_worker_dragging_the_robot_into_a_crate_is_stopped_short():
    """Stress case 499 of seed 2026: in pHRI mode a hand pulls the tool
    with 8 N for 1.6 s towards a crate 0.32 m from the footprint; the
    repulsive field alone let the base touch it."""
    from drake_wbc.stress.cases import run_case, violations

    record = run_case(2026, 499, 4.0)
    assert violations(record) == []
    assert record["min_static_obstacle_distance_m"] > 0.02


def test_last_points_recomputes_only_for_new_points():
    calls = []

    def gap_sum(points):
        calls.append(1)
        return np.array([repulsion.footprint_gap(points, HALF).sum()])

    last = repulsion.LastPoints(gap_sum)
    points = np.random.default_rng(3).uniform(-2.0, 2.0, (50, 2))
    first = last(points)
    np.testing.assert_array_equal(last(points.copy()), first)
    assert len(calls) == 1  # equal values: remembered
    first[0] = -1.0  # the caller's copy, not the remembered result
    assert last(points)[0] != -1.0 and len(calls) == 1
    points[7, 0] += 1e-12  # changed in place: seen as new
    last(points)
    assert len(calls) == 2
    last(points[:10])  # another shape
    assert len(calls) == 3
    nan = points.copy()
    nan[0, 0] = np.nan  # NaN equals nothing: computed each time
    last(nan), last(nan)
    assert len(calls) == 5


def test_last_points_compares_by_value_as_array_equal():
    """Whatever the caller changes (the array in place, a copy, a list, a
    transposed copy), the function runs again exactly when the points
    differ by value."""
    calls = []

    def function(points):
        calls.append(np.array(points))
        return np.asarray(points, dtype=float).sum(axis=0)

    last = repulsion.LastPoints(function)
    rng = np.random.default_rng(17)
    points = rng.normal(size=(30, 2))
    seen = None
    for trial in range(200):
        choice = rng.integers(0, 6)
        if choice == 0:
            points = rng.normal(size=(int(rng.integers(0, 40)), 2))
        elif choice == 1:
            points[rng.integers(0, len(points) or 1) if len(points) else
                   slice(0)] += 1.0  # changed in place
        elif choice == 2:
            points = points.copy()  # the same values, a new array
        elif choice == 3:
            points = points.tolist()  # a list of the same values
        elif choice == 4:
            points = np.asarray(points)[:, ::-1].copy()
        given = points
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        expected_call = seen is None or not np.array_equal(seen, points)
        before = len(calls)
        np.testing.assert_array_equal(last(given), points.sum(axis=0))
        assert (len(calls) > before) == expected_call, trial
        seen = points.copy()
