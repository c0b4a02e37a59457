"""The simulated arm refuses what the real arm refuses: a position command
beyond a joint's position, speed or acceleration limit faults it, and it
brakes to rest within its acceleration limits and stays stopped
(drake_wbc.station.arm_supervisor, drake_wbc.math.arm_servo); a stream
within the limits, up to rounding, passes. The closed forms: from a rate
of k a h the stop's rates are (k - 1) a h, ..., a h, 0, and it comes to
rest a h^2 k (k - 1) / 2 further on."""

import logging

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from drake_wbc.controller.run_log import RunLog
from drake_wbc.experiments.common import run_metrics
from drake_wbc.experiments.runner import (
    build_closed_loop,
    fault_message,
    simulate,
    start_simulator,
)
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.math.arm_servo import (
    ArmLimitViolation,
    arm_command_violation,
    brake_arm,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.station.arm_supervisor import ArmFault
from drake_wbc.station.simulation import SimulatedStation, StationOptions
from drake_wbc.stress.cases import case_record, violations

H = 0.01  # the arm's command period, s
ARM = ArmKinematics()
SPEED, ACCELERATION = ARM.velocity_limits, ARM.acceleration_limits
LOWER, UPPER = ARM.lower, ARM.upper
HOME = np.array(ARM.home)


def violation(command, last=HOME, velocity=None):
    velocity = np.zeros(6) if velocity is None else velocity
    return arm_command_violation(command, last, velocity, H, LOWER, UPPER,
                                 SPEED, ACCELERATION)


def along(joint, value):
    e = np.zeros(6)
    e[joint] = value
    return e


@pytest.mark.parametrize("joint", range(6))
def test_a_command_at_each_limit_up_to_rounding_is_within_it(joint):
    a, v = ACCELERATION[joint], SPEED[joint]
    for scale, within in ((1.0 + 0.5e-9, True), (1.0 + 2e-9, False)):
        # Position: on the upper limit, the last command at rest on it.
        at = HOME.copy()
        at[joint] = UPPER[joint]
        beyond = violation(at + along(joint, (scale - 1.0) * UPPER[joint]),
                           last=at)
        assert (beyond is None) == within
        if not within:
            assert beyond == (joint, "position", pytest.approx(
                UPPER[joint] * scale, rel=1e-15), UPPER[joint])
        # Speed: at the speed limit from it (no change of rate).
        found = violation(HOME + along(joint, v * H * scale),
                          velocity=along(joint, v))
        assert (found is None) == within
        if not within:
            assert found.kind == "speed" and found.joint == joint
            assert found.value == pytest.approx(v * scale, rel=1e-12)
            assert found.limit == v
        # Acceleration: a h^2 from rest.
        found = violation(HOME + along(joint, a * H * H * scale))
        assert (found is None) == within
        if not within:
            assert found.kind == "acceleration" and found.joint == joint
            assert found.value == pytest.approx(a * scale, rel=1e-9)
            assert found.limit == a


def test_the_first_limit_broken_is_reported_in_order():
    """Position before speed before acceleration, the first joint first;
    a command that is not a number is beyond its position limits."""
    jump = HOME + along(4, 1.0) + along(2, 0.5)
    assert violation(jump)[:2] == (2, "speed")
    found = violation(jump + along(5, 10.0))
    assert found[:2] == (5, "position") and found.limit == UPPER[5]
    found = violation(HOME + along(3, np.nan) + along(1, -5.0))
    assert found[:2] == (1, "position") and found.limit == LOWER[1]
    found = violation(HOME + along(3, np.nan))
    assert found[:2] == (3, "position") and np.isnan(found.value)
    assert violation(HOME) is None


def test_the_stop_slows_at_the_acceleration_limit_and_holds():
    a, k = ACCELERATION, 7
    q, v = HOME.copy(), k * a * H
    rates = []
    for _ in range(k + 3):
        q, v = brake_arm(q, v, H, a, LOWER, UPPER)
        rates.append(v)
    expected = [max(k - 1 - j, 0) * a * H for j in range(k + 3)]
    np.testing.assert_allclose(rates, expected, atol=1e-12)
    np.testing.assert_allclose(q - HOME, a * H * H * k * (k - 1) / 2,
                               rtol=1e-12)


def test_the_fault_says_which_joint_broke_which_limit():
    stop = ("; the arm brakes to rest within its acceleration limits and "
            "stays stopped")
    for violation, what in (
            (ArmLimitViolation(1, "position", -2.5, -2.35),
             "joint 2 (j2)'s command -2.5 rad is beyond its lower limit "
             "-2.35 rad"),
            (ArmLimitViolation(3, "position", np.nan, 3.14),
             "joint 4 (j4)'s command is not a number")):
        name = f"j{violation.joint + 1}"
        assert ArmFault(1.5, violation, name).message() == (
            f"arm fault at t = 1.500 s: {what}{stop}")


@pytest.fixture(scope="module")
def station():
    return SimulatedStation(StationOptions(time_step=0.005))


def drive(station, commands, duration, initial=None):
    """The station from rest (the arm at `initial`, its home if None),
    its arm sent commands[k] at its servo's k-th sample (every H from 0,
    the last one held after). Returns a dict of arrays, one row a sample
    time k H (before that sample): time, q and v (the arm's measured
    joints), fault, v_d (the servo's desired rates)."""
    if initial is not None:
        station = SimulatedStation(StationOptions(
            time_step=0.005, initial_arm_positions=list(initial)))
    simulator = Simulator(station.diagram)
    root = simulator.get_mutable_context()
    station.set_initial_state(root)
    diagram = station.diagram
    diagram.GetInputPort("base.velocity_command").FixValue(root, np.zeros(3))
    driver = station.systems["arm_driver"]
    rows = {name: [] for name in ("time", "q", "v", "fault", "v_d")}
    command = diagram.GetInputPort("arm.position_command")
    command.FixValue(root, commands[0])
    for k in range(int(round(duration / H)) + 1):
        # The sample at k H is taken at the start of the AdvanceTo from
        # k H (from 0: the first one).
        simulator.AdvanceTo(k * H)
        rows["time"].append(k * H)
        rows["q"].append(diagram.GetOutputPort(
            "arm.position_measured").Eval(root).copy())
        rows["v"].append(diagram.GetOutputPort(
            "arm.velocity_estimated").Eval(root).copy())
        rows["fault"].append(diagram.GetOutputPort("arm.fault").Eval(
            root)[0])
        rows["v_d"].append(driver.get_output_port().Eval(
            driver.GetMyContextFromRoot(root))[6:].copy())
        command.FixValue(root, commands[min(k, len(commands) - 1)])
    rows = {name: np.array(value) for name, value in rows.items()}
    rows["station"], rows["simulator"] = station, simulator
    return rows


def station_warnings(caplog):
    return [r.getMessage() for r in caplog.records
            if r.name == "drake_wbc.station"]


def test_a_step_beyond_the_speed_limit_faults_and_the_arm_brakes(
        station, caplog):
    """Joint 1 speeds up at its acceleration limit for ten samples (to
    1.256 rad/s), then the command jumps 0.05 rad (5 rad/s): the arm
    faults at that sample, t = 0.11 s, its servo's rates fall by a h a
    period to rest, the arm stops a h^2 45 further on and stays there,
    whatever it is sent after."""
    a = ACCELERATION[0]
    ramp = [HOME + along(0, a * H * H * j * (j + 1) / 2) for j in range(11)]
    jump = ramp[-1] + along(0, 0.05)
    later = [jump, HOME, HOME + 1.0]  # refused: the arm stays stopped
    with caplog.at_level(logging.WARNING, logger="drake_wbc.station"):
        run = drive(station, ramp + later, 1.0)
    t, fault = run["time"], run["fault"]
    assert np.all(fault[t <= 0.11 + 1e-9] == 0.0)
    assert np.all(fault[t > 0.11 + 1e-9] == 1.0)
    record = run["station"].arm_fault(run["simulator"].get_context())
    assert record.time == pytest.approx(0.11)
    assert record.violation == (0, "speed", pytest.approx(5.0), 1.57)
    messages = station_warnings(caplog)
    assert messages == [
        "arm fault at t = 0.110 s: joint 1 (elfin5::joint1)'s command "
        "moves at 5 rad/s, beyond its 1.57 rad/s limit; the arm brakes to "
        "rest within its acceleration limits and stays stopped"]
    # The servo's rates after the fault: 9 a h, 8 a h, ..., a h, 0 (a
    # row holds the sample before its time).
    after = (t > 0.11 + 1e-9) & (t <= 0.21 + 1e-9)
    np.testing.assert_allclose(run["v_d"][after, 0],
                               a * H * np.arange(9, -1, -1), atol=1e-9)
    # At rest from 0.21 s on, a h^2 45 further on: the servo's command
    # stays there; the arm comes to rest on it, but for the mount's
    # rocking that the stop set off (5 Hz, damping ratio 0.05: a few
    # tenths of a milliradian, dying out).
    rest = ramp[-1][0] + a * H * H * 45
    settled = t >= 0.4 - 1e-9
    np.testing.assert_allclose(run["v_d"][settled], 0.0, atol=1e-12)
    np.testing.assert_allclose(run["q"][settled, 0], rest, atol=1e-3)
    assert np.max(np.abs(run["v"][settled])) < 0.02
    assert np.max(np.abs(run["v"][t >= 0.9 - 1e-9])) < 2e-3


def test_a_step_beyond_the_acceleration_limit_faults_and_the_arm_holds(
        station, caplog):
    """From rest, joint 3 is sent 2 m rad (0.2 rad/s, within its speed
    limit, but from rest in one period: 20 rad/s^2): a fault at 0.01 s;
    at rest, the arm stays where it was, whatever it is sent after."""
    step = HOME + along(2, 2e-3)
    ramp = [step + along(2, 1e-3 * j) for j in range(1, 50)]
    with caplog.at_level(logging.WARNING, logger="drake_wbc.station"):
        run = drive(station, [HOME, step] + ramp, 0.5)
    assert station_warnings(caplog) == [
        "arm fault at t = 0.010 s: joint 3 (elfin5::joint3)'s command "
        "changes its rate at 20 rad/s^2, beyond its 12.56 rad/s^2 limit; "
        "the arm brakes to rest within its acceleration limits and stays "
        "stopped"]
    assert run["fault"][0] == run["fault"][1] == 0.0
    assert np.all(run["fault"][2:] == 1.0)
    np.testing.assert_allclose(run["v_d"], 0.0, atol=1e-12)
    np.testing.assert_allclose(run["q"] - run["q"][0], 0.0, atol=1e-6)


def test_a_command_beyond_a_position_limit_faults_the_arm(caplog):
    """Joint 1 starts 0.1 mrad inside its upper limit; a command 0.1 mrad
    beyond it is within the speed and acceleration limits (0.02 rad/s, 2
    rad/s^2) but not the position limit: a fault, and the arm stays."""
    start = HOME.copy()
    start[0] = UPPER[0] - 1e-4
    beyond = start + along(0, 2e-4)
    with caplog.at_level(logging.WARNING, logger="drake_wbc.station"):
        run = drive(None, [start, beyond], 0.3, initial=start)
    assert station_warnings(caplog) == [
        "arm fault at t = 0.010 s: joint 1 (elfin5::joint1)'s command "
        "3.1401 rad is beyond its upper limit 3.14 rad; the arm brakes to "
        "rest within its acceleration limits and stays stopped"]
    assert np.all(run["fault"][2:] == 1.0)
    np.testing.assert_allclose(run["q"][:, 0], start[0], atol=1e-6)


def at_the_limits(joint, distance_sign):
    """The rates of a move of `joint` at its speed and acceleration limits:
    up at a h a period to the speed limit, 10 periods at it, and down
    again to rest; and the move's length. `distance_sign` its
    direction."""
    a, v = ACCELERATION[joint], SPEED[joint]
    up = [min(j * a * H, v) for j in range(1, int(np.ceil(v / (a * H))) + 1)]
    rates = np.array(up + [v] * 10 + up[::-1] + [0.0]) * distance_sign
    return rates, H * float(np.sum(rates))


def test_a_stream_at_the_limits_does_not_fault(caplog):
    """Joint 1 moves onto its upper limit and joint 6 onto its lower one,
    each at its speed and acceleration limits all the way: no fault, and
    the arm ends on the limits."""
    rates_1, length_1 = at_the_limits(0, 1.0)
    rates_6, length_6 = at_the_limits(5, -1.0)
    start = HOME.copy()
    start[0], start[5] = UPPER[0] - length_1, LOWER[5] - length_6
    commands = [start]
    for j in range(len(rates_1)):
        q = commands[-1] + H * along(0, rates_1[j]) + H * along(5, rates_6[j])
        commands.append(q)
    # The last one on the limits exactly (its rate off by rounding alone).
    commands[-1][0], commands[-1][5] = UPPER[0], LOWER[5]
    with caplog.at_level(logging.WARNING, logger="drake_wbc.station"):
        run = drive(None, commands, len(commands) * H + 0.2, initial=start)
    assert station_warnings(caplog) == []
    assert np.all(run["fault"] == 0.0)
    assert np.max(np.abs(run["v_d"][:, 0])) == pytest.approx(SPEED[0])
    np.testing.assert_allclose(run["q"][-1, [0, 5]], [UPPER[0], LOWER[5]],
                               atol=1e-3)


def test_a_run_that_faults_the_arm_says_so_in_its_summary(tmp_path):
    """A controller started 0.05 rad away from the station's arm sends a
    first command that jumps there: the arm faults at t = 0, and the
    run's log, its summary's metrics and the stress check say so; a run
    started where the arm is does not fault."""
    scenario = load_scenario(find_scenario("trajectory_tracking"))
    clean = simulate(build_closed_loop(scenario), duration=0.2)
    assert clean.arm_fault == "none"
    assert run_metrics(scenario, clean)["arm_fault"] == "none"

    loop = build_closed_loop(scenario)
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    away = np.array(scenario.station.initial_arm_positions) + along(0, 0.05)
    loop.controller.initialize(root, arm_position=away)
    simulator.AdvanceTo(0.2)
    log = loop.logger.run_log(root, arm_fault=fault_message(loop.station,
                                                            root))
    assert log.arm_fault.startswith(
        "arm fault at t = 0.000 s: joint 1 (elfin5::joint1)'s command "
        "moves at 5 rad/s, beyond its 1.57 rad/s limit")
    assert run_metrics(scenario, log)["arm_fault"] == log.arm_fault
    assert RunLog.load(log.save(tmp_path / "log")).arm_fault == log.arm_fault
    # (the jump breaks the stress check's own speed limit of the logged
    # commands too)
    found = violations(case_record(0, 0, scenario, log))
    assert f"the arm faulted: {log.arm_fault}" in found
    assert f"the arm faulted: {log.arm_fault}" not in violations(
        case_record(0, 0, scenario, clean))
