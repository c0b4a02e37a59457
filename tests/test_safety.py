"""Run-time safety of the controller: invalid inputs never reach a command
(safe stop, hold, resume without a jump), saturation that keeps the
direction, and singular and limit configurations, on the controller
Diagram advanced against fixed measurements."""

import logging
from dataclasses import dataclass, replace

import numpy as np
import pytest
from controller_rig import H, Rig
from pydrake.systems.framework import (
    InputPortIndex,
    OutputPortIndex,
    PortDataType,
)
from pydrake.systems.primitives import Linearize

from drake_wbc.controller import (
    ControllerParameters,
    build_controller,
    load_controller_parameters,
)
from drake_wbc.controller.diagram import (
    HARDWARE_INPUTS,
    STATION_INPUTS,
    TASK_INPUTS,
)
from drake_wbc.math import command_limits, safety
from drake_wbc.math.motion_mode import MotionMode
from drake_wbc.math.safety import Reason, SafetyParameters
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages import BaseCommandLimiter, InputGuard, StopGate
from drake_wbc.stages.safety import LOGGER, STATUS_FIELDS, GuardedInput

HOLD = safety.DEFAULT_HOLD_TIME
V_MAX = np.array(safety.BASE_VELOCITY_LIMITS)
A_MAX = np.array(safety.BASE_ACCELERATION_LIMITS)
JOINT_SPEED = 1.57
JOINT_ACCELERATION = 12.56
TOL = 1e-9
STATUS = {name: i for i, name in enumerate(STATUS_FIELDS)}


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


# --- invalid inputs: one run injecting into each input in turn --------


@dataclass
class Injection:
    port: str
    bad: object
    reason: Reason
    entry: int
    text: str


def vector_injections():
    injections = []
    sizes = dict(zip(STATION_INPUTS + TASK_INPUTS,
                     (6, 6, 6, None, 6, 6, 1, 1, 1), strict=True))
    for port, size in sizes.items():
        if size is None:
            continue
        entry = size - 1
        injections += [
            Injection(port, (entry, np.nan), Reason.NOT_A_NUMBER, entry,
                      f"{port}[{entry}] is NaN"),
            Injection(port, (entry, np.inf), Reason.INFINITE, entry,
                      f"{port}[{entry}] = inf is infinite"),
        ]
    injections += [
        Injection("null_space_gain", (0, -0.1), Reason.OUT_OF_RANGE, 0,
                  "null_space_gain[0] = -0.1 is out of the range"),
        Injection("compensation_switch", (0, 1.5), Reason.OUT_OF_RANGE, 0,
                  "compensation_switch[0] = 1.5 is out of the range"),
        Injection("lidar.obstacle_points", np.zeros(3), Reason.MALFORMED, -1,
                  "lidar.obstacle_points is malformed"),
    ]
    return injections


INJECTIONS = vector_injections()
WARM_UP = 1.0
FAULT = 0.2
AFTER = HOLD + 0.3
SEGMENT = FAULT + AFTER


