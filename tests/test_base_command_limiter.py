"""The BaseCommandLimiter tick by tick: its outputs and update against a
model built from the public functions (drake_wbc.math.separation's
references and command_limits.limit_base_velocity), in double and in
AutoDiffXd, over stops, non-finite commands, envelopes and obstacle
scans of every kind."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue
from pydrake.common.value import AbstractValue
from shipped_names import BASE_LIMITS

from drake_wbc.math.command_limits import limit_base_velocity
from drake_wbc.math.repulsion import footprint_gap
from drake_wbc.math.safety import SafetyParameters
from drake_wbc.math.separation import (
    NEAREST_POINTS,
    protective_timing,
    scale_for_rows,
    separation_state,
)
from drake_wbc.stages import BaseCommandLimiter
from drake_wbc.stages.base_command import limiter_state

HALF_SIZES = (0.4, 0.3)
H = 0.01
TOLERANCE = 1e-12


def random_points(rng):
    """A scan around the base, one with points inside the footprint, fewer
    than NEAREST_POINTS, or none."""
    kind = rng.choice(["scan", "scan", "inside", "few", "none"])
    count = int(rng.integers(20, 400))
    radius = rng.uniform(0.3, 5.0, count)
    angle = rng.uniform(-np.pi, np.pi, count)
    points = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    if kind == "inside":
        points[rng.integers(0, count, 3)] = rng.uniform(-0.3, 0.3, (3, 2))
    elif kind == "few":
        points = points[:int(rng.integers(1, NEAREST_POINTS))]
    elif kind == "none":
        points = np.zeros((0, 2))
    return points


def random_tick(rng, previous):
    desired = rng.normal(size=3) * rng.choice([0.05, 0.5, 3.0])
    if rng.random() < 0.3:  # a small step: often within every limit
        desired = previous + rng.normal(size=3) * 1e-3
    if rng.random() < 0.05:
        desired[rng.integers(0, 3)] = rng.choice([np.nan, np.inf])
    stopped = 1.0 if rng.random() < 0.1 else 0.0
    envelope = 1.0 if rng.random() < 0.8 else rng.uniform(0.2, 1.0)
    return desired, stopped, envelope, random_points(rng)


def timing_of(params):
    """The base's reaction, lag and braking the limiter's rules use."""
    return protective_timing(params.people, H,
                             params.base_acceleration_limits,
                             params.base_lag)


def model_tick(params, previous, separation, desired, stopped, envelope,
               points, people=None):
    """The limiter's outputs and next static state (the command and the
    separation state of eq. (allowed)) from the public functions;
    `people`: the people's rows (MAX_TRACKS, 3), allowed speeds and
    protective stop the limiter holds, or None."""
    rows = separation[:3 * NEAREST_POINTS].reshape(-1, 3)
    allowed = separation[3 * NEAREST_POINTS:]
    if stopped >= 0.5:
        command, limited, scales = np.zeros(3), 0.0, [1.0, 1.0]
    elif not np.isfinite(desired).all():
        command, limited, scales = np.zeros(3), 1.0, [0.0, 0.0]
    else:
        scale = scale_for_rows(desired, rows, allowed)
        if people is not None:
            scale = min(scale, scale_for_rows(desired, people[0], people[1]))
            if people[2] >= 0.5:
                scale = 0.0
        result = limit_base_velocity(
            desired, previous, params.base_velocity_limits,
            params.base_acceleration_limits, H, scale=scale)
        command = result.command
        limited = 1.0 if result.limited else 0.0
        scales = [result.velocity_scale, result.acceleration_scale]
    if envelope < 1.0:
        limited = 1.0
    saturation = np.array([limited, envelope * scales[0], scales[1]])
    following = separation_state(points, HALF_SIZES, params.stop_distance,
                                 params.stop_time, timing_of(params))
    return command, saturation, np.concatenate([command, following])


def values(vector):
    vector = np.asarray(vector)
    return ExtractValue(vector).ravel() if vector.dtype == object else vector


@pytest.mark.parametrize("scalar", ["double", "autodiff"])
def test_the_limiter_is_the_model_tick_by_tick(scalar):
    # A short hold, so that protective stops (a scan in five has points
    # inside the footprint) clear within the run.
    params = SafetyParameters(**BASE_LIMITS, hold_time=0.02)
    system = BaseCommandLimiter(params, H, HALF_SIZES)
    if scalar == "autodiff":
        system = system.ToAutoDiffXd()
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(3)
    previous = np.zeros(3)
    separation = separation_state(np.zeros((0, 2)), HALF_SIZES,
                                  params.stop_distance, params.stop_time,
                                  timing_of(params))
    seen = set()
    people, last_inside = None, -1e9
    for tick in range(150):
        context.SetTime(tick * H)
        desired, stopped, envelope, points = random_tick(rng, previous)
        system.GetInputPort("velocity").FixValue(context, desired)
        system.GetInputPort("stopped").FixValue(context, [stopped])
        system.GetInputPort("envelope_scale").FixValue(context, [envelope])
        system.GetInputPort("obstacle_points").FixValue(
            context, AbstractValue.Make(points))
        command = values(system.GetOutputPort("velocity_command").Eval(
            context))
        saturation = values(system.GetOutputPort("saturation").Eval(context))
        state = system.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector()
        context.SetDiscreteState(state)
        state = values(state)
        parts = limiter_state(state)
        expected = model_tick(params, previous, separation, desired,
                              stopped, envelope, points, people)
        # The protective stop: from a point on or inside the footprint,
        # for hold_time after the last such scan.
        if len(points) and footprint_gap(points, HALF_SIZES).min() <= 0.0:
            last_inside = tick * H
        stop = parts.protective[0]
        assert stop == (
            1.0 if tick * H - last_inside < params.hold_time - 1e-9 else 0.0)
        seen.add(f"protective {stop}")
        for got, wanted in zip(
                (command, saturation,
                 np.concatenate([parts.previous, parts.separation])),
                expected, strict=True):
            np.testing.assert_allclose(got, wanted, rtol=0.0,
                                       atol=TOLERANCE * max(
                                           1.0, np.abs(wanted).max()))
        previous, separation = parts.previous, parts.separation
        people = (parts.person_rows, parts.person_allowed, stop)
        if stopped < 0.5 and np.isfinite(desired).all():
            seen.add("passed" if np.array_equal(command, desired)
                     else "limited")
        seen.add("stopped" if stopped >= 0.5 else "running")
    assert seen == {"passed", "limited", "stopped", "running",
                    "protective 0.0", "protective 1.0"}


def test_the_autodiff_limiter_differentiates_the_separation_scale():
    """Approaching a wall 0.5 m ahead at v_x = 1 m/s, the point straight
    ahead allows (0.5 - 0.1) / 0.5 = 0.8 m/s, so the scale is 0.8 / v_x
    and the command 0.8 / v_x (v_x, v_y, 0): its derivative by v_x is
    (0, -0.8 v_y / v_x^2) = 0 and by v_y (0, 0.8 / v_x), exactly (the
    scale's reference in AutoDiffXd; the acceleration limit is out of
    the way)."""
    params = SafetyParameters(base_velocity_limits=[2.0, 2.0, 2.0],
                              base_acceleration_limits=[1e3, 1e3, 1e3],
                              base_lag=0.3, stop_distance=0.1)
    system = BaseCommandLimiter(params, H, HALF_SIZES).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    wall = np.array([[0.9, y] for y in np.linspace(-1.0, 1.0, 21)])
    system.GetInputPort("obstacle_points").FixValue(
        context, AbstractValue.Make(wall))
    system.GetInputPort("stopped").FixValue(context, [0.0])
    system.GetInputPort("velocity").FixValue(context, [0.0, 0.0, 0.0])
    state = system.EvalUniquePeriodicDiscreteUpdate(
        context).get_vector().CopyToVector()
    context.SetDiscreteState(state)
    vx = 1.0
    desired = np.array([AutoDiffXd(vx, [1.0, 0.0]),
                        AutoDiffXd(0.0, [0.0, 1.0]), AutoDiffXd(0.0)],
                       dtype=object)
    system.GetInputPort("velocity").FixValue(context, desired)
    command = system.GetOutputPort("velocity_command").Eval(context)
    np.testing.assert_allclose(ExtractValue(command).ravel(),
                               [0.8, 0.0, 0.0], atol=1e-12)
    gradient = ExtractGradient(command)
    # d(0.8 v / v_x)/dv: row x [0, 0.8 / v_x], row y [0, 0.8 / v_x].
    np.testing.assert_allclose(gradient[:2], [[0.0, 0.0], [0.0, 0.8]],
                               atol=1e-12)


@pytest.mark.parametrize("limit", ["velocity", "acceleration"])
def test_the_autodiff_limiter_differentiates_the_limits_exactly(limit):
    """A command 3 m/s along x against a 2 m/s limit is scaled by
    s = 2 / v_x; with an acceleration limit of 50 m/s^2 from rest, by
    s = a h / v_x = 0.5 / v_x. Either way the command is s (v_x, v_y, 0):
    its derivative by v_x is 0 along x and by v_y is s along y, exactly
    (limit_base_velocity is scalar-generic)."""
    if limit == "velocity":
        params = SafetyParameters(base_velocity_limits=[2.0, 2.0, 2.0],
                                  base_acceleration_limits=[1e3, 1e3, 1e3],
                                  base_lag=0.3, stop_distance=0.1)
        scale = 2.0 / 3.0
    else:
        params = SafetyParameters(base_velocity_limits=[4.0, 4.0, 4.0],
                                  base_acceleration_limits=[50.0, 50.0, 50.0],
                                  base_lag=0.3, stop_distance=0.1)
        scale = 50.0 * H / 3.0
    system = BaseCommandLimiter(params, H, HALF_SIZES).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    system.GetInputPort("obstacle_points").FixValue(
        context, AbstractValue.Make(np.zeros((0, 2))))
    system.GetInputPort("stopped").FixValue(context, [0.0])
    desired = np.array([AutoDiffXd(3.0, [1.0, 0.0]),
                        AutoDiffXd(0.0, [0.0, 1.0]), AutoDiffXd(0.0)],
                       dtype=object)
    system.GetInputPort("velocity").FixValue(context, desired)
    command = system.GetOutputPort("velocity_command").Eval(context)
    np.testing.assert_allclose(ExtractValue(command).ravel(),
                               [3.0 * scale, 0.0, 0.0], rtol=1e-15)
    np.testing.assert_allclose(ExtractGradient(command),
                               [[0.0, 0.0], [0.0, scale], [0.0, 0.0]],
                               atol=1e-15)


@pytest.mark.parametrize("measured", [[2.0, 0.0, 0.0], [1.5, -3.0, 0.5]])
def test_a_takeover_beyond_the_velocity_limits_sends_none_beyond(measured):
    """The controller takes over a base moving faster than the velocity
    limits (set_previous, from its measured velocity): the command stays
    within them from the first tick, ramping from the measured velocity
    scaled into them (its direction kept)."""
    params = SafetyParameters(**BASE_LIMITS)
    limits = np.array(params.base_velocity_limits)
    system = BaseCommandLimiter(params, H, HALF_SIZES)
    context = system.CreateDefaultContext()
    system.set_previous(context, measured)
    scaled = np.array(measured) / np.max(np.abs(measured) / limits)
    np.testing.assert_allclose(limiter_state(
        context.get_discrete_state_vector().CopyToVector()).previous,
        scaled, rtol=1e-15)
    system.GetInputPort("velocity").FixValue(context, measured)
    system.GetInputPort("stopped").FixValue(context, [0.0])
    for _ in range(5):
        command = system.GetOutputPort("velocity_command").Eval(context)
        assert np.all(np.abs(command) <= limits * (1 + 1e-15))
        context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())
    # Within the limits, the measured velocity is taken as it is.
    system.set_previous(context, [0.5, -0.25, 0.125])
    np.testing.assert_array_equal(limiter_state(
        context.get_discrete_state_vector().CopyToVector()).previous,
        [0.5, -0.25, 0.125])


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="time_step"):
        BaseCommandLimiter(time_step=0.0)
    with pytest.raises(ValueError, match="half_sizes"):
        BaseCommandLimiter(half_sizes=(0.4, -0.3))
    with pytest.raises(ValueError, match="params"):
        BaseCommandLimiter(params={"stop_time": 0.5})
