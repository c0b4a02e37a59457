"""Run-time safety of the controller: invalid inputs never reach a command
(safe stop, hold, resume without a jump), saturation that keeps the
direction, and singular and limit configurations, on the controller
Diagram advanced against fixed measurements."""

import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from controller_rig import H, Rig
from pydrake.autodiffutils import ExtractValue
from pydrake.systems.framework import (
    InputPortIndex,
    OutputPortIndex,
    PortDataType,
)
from pydrake.systems.primitives import Linearize
from shipped_names import (
    BASE_ACCELERATION_LIMITS,
    BASE_LIMITS,
    BASE_VELOCITY_LIMITS,
    FOOTPRINT,
)

from drake_wbc.controller import (
    ControllerParameters,
    build_controller,
    load_controller_parameters,
)
from drake_wbc.controller.diagram import HARDWARE_INPUTS, STATION_INPUTS
from drake_wbc.experiments.runner import (
    build_closed_loop,
    fault_message,
    simulate,
    start_simulator,
)
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.math import command_limits, safety
from drake_wbc.math.arm_control import DEFAULT_JOINT_LIMIT_MARGIN
from drake_wbc.math.motion_mode import MotionMode
from drake_wbc.math.safety import STATUS_FIELDS, Reason, SafetyParameters
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    ArmKinematics,
    arm_kinematics,
)
from drake_wbc.stages import BaseCommandLimiter, InputGuard, StopGate
from drake_wbc.stages.arm_control import CAUGHT_UP
from drake_wbc.stages.safety import LOGGER, GuardedInput