class Recorder(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append((record.created, record.getMessage()))


@pytest.fixture(scope="module")
def injected(arm):
    """One run: WARM_UP s valid, then per injection FAULT s with the bad
    value, then AFTER s valid again. Returns the rig, each injection's
    start time, the reason text during each, and the log messages."""
    rig = Rig(arm)
    recorder = Recorder()
    LOGGER.addHandler(recorder)
    try:
        rig.advance(WARM_UP)
        starts, reasons, messages = [], [], []
        for injection in INJECTIONS:
            valid = rig.valid[injection.port]
            if isinstance(injection.bad, tuple):
                entry, bad = injection.bad
                value = np.array(valid, dtype=float)
                value[entry] = bad
            else:
                value = injection.bad
            starts.append(rig.time())
            before = len(recorder.records)
            rig.set(injection.port, value)
            rig.advance(FAULT / 2)
            reasons.append(rig.controller.safety_reason(rig.root_context))
            rig.advance(FAULT / 2)
            rig.set(injection.port, valid)
            rig.advance(AFTER)
            messages.append([m for _, m in recorder.records[before:]])
    finally:
        LOGGER.removeHandler(recorder)
    return rig, starts, reasons, messages


def index_at(times, t):
    return int(np.argmin(np.abs(times - t)))


def test_no_output_is_ever_not_finite(injected):
    rig = injected[0]
    for name in rig.logs:
        times, data = rig.log(name)
        assert times[-1] > WARM_UP + len(INJECTIONS) * SEGMENT - 0.02
        assert np.all(np.isfinite(data)), name


@pytest.mark.parametrize("k", range(len(INJECTIONS)),
                         ids=[f"{i.port}-{i.reason.name}" for i in INJECTIONS])
def test_invalid_input_stops_holds_and_resumes(injected, k):
    rig, starts, reasons, messages = injected
    injection, t0 = INJECTIONS[k], starts[k]
    times, base = rig.log("base.velocity_command")
    _, q_cmd = rig.log("arm.position_command")
    _, status = rig.log("safety_status")
    # A sample logged at t shows the outputs before the update at t: what
    # the tick at t decides is in the next sample.
    i0 = index_at(times, t0) + 1           # the first tick with the bad value
    i1 = index_at(times, t0 + FAULT) + 1   # the first valid tick again
    i_resume = index_at(times, t0 + FAULT + HOLD - H) + 1
    i_end = index_at(times, t0 + SEGMENT)
    # Moving before the fault; stopped from its first tick.
    assert status[i0 - 1, STATUS["stopped"]] == 0.0
    assert np.abs(base[i0 - 1]).max() > 1e-3
    np.testing.assert_array_equal(base[i0:i_resume], 0.0)
    assert np.all(status[i0:i_resume, STATUS["stopped"]] == 1.0)
    # The arm held at the last command before the fault.
    q_last = q_cmd[i0 - 1]
    assert np.abs(q_cmd[i0 - 1] - q_cmd[i0 - 2]).max() > 1e-6  # was moving
    np.testing.assert_array_equal(q_cmd[i0:i_resume], np.tile(
        q_last, (i_resume - i0, 1)))
    # The status names the input, the reason, the entry.
    names = rig.controller.stages["guard"].input_names
    assert sorted(names) == sorted(STATION_INPUTS + TASK_INPUTS
                                   + HARDWARE_INPUTS)
    expected_input = names.index(injection.port)
    fault = status[i0]
    assert fault[STATUS["invalid"]] == 1.0
    assert fault[STATUS["reason"]] == int(injection.reason)
    assert fault[STATUS["input"]] == expected_input
    assert fault[STATUS["entry"]] == injection.entry
    assert status[i1, STATUS["invalid"]] == 0.0     # valid, holding
    assert status[i1, STATUS["reason"]] == int(injection.reason)
    assert status[i0, STATUS["trips"]] == status[i0 - 1, STATUS["trips"]] + 1
    assert injection.text in reasons[k]
    # Resumes after HOLD of valid inputs, not before.
    assert status[i_resume - 1, STATUS["stopped"]] == 1.0
    assert status[i_resume, STATUS["stopped"]] == 0.0
    assert status[i_resume, STATUS["reason"]] == 0.0
    # Once on the log when it trips, once when it clears.
    assert len(messages[k]) == 2
    assert "safe stop at" in messages[k][0]
    assert injection.port in messages[k][0]
    assert "cleared" in messages[k][1]
    # No jump on resuming: the base from zero within its acceleration
    # limits, the arm from rest at the held position within its limits.
    steps = np.abs(np.diff(base[i_resume - 1:i_end], axis=0))
    assert np.all(steps <= A_MAX * H + TOL)
    assert np.abs(base[i_end]).max() > 1e-3          # moving again
    q = q_cmd[i_resume - 1:i_end]
    rates = np.diff(q, axis=0) / H
    assert np.all(np.abs(rates) <= JOINT_SPEED + TOL)
    accelerations = np.diff(np.vstack([np.zeros(6), rates]), axis=0) / H
    assert np.all(np.abs(accelerations) <= JOINT_ACCELERATION * (1 + 1e-6))
    assert np.abs(q[-1] - q_last).max() > 1e-4        # moving again


def test_a_point_with_nan_is_dropped_not_a_fault(arm):
    rig = Rig(arm)
    points = np.array([[0.7, 0.1], [np.nan, 0.3], [np.inf, 1.0],
                       [2.0, 0.0]])
    rig.set("lidar.obstacle_points", points)
    rig.advance(0.5)
    _, status = rig.log("safety_status")
    assert np.all(status[:, STATUS["stopped"]] == 0.0)
    assert np.all(status[1:, STATUS["dropped_points"]] == 2.0)
    # The same commands as with the finite points alone.
    clean = Rig(arm)
    clean.set("lidar.obstacle_points", points[[0, 3]])
    clean.advance(0.5)
    for name in ("base.velocity_command", "arm.position_command"):
        np.testing.assert_array_equal(rig.log(name)[1], clean.log(name)[1])


def test_commands_have_no_direct_feedthrough_from_inputs(arm):
    diagram = build_controller(arm=arm).diagram
    for output in ("base.velocity_command", "arm.position_command",
                   "safety_status"):
        j = diagram.GetOutputPort(output).get_index()
        for i in range(diagram.num_input_ports()):
            assert not diagram.HasDirectFeedthrough(i, j), output


# --- saturation that keeps the direction -------------------------------


def test_velocity_scaling_is_parallel_in_closed_form():
    desired = np.array([3.0, -1.5, 0.5])
    result = command_limits.limit_base_velocity(desired, desired / 3.0,
                                                V_MAX, A_MAX, H)
    np.testing.assert_allclose(result.command, desired / 3.0, rtol=1e-15)
    assert result.velocity_scale == pytest.approx(1.0 / 3.0, rel=1e-15)
    assert result.acceleration_scale == 1.0 and result.limited
    # The change scaled as a whole: from rest, a_max h on the largest axis.
    change = np.array([0.5, 0.2, -0.1])
    result = command_limits.limit_base_velocity(change, np.zeros(3), V_MAX,
                                                A_MAX, H)
    np.testing.assert_allclose(result.command, change * (A_MAX[0] * H / 0.5),
                               rtol=1e-15)
    assert result.acceleration_scale == pytest.approx(0.02, rel=1e-15)
    # Within limits: unchanged, bit for bit.
    small = np.array([0.1, 0.2, -0.3]) / 3.0
    result = command_limits.limit_base_velocity(small, small + 0.001, V_MAX,
                                                A_MAX, H)
    assert result.command is small and not result.limited
    assert command_limits.uniform_scale([2.0, -4.0], [1.0, 1.0]) == 0.25


def _limit_as_written(desired, previous, scale):
    """limit_base_velocity's formulas, written out in numpy."""
    def scale_into(vector, limits):
        over = np.abs(vector) > limits
        return 1.0 if not over.any() else np.min(
            limits[over] / np.abs(vector[over]))
    desired = scale * desired
    s_v = scale_into(desired, V_MAX)
    target = s_v * desired
    s_a = scale_into(target - previous, A_MAX * H)
    return previous + s_a * (target - previous), scale * s_v, s_a


def test_limits_agree_with_the_formulas_written_out():
    rng = np.random.default_rng(11)
    for _ in range(2000):
        desired = rng.uniform(-2.0, 2.0, 3) * rng.choice([0.01, 0.1, 1.0])
        previous = np.clip(desired + rng.normal(0.0, 0.02, 3), -V_MAX, V_MAX)
        scale = rng.choice([1.0, rng.uniform(0.0, 1.0)])
        result = command_limits.limit_base_velocity(
            desired, previous, V_MAX, A_MAX, H, scale=scale)
        command, s_v, s_a = _limit_as_written(desired, previous, scale)
        np.testing.assert_allclose(result.command, command, rtol=1e-14,
                                   atol=1e-15)
        assert result.velocity_scale == pytest.approx(s_v, rel=1e-14)
        assert result.acceleration_scale == pytest.approx(s_a, rel=1e-14)
        assert np.all(np.abs(result.command) <= V_MAX * (1 + 1e-12))


def test_saturated_base_command_is_parallel_and_flagged(arm):
    params = ControllerParameters()
    params.workspace.mode = MotionMode.LOCOMOTION  # sigma = 0: the base
    rig = Rig(arm, params)
    rig.set("reference_velocity", [2.4, -1.8, 0.0, 0.0, 0.0, 0.0])
    rig.set("lidar.obstacle_points", np.zeros((0, 2)))
    rig.advance(2.0)
    times, command = rig.log("base.velocity_command")
    _, desired = rig.log("base_velocity")
    _, filtered = rig.log("filtered_base_velocity")
    _, saturation = rig.log("base_saturation")
    for signal in (command, filtered):
        assert np.all(np.abs(signal) <= V_MAX + TOL)
    assert np.all(np.abs(np.diff(command, axis=0)) <= A_MAX * H + TOL)
    late = times > 1.8
    assert np.all(saturation[late, 0] == 1.0)
    # Parallel to the desired command V_b, scaled by 1 / max |V_b_i| (the
    # envelope before the filter; V_b is about 3 m/s in x: the base's half
    # is the whole planar motion, rotated into T_b by the yaw of 0.3 rad),
    # once the DMP and the filter have settled.
    for c, d, s in zip(command[late], desired[late], saturation[late],
                       strict=True):
        scale = 1.0 / np.max(np.abs(d))
        np.testing.assert_allclose(c, scale * d, rtol=2e-3, atol=1e-6)
        assert s[1] == pytest.approx(scale, rel=2e-3)
    assert np.max(np.abs(desired[late])) > 1.5


# --- singular and limit configurations ---------------------------------


def limit_case(arm, q, reference, params=None, points=None, duration=1.5):
    rig = Rig(arm, params, q=q)
    rig.set("reference_velocity", reference)
    if points is not None:
        rig.set("lidar.obstacle_points", points)
    rig.advance(duration)
    return rig


def assert_within_limits(rig, arm):
    for name in rig.logs:
        assert np.all(np.isfinite(rig.log(name)[1])), name
    _, base = rig.log("base.velocity_command")
    assert np.all(np.abs(base) <= V_MAX + TOL)
    assert np.all(np.abs(np.diff(base, axis=0)) <= A_MAX * H + TOL)
    _, q = rig.log("arm.position_command")
    assert np.all(q <= arm.upper + TOL) and np.all(q >= arm.lower - TOL)
    assert np.all(np.abs(np.diff(q, axis=0)) <= JOINT_SPEED * H + TOL)
    _, status = rig.log("safety_status")
    assert np.all(status[:, STATUS["stopped"]] == 0.0)
    return base, q


WRIST_ALIGNED = HOME_ARM_POSITIONS * [1, 1, 1, 1, 0, 1]
STRETCHED = np.array([0.0, -0.45, 0.0, 0.0, 1.15, 0.0])


@pytest.mark.parametrize("q, reference", [
    (WRIST_ALIGNED, [0.0, 0.0, 0.0, 0.3, 0.2, 0.0]),
    (STRETCHED, [0.3, 0.0, 0.1, 0.0, 0.0, 0.0]),
], ids=["wrist-aligned", "stretched"])
def test_near_a_singularity(arm, q, reference):
    rig = limit_case(arm, q, reference)
    _, q_cmd = assert_within_limits(rig, arm)
    assert np.abs(q_cmd[-1] - q).max() > 1e-3  # it did move


def test_at_joint_limits(arm):
    q = HOME_ARM_POSITIONS.copy()
    q[1] = arm.lower[1]          # the shoulder on its limit
    q[5] = arm.upper[5] + 0.02   # the wrist measured beyond its limit
    rig = limit_case(arm, q, [-0.3, 0.1, -0.3, 0.5, 0.0, 1.0])
    _, q_cmd = assert_within_limits(rig, arm)
    assert q_cmd[0, 5] == arm.upper[5]


@pytest.mark.parametrize("sigma, mode", [
    (0.0, MotionMode.LOCOMOTION), (1.0, MotionMode.MANIPULATION)])
def test_sigma_at_its_ends(arm, sigma, mode):
    params = ControllerParameters()
    params.workspace.mode = mode  # sigma_xy = sigma_phi = sigma
    rig = limit_case(arm, HOME_ARM_POSITIONS, [0.2, 0.1, 0.0, 0.0, 0.0, 0.2],
                     params)
    base, _ = assert_within_limits(rig, arm)
    assert (np.abs(base[-1]).max() > 1e-3) == (sigma == 0.0)


def test_obstacle_inside_the_footprint(arm):
    points = np.array([[0.0, 0.0], [0.39, 0.29], [-0.1, 0.05]])
    rig = limit_case(arm, HOME_ARM_POSITIONS, [0.0] * 6, points=points)
    base, _ = assert_within_limits(rig, arm)
    assert np.abs(base).max() > 1e-3  # pushed, but within the limits


# --- the systems and parameters ----------------------------------------


def test_systems_convert_to_autodiff():
    guard = InputGuard([GuardedInput("u", 2, (("u", [1.0, 2.0]),))],
                       points_name="points")
    for system in (guard, StopGate(3), BaseCommandLimiter()):
        converted = system.ToAutoDiffXd()
        context = converted.CreateDefaultContext()
        for i in range(converted.num_input_ports()):
            port = converted.get_input_port(i)
            if port.get_data_type() == PortDataType.kVectorValued:
                port.FixValue(context, np.zeros(port.size()))
        for i in range(converted.num_output_ports()):
            converted.get_output_port(i).Eval(context)
        converted.EvalUniquePeriodicDiscreteUpdate(context) if (
            converted.num_discrete_state_groups()) else None
    assert guard.ToAutoDiffXd().params == guard.params


def test_limiter_linearises_to_the_identity_within_limits():
    limiter = BaseCommandLimiter()
    context = limiter.CreateDefaultContext()
    limiter.set_previous(context, [0.2, -0.1, 0.05])
    limiter.GetInputPort("velocity").FixValue(context, [0.2, -0.1, 0.05])
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    linear = Linearize(limiter, context,
                       input_port_index=InputPortIndex(0),
                       output_port_index=OutputPortIndex(0))
    np.testing.assert_allclose(linear.D(), np.eye(3), atol=1e-9)


def test_the_controller_converts_to_autodiff(arm):
    converted = build_controller(arm=arm).diagram.ToAutoDiffXd()
    assert converted.HasOutputPort("safety_status")


@pytest.mark.parametrize("kwargs, name", [
    (dict(hold_time=0.0), "hold_time"),
    (dict(hold_time=float("nan")), "hold_time"),
    (dict(base_velocity_limits=[1.0, -1.0, 1.0]), "base_velocity_limits"),
    (dict(base_acceleration_limits=[1.0, 1.0]), "base_acceleration_limits"),
])
def test_bad_parameters_are_rejected(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SafetyParameters(**kwargs)


def test_parameters_load_from_yaml():
    params = load_controller_parameters(
        text="safety: {hold_time: 0.2, base_velocity_limits: [0.5, 0.5, 1]}")
    assert params.safety == replace(SafetyParameters(), hold_time=0.2,
                                    base_velocity_limits=(0.5, 0.5, 1.0))
    with pytest.raises(ValueError, match="safety.hold_time"):
        load_controller_parameters(text="safety: {hold_time: -1}")


def test_checks_in_closed_form():
    assert safety.check_vector([1.0, np.nan, np.inf]) == (
        Reason.NOT_A_NUMBER, 1, pytest.approx(np.nan, nan_ok=True))
    assert safety.check_vector([1.0, -np.inf, np.nan]).reason is (
        Reason.INFINITE)
    assert safety.check_vector([0.5, 2.0], 0.0, 1.0)[:2] == (
        Reason.OUT_OF_RANGE, 1)
    assert safety.check_vector([0.0, 1.0], 0.0, 1.0).valid
    kept, dropped, check = safety.check_points(
        [[1.0, 2.0], [np.nan, 0.0], [3.0, 4.0]])
    np.testing.assert_array_equal(kept, [[1.0, 2.0], [3.0, 4.0]])
    assert dropped == 1 and check.valid
    assert safety.check_points(np.zeros((2, 3)))[2].reason is (
        Reason.MALFORMED)
    state = safety.StopState(False, 0.0)
    state = safety.next_stop_state(state, True, H, 0.05)
    assert state == (True, 0.0)
    for _ in range(4):
        state = safety.next_stop_state(state, False, H, 0.05)
        assert state.stopped
    assert not safety.next_stop_state(state, False, H, 0.05).stopped
