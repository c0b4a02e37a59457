"""The base command path's double fast paths against their general
formulations, on seeded random inputs: `separation_state` against the
composition of nearest_points, approach_rows and allowed_speeds;
`scale_for_rows`' loop against the masked-array formula; and the
BaseCommandLimiter's double outputs and update against its AutoDiffXd
path and against a tick-by-tick model built from the public
functions."""

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractValue
from pydrake.common.value import AbstractValue

from drake_wbc.math.command_limits import limit_base_velocity
from drake_wbc.math.repulsion import LastPoints
from drake_wbc.math.safety import SafetyParameters
from drake_wbc.math.separation import (
    NEAREST_POINTS,
    allowed_speeds,
    approach_rows,
    nearest_points,
    scale_for_rows,
    separation_scale,
    separation_state,
)
from drake_wbc.stages.base_command import BaseCommandLimiter
from drake_wbc.stages.safety import StopGate

HALF_SIZES = (0.4, 0.3)
H = 0.01


def composed_state(points, stop_distance, stop_time, count=NEAREST_POINTS):
    rows, d = approach_rows(nearest_points(points, HALF_SIZES, count),
                            HALF_SIZES)
    return np.concatenate([rows.ravel(),
                           allowed_speeds(d, stop_distance, stop_time)])


def random_points(rng, kind):
    """Obstacle points of a few kinds: a scan around the base, some
    inside the footprint, fewer than NEAREST_POINTS, duplicated (ties),
    on the footprint's edge, none."""
    count = int(rng.integers(20, 400))
    radius = rng.uniform(0.3, 5.0, count)
    angle = rng.uniform(-np.pi, np.pi, count)
    points = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    if kind == "inside":
        points[rng.integers(0, count, 3)] = rng.uniform(-0.3, 0.3, (3, 2))
    elif kind == "few":
        points = points[:int(rng.integers(1, NEAREST_POINTS))]
    elif kind == "ties":
        points = np.concatenate([points, points[::2], -points[::3]])
    elif kind == "edge":
        points[:5] = [[0.4, 0.0], [-0.4, 0.1], [0.0, 0.3], [0.2, -0.3],
                      [0.4, 0.3]]
    elif kind == "none":
        points = np.zeros((0, 2))
    return points


@pytest.mark.parametrize("kind",
                         ["scan", "inside", "few", "ties", "edge", "none"])
def test_separation_state_is_the_composition_bit_for_bit(kind):
    rng = np.random.default_rng(7)
    for _ in range(40):
        points = random_points(rng, kind)
        stop_distance = rng.uniform(0.0, 0.3)
        stop_time = rng.uniform(0.1, 1.0)
        count = int(rng.choice([1, 4, NEAREST_POINTS]))
        expected = composed_state(points, stop_distance, stop_time, count)
        got = separation_state(points, HALF_SIZES, stop_distance, stop_time,
                               count)
        assert got.shape == (4 * count,)
        np.testing.assert_array_equal(got, expected)
        assert np.array_equal(got, expected)  # also the signs of zeros
        assert np.array_equal(np.signbit(got), np.signbit(expected))


def masked_scale(command, rows, allowed):
    """`scale_for_rows` as masked arrays (the general formulation)."""
    with np.errstate(divide="ignore"):
        approach = rows @ command
        closing = approach > allowed
        if not closing.any():
            return 1.0
        return min(max(float(np.min(allowed[closing] / approach[closing])),
                       0.0), 1.0)


def test_scale_for_rows_is_the_masked_formula():
    rng = np.random.default_rng(11)
    seen = set()
    for trial in range(600):
        m = int(rng.integers(0, 20))
        rows = rng.normal(size=(m, 3))
        allowed = rng.uniform(0.0, 0.5, m)
        if trial % 5 == 0 and m:
            allowed[rng.integers(0, m)] = -rng.uniform(0.0, 1.0)
            rows[rng.integers(0, m)] = [0.0, 0.0, 0.0]
        command = rng.normal(size=3) * rng.choice([1e-3, 0.3, 3.0])
        expected = masked_scale(command, rows, allowed)
        got = scale_for_rows(command, rows, allowed)
        assert got == expected and type(got) is float
        seen.add("one" if got == 1.0 else "zero" if got == 0.0 else "part")
    assert seen == {"one", "zero", "part"}


def test_the_separation_scale_is_unchanged_on_scans():
    rng = np.random.default_rng(5)
    for _ in range(50):
        points = nearest_points(random_points(rng, "scan"), HALF_SIZES)
        command = rng.normal(size=3)
        rows, d = approach_rows(points, HALF_SIZES)
        assert separation_scale(command, points, HALF_SIZES, 0.1, 0.5) == (
            masked_scale(command, rows, allowed_speeds(d, 0.1, 0.5)))


# --- the BaseCommandLimiter ----------------------------------------------


@pytest.fixture(scope="module")
def limiters():
    params = SafetyParameters()
    double = BaseCommandLimiter(params, H, HALF_SIZES)
    return params, double, double.ToAutoDiffXd()