HOLD = safety.DEFAULT_HOLD_TIME
V_MAX = np.array(BASE_VELOCITY_LIMITS)
A_MAX = np.array(BASE_ACCELERATION_LIMITS)
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
    sizes = dict(zip(STATION_INPUTS + tuple(TASK_INPUTS),
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
        # A joint read a million radians off (a corrupted or forged
        # status): beyond the span of the joints' limits.
        Injection("arm.position_measured", (5, 1e6), Reason.OUT_OF_RANGE, 5,
                  "arm.position_measured[5] = 1000000.0 is out of the "
                  "range"),
        Injection("lidar.obstacle_points", np.zeros(3), Reason.MALFORMED, -1,
                  "lidar.obstacle_points is malformed"),
    ]
    # A switch is 0 or 1: the stages would read 0.7 and 3 as 1, -1 as 0.
    injections += [
        Injection("phri_switch", (0, bad), Reason.NOT_A_SWITCH, 0,
                  f"phri_switch[0] = {bad!r} is not a switch: must be 0 or 1")
        for bad in (0.7, 3.0, -1.0)]
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
            rig.restore(injection.port)
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
    # The arm brakes to rest from its last command, within its
    # acceleration limit (at most 0.125 s from 1.57 rad/s), and holds.
    assert np.abs(q_cmd[i0 - 1] - q_cmd[i0 - 2]).max() > 1e-6  # was moving
    rest = i0 + 14
    q_last = q_cmd[rest]
    np.testing.assert_array_equal(q_cmd[rest:i_resume], np.tile(
        q_last, (i_resume - rest, 1)))
    rates = np.diff(q_cmd[i0 - 2:rest + 1], axis=0) / H
    assert np.all(np.abs(np.diff(rates, axis=0)) / H
                  <= JOINT_ACCELERATION * (1 + 1e-6))
    # The status names the input, the reason, the entry.
    names = rig.controller.stages["guard"].input_names
    assert sorted(names) == sorted(STATION_INPUTS + tuple(TASK_INPUTS)
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


# --- no command jumps, nothing integrated while stopped ----------------


def tripped_run(arm, params=None, reference=(0.3, 0.2, 0.0, 0.0, 0.0, 0.3),
                port="base.state_estimated", phri=0.0, push=None,
                sample=None):
    """A brisk motion, then a NaN on `port` for 0.3 s, then valid inputs
    again for 2 s. `push`: a force (N, sensor frame) added to the wrist
    reading throughout; `sample(rig)`, called after each tick from the
    trip on. Returns the rig, the trip's first and the stop's last
    logged sample."""
    rig = Rig(arm, params)
    rig.set("reference_velocity", list(reference))
    rig.set("phri_switch", [phri])
    if push is not None:
        reading = np.array(rig.valid["wrist.wrench_measured"], dtype=float)
        reading[:3] += push
        rig.set("wrist.wrench_measured", reading)
    rig.advance(2.0)
    bad = np.array(rig.valid[port], dtype=float)
    bad[0] = np.nan
    rig.set(port, bad)
    for k in range(round(2.3 / H)):
        if k == round(0.3 / H):
            rig.restore(port)
        rig.advance(H)
        if sample is not None:
            sample(rig)
    times, status = rig.log("safety_status")
    stopped = np.flatnonzero(status[:, STATUS["stopped"]])
    return rig, stopped[0], stopped[-1]


def test_no_command_jumps_through_a_trip(arm):
    """From the trip on, through the stop and after it clears, every
    command stays within the acceleration limits, except the base's
    velocity command going to zero at once when the stop begins (the
    base's own drive brakes it, the shortest stop it can make). The
    joints brake within 12.56 rad/s^2 (held at once, they asked for
    19.9 rad/s^2 here), and both resume from what was last sent, from
    rest."""
    rig, first, last = tripped_run(arm)
    _, base = rig.log("base.velocity_command")
    _, q_cmd = rig.log("arm.position_command")
    assert np.abs(base[first - 1]).max() > 0.1         # fast before it
    np.testing.assert_array_equal(base[first:last + 1], 0.0)
    steps = np.abs(np.diff(base[first:], axis=0))
    assert steps.max() <= A_MAX[0] * H + TOL           # largest after it
    assert steps[last - first:].max() > 1e-3           # moving again
    rates = np.diff(q_cmd[first - 3:], axis=0) / H
    assert np.abs(rates[:3]).max() > 0.15              # moving before it
    accelerations = np.abs(np.diff(rates, axis=0)) / H
    assert accelerations.max() <= JOINT_ACCELERATION * (1 + 1e-6)
    assert np.abs(rates[-100:]).max() > 1e-3            # moving again


def test_a_redundant_arm_holds_still_in_a_stop():
    """A seven-joint arm started away from the middles of its joints,
    whose self-motion keeps moving it: a NaN on an input stops the
    controller, and once braked (within the acceleration limit) the arm's
    command stays where it is until the stop clears (the joint centring
    went on moving a stopped robot at 0.02 rad/s), then moves again."""
    description = load_robot_description(
        Path(__file__).resolve().parent.parent / "models"
        / "lbr_omni.robot.yaml")
    arm = arm_kinematics(description)
    rig = Rig(arm, q=np.asarray(arm.home) + 0.3)
    rig.set("reference_velocity", [0.0] * 6)
    rig.advance(1.0)
    bad = np.array(rig.valid["base.state_estimated"], dtype=float)
    bad[0] = np.nan
    rig.set("base.state_estimated", bad)
    rig.advance(0.3)
    rig.set("base.state_estimated", rig.valid["base.state_estimated"])
    rig.advance(HOLD + 0.5)
    _, q_cmd = rig.log("arm.position_command")
    _, status = rig.log("safety_status")
    stopped = np.flatnonzero(status[:, STATUS["stopped"]])
    first, last = stopped[0], stopped[-1]
    assert np.abs(q_cmd[first - 1] - q_cmd[first - 2]).max() > 1e-5
    braked = first + 14  # at most 0.125 s from 1.57 rad/s
    np.testing.assert_array_equal(
        q_cmd[braked:last + 1], np.tile(q_cmd[braked], (last - braked + 1, 1)))
    assert np.abs(q_cmd[-1] - q_cmd[last]).max() > 1e-5  # moving again


@pytest.mark.parametrize("case", ["admittance", "force-control"])
def test_the_dmps_do_not_integrate_while_stopped(arm, case):
    """The DMPs' couplings (the integrated reference and wrench terms C,
    C_a, the base's C_b and the tracking error E) are held while stopped,
    though a person keeps pushing and the force error persists (the
    guard passes the last valid wrench on): after the stop the robot does
    not make up for what they would have integrated meanwhile."""
    params = ControllerParameters()
    if case == "force-control":
        params.arm_cdmp.S_m = [0.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    stages = ("whole_body_cdmp", "base_cdmp", "arm_cdmp")
    parts = {"whole_body_cdmp": slice(12, 24), "base_cdmp": slice(6, 9),
             "arm_cdmp": slice(12, 18)}
    records = []

    def sample(rig):
        status = rig.controller.stages["guard"].GetOutputPort(
            "safety_status").Eval(rig.controller.stages[
                "guard"].GetMyContextFromRoot(rig.root_context))
        records.append((status[STATUS["stopped"]], [
            rig.controller.stages[name].GetMyContextFromRoot(
                rig.root_context).get_discrete_state_vector()
            .CopyToVector()[parts[name]] for name in stages]))

    tripped_run(arm, params, port="reference_velocity",
                phri=1.0 if case == "admittance" else 0.0,
                push=[15.0, -10.0, 5.0], sample=sample)
    held = [states for stopped, states in records if stopped]
    assert len(held) >= 50
    moved = 0.0
    for states in held[1:]:
        for state, start in zip(states, held[0], strict=True):
            np.testing.assert_allclose(state, start, rtol=1e-12,
                                       atol=1e-15)
    for state, start in zip(records[-1][1], held[0], strict=True):
        moved = max(moved, np.abs(state - start).max())
    assert moved > 1e-3  # they do integrate when not stopped


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


def test_a_reference_too_large_for_the_dmps_is_a_fault(arm):
    """A finite reference of 1e16 m/s for 50 ms: the DMPs, integrating it
    in double precision, lost their own values in it, and seven seconds
    later the base still drove at its full speed against the reference
    (-1 m/s for 0.1), with no input invalid. Beyond MAX_REFERENCE it is a
    fault: a safe stop that names it, after which the robot resumes the
    task as a run without it does."""
    rig, clean = Rig(arm), Rig(arm)
    bad = np.array(rig.valid["reference_velocity"], dtype=float)
    bad[[0, 1, 5]] = 1e16
    for run, value in ((rig, bad), (clean, rig.valid["reference_velocity"])):
        run.advance(0.3)
        run.set("reference_velocity", value)
        run.advance(0.05)
        if run is rig:
            assert ("reference_velocity[0] = 1e+16 is out of the range"
                    in rig.controller.safety_reason(rig.root_context))
        run.set("reference_velocity", rig.valid["reference_velocity"])
        run.advance(7.0)
    _, status = rig.log("safety_status")
    assert status[:, STATUS["trips"]].max() == 1.0
    assert status[-1, STATUS["stopped"]] == 0.0
    command = rig.log("base.velocity_command")[1][-1]
    np.testing.assert_allclose(
        command, clean.log("base.velocity_command")[1][-1], atol=1e-3)


@pytest.mark.parametrize("entry, value", [(2, 1e30), (4, -30.5)])
def test_a_wrench_beyond_the_sensors_range_is_a_fault(arm, entry, value):
    """A finite wrist reading beyond what the sensor can measure (its
    range in the robot's description: the FT-300's 300 N and 30 N m) was
    taken as a real force: 1e30 N on the wrist, passed to the admittance
    and the arm's DMP. It is a fault of the stream: a safe stop that
    names the entry, after which the robot resumes as a run without it;
    a reading at the range itself (a saturated sensor) is not."""
    rig, clean = Rig(arm), Rig(arm)
    valid = np.array(rig.valid["wrist.wrench_measured"], dtype=float)
    bad = valid.copy()
    bad[entry] = value
    at_range = valid.copy()
    at_range[entry] = np.sign(value) * (300.0 if entry < 3 else 30.0)
    for run in (rig, clean):
        run.advance(0.3)
        if run is rig:
            run.set("wrist.wrench_measured", at_range)
            run.advance(0.05)
            assert rig.controller.safety_reason(rig.root_context) == ""
            run.set("wrist.wrench_measured", bad)
        run.advance(0.05)
        if run is rig:
            assert (f"wrist.wrench_measured[{entry}] = {value!r} is out of "
                    "the range" in rig.controller.safety_reason(
                        rig.root_context))
        run.set("wrist.wrench_measured", valid)
        run.advance(1.0)
    _, status = rig.log("safety_status")
    assert status[:, STATUS["trips"]].max() == 1.0
    assert status[-1, STATUS["stopped"]] == 0.0
    # Zero at the stop (the base's drive brakes), then from rest within
    # the acceleration limits.
    t, commands = rig.log("base.velocity_command")
    stopped = status[:, STATUS["stopped"]] == 1.0
    np.testing.assert_array_equal(commands[stopped], 0.0)
    after = t > t[stopped][0]
    steps = np.abs(np.diff(commands[after], axis=0)) / H
    assert np.all(steps <= A_MAX * (1.0 + TOL))


@pytest.mark.parametrize("entry, value", [(3, 50.0), (2, 1e30),
                                          (0, 1e30)])
def test_an_odometry_no_base_can_read_is_a_fault(arm, entry, value):
    """The base's state had no range: a forged or corrupted odometry of
    1e30 rad of yaw turned the world-frame reference into an arbitrary
    direction (the arm's joints at 0.74 rad/s instead of 0.4, no input
    invalid), one of 1e30 m left the people tracker no precision, and a
    twist of 50 m/s was taken as measured. A pose beyond MAX_ODOMETRY or
    a twist beyond MEASURED_TWIST_FACTOR times the base's own limits is
    a fault; five times its limit (a slipping wheel) is not."""
    rig = Rig(arm)
    rig.advance(0.3)
    state = np.array(rig.valid["base.state_estimated"])
    fast = state.copy()
    fast[3] = 5.0 * V_MAX[0]
    rig.set("base.state_estimated", fast)
    rig.advance(0.05)
    assert rig.controller.safety_reason(rig.root_context) == ""
    state[entry] = value
    rig.set("base.state_estimated", state)
    rig.advance(0.05)
    assert (f"base.state_estimated[{entry}] = {value!r} is out of the "
            "range" in rig.controller.safety_reason(rig.root_context))


def test_an_arm_position_beyond_its_own_joints_limit_is_a_fault(arm):
    """The arm's measured positions had one range for every joint, the
    widest joint's (+-3.14 rad, give or take the margin): a status of
    3.0 rad on the fifth joint, limited to +-2.56 rad, was taken as a
    real position. Each joint has its own range now.

    Within the margin beyond its limit (0.05 rad, no fault) the arm is
    still no position to restart from when the stop clears: the command
    restarted there, held on the limit, jumped 0.72 rad in one tick (72
    rad/s), and still 0.05 rad away from the arm. It resumes from where it
    was (restart_position, the rule of the hardware's guard); the arm
    not following it, the controller stops again and its held command
    goes within the joint speed limit to the edge of the band the
    running command keeps to (the margin inside the limit), from where
    it resumes."""
    rig = Rig(arm)
    rig.advance(0.1)
    q = np.array(rig.q)
    q[4] = arm.upper[4] + safety.MEASURED_POSITION_MARGIN + 0.01
    assert q[4] < np.max(arm.upper)
    rig.set("arm.position_measured", q)
    rig.advance(0.05)
    assert ("arm.position_measured[4]" in
            rig.controller.safety_reason(rig.root_context))
    q[4] = arm.upper[4] + 0.5 * safety.MEASURED_POSITION_MARGIN
    rig.set("arm.position_measured", q)
    rig.advance(HOLD + 0.05)
    assert rig.controller.safety_reason(rig.root_context).startswith(
        "arm.position_measured[4] is 0.753 rad from the last command")
    rig.advance(HOLD)
    assert rig.controller.safety_reason(rig.root_context) == ""
    _, command = rig.log("arm.position_command")
    edge = arm.upper[4] - DEFAULT_JOINT_LIMIT_MARGIN
    assert edge - 0.01 < command[-1][4] <= edge + 1e-12
    assert np.abs(np.diff(command, axis=0)).max() <= JOINT_SPEED * H * (
        1 + 1e-9)


def test_a_protective_stop_stops_the_arm_too(arm):
    """A point inside the footprint (a person, or what the base struck)
    while the robot follows 0.3 m/s ahead: the base braked to rest, and
    the arm, compensating the braking and then carrying the whole
    reference, went on moving the tool towards it at up to 0.29 rad/s a
    joint for as long as the stop lasted. It brakes to rest within its
    acceleration limit and holds, and after the stop the arm and the
    base resume from rest within their acceleration limits."""
    rig = Rig(arm)
    rig.set("reference_velocity", [0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    rig.advance(1.0)
    rig.set("lidar.obstacle_points", np.array([[0.35, 0.0], [2.0, 0.0]]))
    rig.advance(1.0)
    rig.set("lidar.obstacle_points", rig.valid["lidar.obstacle_points"])
    rig.advance(1.5)
    t, stop = rig.log("base_protective_stop")
    _, q = rig.log("arm.position_command")
    rates = np.diff(q, axis=0) / H  # rates[k]: from tick k to k + 1
    stopped = np.flatnonzero(stop[:, 0] == 1.0)
    assert t[stopped[0]] == pytest.approx(1.01)
    assert np.abs(rates[stopped[0] - 1]).max() > 0.1
    # At rest within 0.125 s (1.57 rad/s at 12.56 rad/s^2) and a tick,
    # then held.
    rest = stopped[0] + 14
    np.testing.assert_allclose(q[rest:stopped[-1] + 1] - q[rest], 0.0,
                               atol=1e-12)
    accelerations = np.abs(np.diff(rates, axis=0)) / H
    assert np.all(accelerations <= JOINT_ACCELERATION * (1.0 + 1e-6))
    assert np.abs(rates[-1]).max() > 0.05  # moving again
    _, base = rig.log("base.velocity_command")
    steps = np.abs(np.diff(base, axis=0)) / H
    assert np.all(steps <= A_MAX * (1.0 + TOL))


def test_commands_have_no_direct_feedthrough_from_inputs(arm):
    diagram = build_controller(robot=arm).diagram
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
    np.testing.assert_array_equal(result.command, small)
    assert not result.limited
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
    # The arm's measurement held at its start, so that the capability
    # and the distribution stay put; a tolerance that lets it.
    params.safety.arm_follow_tolerance = 10.0
    rig = Rig(arm, params)
    rig.set("arm.position_measured", rig.q)
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
    # The wrist measured past its limit, as an encoder at its limit reads
    # (within one period's step at the acceleration limit: further is
    # refused, arm_control.start_within_limits).
    q[5] = arm.upper[5] + 0.9 * arm.acceleration_limits[5] * H * H
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
    # A protective stop, not a push by the field (which reached 0.59 m/s):
    # from rest, the base stays at rest.
    assert np.abs(base).max() == 0.0


# --- the systems and parameters ----------------------------------------


def test_systems_convert_to_autodiff():
    guard = InputGuard([GuardedInput("u", 2, (("u", [1.0, 2.0]),))],
                       points_name="points")
    for system in (guard, StopGate(3), BaseCommandLimiter(
            SafetyParameters(**BASE_LIMITS), half_sizes=FOOTPRINT)):
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


def test_stop_gate_zeroes_or_scales_as_a_whole():
    """The gate in closed form, in double and in AutoDiffXd: zeros while
    stopped; else the value scaled by min(1, min_i limit_i / |v_i|)."""
    limits = (0.5, 0.4, 0.9)
    double = StopGate(3, limits)
    autodiff = double.ToAutoDiffXd()
    rng = np.random.default_rng(13)
    contexts = [system.CreateDefaultContext()
                for system in (double, autodiff)]
    for _ in range(60):
        value = rng.normal(size=3) * rng.choice([0.1, 1.0])
        stop = float(rng.random() < 0.2)
        expected = 1.0 if stop else min(
            [1.0] + [lim / abs(v) for v, lim in zip(value, limits,
                                                     strict=True)
                     if abs(v) > lim])
        for system, context in zip((double, autodiff), contexts,
                                   strict=True):
            system.GetInputPort("value").FixValue(context, value)
            system.GetInputPort("stop").FixValue(context, [stop])
            gated, scale = (
                np.asarray(ExtractValue(np.asarray(
                    system.GetOutputPort(name).Eval(context), dtype=object)),
                    dtype=float).ravel() for name in ("gated", "scale"))
            assert scale[0] == expected
            np.testing.assert_array_equal(
                gated, np.zeros(3) if stop else
                (value if expected == 1.0 else expected * value))


def test_limiter_linearises_to_the_identity_within_limits():
    limiter = BaseCommandLimiter(SafetyParameters(**BASE_LIMITS),
                                 half_sizes=FOOTPRINT)
    context = limiter.CreateDefaultContext()
    limiter.set_previous(context, [0.2, -0.1, 0.05])
    limiter.GetInputPort("velocity").FixValue(context, [0.2, -0.1, 0.05])
    limiter.GetInputPort("stopped").FixValue(context, [0.0])
    linear = Linearize(limiter, context,
                       input_port_index=InputPortIndex(0),
                       output_port_index=OutputPortIndex(0))
    np.testing.assert_allclose(linear.D(), np.eye(3), atol=1e-9)


def test_the_controller_converts_to_autodiff(arm):
    converted = build_controller(robot=arm).diagram.ToAutoDiffXd()
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


@pytest.mark.parametrize("text, message", [
    ("safety: {base_velocity_limits: [1e9, 1.0, 1.0]}",
     r"safety.base_velocity_limits\[0\] = 1000000000.0 is not allowed: "
     r"must be at most the robot's own 1.0 m/s"),
    ("safety: {base_acceleration_limits: [1.0, 1.0, 1e9]}",
     r"safety.base_acceleration_limits\[2\] = 1000000000.0 .* robot's own "
     r"1.0 rad/s\^2"),
    ("arm_controller: {acceleration_limit: 1e6}",
     r"arm_controller.acceleration_limit = 1000000.0 .* arm's own 12.56"),
    ("arm_controller: {use_acceleration_limit: false}",
     r"arm_controller.use_acceleration_limit = False is not allowed"),
    ("safety: {base_lag: 0.1}",
     r"safety.base_lag = 0.1 is not allowed: must be at least the robot's "
     r"own 0.3 s"),
], ids=["base-velocity", "base-acceleration", "arm-acceleration",
        "arm-acceleration-off", "base-lag"])
def test_limits_only_tighten(arm, text, message):
    """Every safety limit may tighten the robot's own, not widen it: the
    error names the field, its value and the robot's."""
    params = load_controller_parameters(text=text)
    with pytest.raises(ValueError, match=message):
        build_controller(params, arm)


def test_tighter_limits_are_accepted(arm):
    build_controller(load_controller_parameters(text="""
safety: {base_velocity_limits: [0.5, 0.5, 0.5],
         base_acceleration_limits: [0.5, 0.5, 0.5],
         stop_distance: 0.3, stop_time: 1.0}
arm_controller: {acceleration_limit: 5.0}
"""), arm)


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
    assert safety.check_vector([0.0, 1.0], switch=True).valid
    for bad in (0.7, 0.5, 3.0, -1.0, 1e-300):
        assert safety.check_vector([1.0, bad], switch=True) == (
            Reason.NOT_A_SWITCH, 1, bad)
    assert safety.check_vector([2.0], 0.0, 1.0, switch=True).reason is (
        Reason.OUT_OF_RANGE)
    # A range per entry: the second entry's is the narrower.
    assert safety.check_vector([5.0, 0.5], [-10.0, -1.0], [10.0, 1.0]).valid
    assert safety.check_vector([5.0, 2.0], [-10.0, -1.0],
                               [10.0, 1.0]) == (Reason.OUT_OF_RANGE, 1, 2.0)
    assert safety.check_inputs_float(
        [np.array([5.0, 2.0])], [((-10.0, -1.0), (10.0, 1.0), False)]) == (
        (Reason.OUT_OF_RANGE, 1, 2.0),)
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


# --- an arm that does not follow its commands ---------------------------

FOLLOW_TOLERANCE = safety.DEFAULT_ARM_FOLLOW_TOLERANCE
CAUGHT_UP_RAD = CAUGHT_UP * FOLLOW_TOLERANCE
"""rad: how near the arm a held command that caught up with it ends at
most (the fraction CAUGHT_UP of the follow tolerance; 2 to 17 mrad in
the runs here)."""
BRISK = [0.3, 0.2, 0.0, 0.0, 0.0, 0.3]


def command_now(rig):
    """The arm command the controller sends now (its last)."""
    return np.array(rig.diagram.GetOutputPort("arm.position_command").Eval(
        rig.context))


def moving_then_blind(rig):
    """`rig` after a second of the brisk reference, its odometry then a
    NaN (a safe stop from the next tick on, the arm moving)."""
    rig.set("reference_velocity", BRISK)
    rig.advance(1.0)
    bad = np.array(rig.valid["base.state_estimated"], dtype=float)
    bad[0] = np.nan
    rig.set("base.state_estimated", bad)
    return rig


def stopped_now(rig):
    return rig.diagram.GetOutputPort("safety_status").Eval(rig.context)[
        STATUS["stopped"]] == 1.0


def test_an_arm_held_still_trips_at_the_tick_it_falls_behind(arm):
    """The arm's measured position held still while the commands move
    away (its own protective stop, a hand holding it): the safe stop
    trips at the first tick at which a joint is farther than the
    tolerance from the last command, not before, and says which joint,
    how far and the tolerance. Nothing compared them before: the
    controller integrated on, away from where the arm was."""
    rig = Rig(arm)
    rig.set("reference_velocity", BRISK)
    rig.advance(1.0)
    held = command_now(rig)
    k_held = round(rig.time() / H)
    rig.set("arm.position_measured", held)
    while not stopped_now(rig):
        assert rig.time() < 3.0, "never tripped"
        rig.advance(H)
    k_trip = round(rig.time() / H) - 1  # the tick that decided
    times, q_cmd = rig.log("arm.position_command")
    _, status = rig.log("safety_status")
    assert times[k_trip] == pytest.approx(k_trip * H)
    deviation = held - q_cmd
    assert np.abs(deviation[k_held:k_trip]).max() <= FOLLOW_TOLERANCE
    assert np.all(status[k_held:k_trip + 1, STATUS["stopped"]] == 0.0)
    beyond = np.flatnonzero(np.abs(deviation[k_trip]) > FOLLOW_TOLERANCE)
    j = int(beyond[0])
    fault = status[k_trip + 1]
    assert fault[STATUS["stopped"]] == 1.0
    assert fault[STATUS["reason"]] == int(Reason.NOT_FOLLOWING)
    names = rig.controller.stages["guard"].input_names
    assert fault[STATUS["input"]] == names.index("arm.position_measured")
    assert fault[STATUS["entry"]] == j
    assert fault[STATUS["value"]] == deviation[k_trip, j]
    assert rig.controller.safety_reason(rig.root_context) == (
        f"arm.position_measured[{j}] is {abs(deviation[k_trip, j]):.3g} "
        f"rad from the last command (tolerance {FOLLOW_TOLERANCE:g} rad): "
        "the arm does not follow (its own stop, or held)")
    # Then the command goes back to where the arm is, within the
    # acceleration limit, and rests there while the stop holds.
    rig.advance(0.4)
    _, q_cmd = rig.log("arm.position_command")
    rates = np.diff(q_cmd[k_trip - 1:], axis=0) / H
    assert np.abs(np.diff(rates, axis=0)).max() / H <= (
        JOINT_ACCELERATION * (1 + 1e-6))
    np.testing.assert_array_equal(rates[-5:], 0.0)
    assert np.abs(q_cmd[-1] - held).max() <= CAUGHT_UP_RAD
    assert rig.controller.safety_reason(rig.root_context).endswith(
        f"; resuming from where it is after {HOLD:g} s")


def test_a_station_arm_that_stops_on_its_own_trips_and_is_resumed_where_it_is():
    """The simulated station's arm faults on the first command (the
    controller started 0.05 rad from it) and stays stopped, as a real
    arm's protective stop does. The controller, whose task moves on,
    trips once the arm is 0.1 rad behind (it integrated on for ever),
    its held command goes back to where the arm stands within the joint
    limits, and at each resume starts there: every step within the
    acceleration limit (a jump there in one tick faulted a servo that
    had not stopped)."""
    scenario = load_scenario(find_scenario("trajectory_tracking"))
    loop = build_closed_loop(scenario)
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    away = np.array(scenario.station.initial_arm_positions)
    away[0] += 0.05
    loop.controller.initialize(root, arm_position=away)
    simulator.AdvanceTo(3.0)
    log = loop.logger.run_log(root)
    assert fault_message(loop.station, root).startswith(
        "arm fault at t = 0.000 s")
    status = log["safety_status"]
    command, measured = log["arm.position_command"], log[
        "arm.position_measured"]
    names = loop.controller.stages["guard"].input_names
    trips = np.flatnonzero(np.diff(status[:, STATUS["trips"]]) > 0) + 1
    assert len(trips) >= 2
    for i in trips:
        assert status[i, STATUS["reason"]] == int(Reason.NOT_FOLLOWING)
        assert status[i, STATUS["input"]] == names.index(
            "arm.position_measured")
        assert abs(status[i, STATUS["value"]]) > FOLLOW_TOLERANCE
    resumes = np.flatnonzero(np.diff(status[:, STATUS["stopped"]]) < 0) + 1
    assert len(resumes) >= 1
    for i in resumes:
        # The tick before resumed, near the arm's position then.
        assert np.abs(command[i - 1] - measured[i - 1]).max() <= (
            CAUGHT_UP_RAD)
    rates = np.diff(command[1:], axis=0) / H  # from its first command
    assert np.abs(rates).max() <= JOINT_SPEED * (1 + 1e-9)
    assert np.abs(np.diff(rates, axis=0)).max() / H <= (
        JOINT_ACCELERATION * (1 + 1e-6))


def test_an_arm_pushed_off_its_command_against_a_wall_resumes_without_a_fault():
    """Trajectory tracking with a wall 3 cm past the tool: the arm, pushed
    0.1 rad off its command against it, trips the follow check; the held
    command goes to where the arm is within the joint limits, and the
    commands resume from there. The station's servo, which had not
    stopped, faulted on the resume (a 0.11 rad step in one tick: 11.5
    rad/s on joint 5) when the command was moved there at once."""
    path = find_scenario("trajectory_tracking")
    scenario = load_scenario(text=path.read_text() + (
        "\nscene: {boxes: [{name: wall, center: [1.016, 0.0, 1.0], "
        "size: [0.1, 4.0, 2.0]}]}\n"))
    loop = build_closed_loop(scenario)
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    simulator.AdvanceTo(3.0)
    log = loop.logger.run_log(root)
    assert fault_message(loop.station, root) == "none"
    status = log["safety_status"]
    assert status[-1, STATUS["trips"]] >= 1.0
    assert status[-1, STATUS["stopped"]] == 0.0   # resumed
    rates = np.diff(log["arm.position_command"], axis=0) / H
    assert np.abs(rates).max() <= JOINT_SPEED * (1 + 1e-9)
    assert np.abs(np.diff(rates, axis=0)).max() / H <= (
        JOINT_ACCELERATION * (1 + 1e-6))


def test_after_a_stop_in_which_the_arm_moved_the_commands_start_where_it_is(
        arm):
    """A safe stop (a NaN on the odometry) during which the arm is moved
    0.3 rad on three joints (by hand, or against something): the held
    command goes there within the joint speed and acceleration limits
    while the stop lasts, and the commands resume from where the arm
    stands, every step from the hold to the resume and on within the
    limits. They resumed from the command last sent, 0.3 rad away (a
    jump of the servo's setpoint), and later from the measured position
    in one tick (a step the servo of an arm pushed off its command
    refuses, 10 rad/s and more)."""
    rig = moving_then_blind(Rig(arm))
    rig.advance(0.2)                      # braked to rest and held
    held = command_now(rig)
    k_held = round(rig.time() / H)
    offset = np.array([0.3, -0.3, 0.0, 0.3, 0.0, 0.0])
    for k in range(1, 21):                # moved within 0.2 s
        rig.set("arm.position_measured", held + k / 20 * offset)
        rig.advance(H)
    moved = held + offset
    rig.set("base.state_estimated", rig.valid["base.state_estimated"])
    while stopped_now(rig):
        assert rig.time() < 3.0, "never resumed"
        rig.advance(H)
    k_resume = round(rig.time() / H) - 1  # the tick that resumed
    rig.follow()                          # the arm follows from there
    rig.advance(1.0)
    _, q_cmd = rig.log("arm.position_command")
    _, status = rig.log("safety_status")
    # Within a few mrad of the arm (the catch-up brakes once within the
    # tolerance, on the profile that stops on it).
    assert np.abs(q_cmd[k_resume] - moved).max() <= CAUGHT_UP_RAD
    rates = np.diff(q_cmd[k_held - 1:], axis=0) / H
    assert np.abs(rates).max() <= JOINT_SPEED * (1 + 1e-9)
    assert np.abs(np.diff(rates, axis=0)).max() / H <= (
        JOINT_ACCELERATION * (1 + 1e-6))
    assert np.abs(q_cmd[-1] - moved).max() > 1e-2      # moving again
    # One stop, the odometry's: the arm follows from where it is.
    assert status[-1, STATUS["trips"]] == 1.0
    assert np.all(status[k_resume + 1:, STATUS["stopped"]] == 0.0)


def test_a_protective_stop_that_outlasts_the_safe_stop_holds_where_the_arm_is(
        arm):
    """A safe stop during which the arm is moved 0.3 rad, while a point
    inside the footprint holds the robot in a protective stop too: the
    arm's command goes where the arm is and stays there, at rest, for as
    long as the protective stop lasts (a command left at the old
    position would trip the safe stop again at every tick it was
    checked)."""
    rig = moving_then_blind(Rig(arm))
    rig.set("lidar.obstacle_points", np.array([[0.35, 0.0], [2.0, 0.0]]))
    rig.advance(0.3)
    moved = command_now(rig) + np.array([0.0, 0.3, 0.0, 0.0, -0.3, 0.0])
    rig.set("arm.position_measured", moved)
    rig.set("base.state_estimated", rig.valid["base.state_estimated"])
    while stopped_now(rig):
        rig.advance(H)
    rig.follow()
    rig.advance(1.0)
    _, q_cmd = rig.log("arm.position_command")
    _, status = rig.log("safety_status")
    _, protective = rig.log("base_protective_stop")
    assert protective[-1, 0] == 1.0
    np.testing.assert_array_equal(q_cmd[-100:], np.tile(q_cmd[-1], (100, 1)))
    assert np.abs(q_cmd[-1] - moved).max() <= CAUGHT_UP_RAD
    assert status[-1, STATUS["trips"]] == 1.0
    assert status[-1, STATUS["stopped"]] == 0.0


def test_an_arm_within_the_tolerance_resumes_from_the_last_command(arm):
    """Moved by less than the tolerance during a stop, the arm resumes
    from the command last sent, exactly as a controller that never
    compared them (the rule's other side: nothing changes within it)."""
    runs = []
    for tolerance in (FOLLOW_TOLERANCE, 10.0):
        params = ControllerParameters()
        params.safety.arm_follow_tolerance = tolerance
        rig = moving_then_blind(Rig(arm, params))
        rig.advance(0.3)
        rig.set("arm.position_measured", command_now(rig) + 0.09)
        rig.set("base.state_estimated", rig.valid["base.state_estimated"])
        while stopped_now(rig):
            rig.advance(H)
        rig.follow()
        rig.advance(0.5)
        runs.append(rig.log("arm.position_command")[1])
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("name, variant, duration", [
    ("repeat_obstacle", "obstacle", 4.0),
    ("trajectory_tracking_lbr", "filtered", 4.0)])
def test_a_closed_loop_never_trips_on_the_arm_following(name, variant,
                                                        duration):
    """On the simulated station (a real MultibodyPlant and its servos),
    through a replay whose joints reach their speed limit of 1.57 rad/s
    and a line on the seven-joint arm: no safe stop, and the measured
    position stays within a quarter of the tolerance of the last
    command (0.023 rad at most, the servo's lag)."""
    scenario = load_scenario(find_scenario(name))
    chosen = next(v for v in scenario.variants if v.name == variant)
    log = simulate(build_closed_loop(scenario, chosen), duration=duration)
    assert np.all(log["safety_status"][:, STATUS["trips"]] == 0.0)
    command, measured = log["arm.position_command"], log[
        "arm.position_measured"]
    rates = np.abs(np.diff(command, axis=0)).max() / H
    deviation = np.abs(command - measured).max()
    assert 0.001 < deviation <= 0.25 * FOLLOW_TOLERANCE
    if name == "repeat_obstacle":
        assert rates >= JOINT_SPEED * (1 - 1e-6)


@pytest.mark.parametrize("value, message", [
    (0.0, "must be greater than 0"), (-0.1, "must be greater than 0"),
    (float("nan"), "must be finite"), (float("inf"), "must be finite"),
    ("0.1", "must be a single number")])
def test_the_follow_tolerance_is_checked_where_it_enters(value, message):
    with pytest.raises(ValueError, match=(
            rf"arm_follow_tolerance = .* is not allowed: {message}")):
        SafetyParameters(arm_follow_tolerance=value)
    with pytest.raises(ValueError, match=(
            r"safety.arm_follow_tolerance = -1.0 is not allowed: must be "
            r"greater than 0")):
        load_controller_parameters(text="safety: {arm_follow_tolerance: -1}")


@pytest.mark.parametrize("robot, tolerance", [
    (None, 0.1), ("lbr_omni.robot.yaml", 0.063 * 3.1416),
    ("ur_omni.robot.yaml", 0.063 * np.pi)])
def test_each_arm_is_held_to_its_own_follow_tolerance(robot, tolerance):
    """The arm-follow tolerance was 0.1 rad on every arm, the Elfin5's:
    a UR-class or seven-joint arm's joint at its full 3.14 rad/s lags its
    command by up to 0.14 rad over LCM (the servo's lag and a status at
    its watchdog's age), which stopped the robot though the arm followed.
    Now a robot that gives none has its arm's own (what its fastest
    joint travels in 63 ms, at least 0.1 rad), the same on the
    controller's guard and on the hardware interface's."""
    from pydrake.lcm import DrakeLcm

    from drake_wbc.hardware.interface import HardwareInterface
    from drake_wbc.robot.description import models_dir

    arm = arm_kinematics(None if robot is None else load_robot_description(
        models_dir() / robot))
    controller = build_controller(ControllerParameters(), arm)
    assert controller.params.safety.arm_follow_tolerance == pytest.approx(
        tolerance, rel=1e-12)
    assert controller.stages["arm_controller"].resume_tolerance == (
        controller.params.safety.arm_follow_tolerance)
    hardware = HardwareInterface(lcm=DrakeLcm("memq://"), robot=arm)
    assert hardware.systems["guard"].config.arm_follow_tolerance == (
        controller.params.safety.arm_follow_tolerance)