def random_tick(rng):
    desired = rng.normal(size=3) * rng.choice([0.05, 0.5, 3.0])
    if rng.random() < 0.05:
        desired[rng.integers(0, 3)] = rng.choice([np.nan, np.inf])
    stopped = 1.0 if rng.random() < 0.1 else 0.0
    envelope = 1.0 if rng.random() < 0.8 else rng.uniform(0.2, 1.0)
    kind = rng.choice(["scan", "scan", "inside", "few", "none"])
    return desired, stopped, envelope, random_points(rng, kind)


def model_tick(params, previous, separation, desired, stopped, envelope,
               points):
    """The limiter's outputs and next state from the public functions."""
    rows = separation[:3 * NEAREST_POINTS].reshape(-1, 3)
    allowed = separation[3 * NEAREST_POINTS:]
    if stopped >= 0.5:
        command, limited, scales = np.zeros(3), 0.0, [1.0, 1.0]
    elif not np.isfinite(desired).all():
        command, limited, scales = np.zeros(3), 1.0, [0.0, 0.0]
    else:
        result = limit_base_velocity(
            desired, previous, params.base_velocity_limits,
            params.base_acceleration_limits, H,
            scale=masked_scale(desired, rows, allowed))
        command = result.command
        limited = 1.0 if result.limited else 0.0
        scales = [result.velocity_scale, result.acceleration_scale]
    if envelope < 1.0:
        limited = 1.0
    saturation = np.array([limited, envelope * scales[0], scales[1]])
    following = composed_state(points, params.stop_distance,
                               params.stop_time)
    return command, saturation, command.copy(), following


def test_the_double_limiter_is_its_autodiff_path_and_the_model(limiters):
    params, double, autodiff = limiters
    rng = np.random.default_rng(3)
    contexts = [system.CreateDefaultContext()
                for system in (double, autodiff)]
    previous = np.zeros(3)
    separation = composed_state(np.zeros((0, 2)), params.stop_distance,
                                params.stop_time)
    limited_ticks = passed_ticks = 0
    for _ in range(150):
        desired, stopped, envelope, points = random_tick(rng)
        if rng.random() < 0.3:  # a small step: often within every limit
            desired = previous + rng.normal(size=3) * 1e-3
        outputs = []
        for system, context in zip((double, autodiff), contexts,
                                   strict=True):
            system.GetInputPort("velocity").FixValue(context, desired)
            system.GetInputPort("stopped").FixValue(context, [stopped])
            system.GetInputPort("envelope_scale").FixValue(context,
                                                           [envelope])
            system.GetInputPort("obstacle_points").FixValue(
                context, AbstractValue.Make(points))
            command = system.GetOutputPort("velocity_command").Eval(context)
            saturation = system.GetOutputPort("saturation").Eval(context)
            state = system.EvalUniquePeriodicDiscreteUpdate(
                context).get_vector().CopyToVector()
            outputs.append([ExtractValue(np.asarray(v)).ravel()
                            if v.dtype == object else v
                            for v in (command, saturation, state)])
            context.SetDiscreteState(state)
        (command, saturation, state), general = outputs
        for fast, slow in zip((command, saturation, state), general,
                              strict=True):
            np.testing.assert_array_equal(fast, slow)
        expected = model_tick(params, previous, separation, desired,
                              stopped, envelope, points)
        np.testing.assert_array_equal(command, expected[0])
        np.testing.assert_array_equal(saturation, expected[1])
        np.testing.assert_array_equal(state[:3], expected[2])
        np.testing.assert_array_equal(state[3:], expected[3])
        previous, separation = state[:3], state[3:]
        limited_ticks += saturation[0] == 1.0
        passed_ticks += stopped < 0.5 and np.array_equal(command, desired)
    assert limited_ticks > 10 and passed_ticks > 10


def test_the_double_stop_gate_is_its_autodiff_path():
    limits = (0.5, 0.4, 0.9)
    double = StopGate(3, limits)
    autodiff = double.ToAutoDiffXd()
    rng = np.random.default_rng(13)
    contexts = [system.CreateDefaultContext()
                for system in (double, autodiff)]
    for _ in range(60):
        value = rng.normal(size=3) * rng.choice([0.1, 1.0])
        stop = float(rng.random() < 0.2)
        results = []
        for system, context in zip((double, autodiff), contexts,
                                   strict=True):
            system.GetInputPort("value").FixValue(context, value)
            system.GetInputPort("stop").FixValue(context, [stop])
            results.append([
                np.asarray(ExtractValue(np.asarray(v, dtype=object)),
                           dtype=float).ravel()
                for v in (system.GetOutputPort(name).Eval(context)
                          for name in ("gated", "scale"))])
        (gated, scale), general = results
        np.testing.assert_array_equal(gated, general[0])
        np.testing.assert_array_equal(scale, general[1])
        expected = 1.0 if stop else min(
            [1.0] + [lim / abs(v) for v, lim in zip(value, limits,
                                                     strict=True)
                     if abs(v) > lim])
        assert scale[0] == expected
        np.testing.assert_array_equal(
            gated, np.zeros(3) if stop else
            (value if expected == 1.0 else expected * value))


def test_last_points_compares_by_value_as_array_equal():
    calls = []

    def function(points):
        calls.append(np.array(points))
        return np.asarray(points, dtype=float).sum(axis=0)

    last = LastPoints(function)
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
