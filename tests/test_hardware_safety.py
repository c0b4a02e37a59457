"""The hardware interface's safety, with real LCM (memq://) and the test
playing the robot: every stream has its watchdog, and a stale one stops
what depends on it, within its limit and a millisecond; the commands
resume only after the streams have been fresh for the recovery time, and
within the acceleration limits; bad messages never reach the
controller's inputs, and no time stamp and no flood locks anything out;
every command sent is within the robot's limits."""

import logging
import re
from dataclasses import replace

import numpy as np
import pytest
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_wbc.deployment.deploy import STOP_REPEATS, deploy, send_stop
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.hardware import codecs, messages
from drake_wbc.hardware.interface import DIAGNOSTICS, HardwareInterface
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.hardware.safety import (
    ArmCommandLimiter,
    CommandGuard,
    Limits,
    WallClock,
    follow_arm_command,
    saturate_base_velocity,
    stop_arm,
    target_rate,
)
from drake_wbc.math.arm_servo import brake_speed
from drake_wbc.robot.model import HOME_ARM_POSITIONS

H = 0.01
BASE_COMMAND = np.array([0.3, -0.1, 0.2])
WRENCH = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
POINTS = np.array([[1.0, 0.5], [2.0, -0.5]])
LIDAR_TICKS = 6
"""The test's LIDAR sends every 6 control periods (16.7 Hz)."""


class Bench:
    """The interface in a Diagram, with constant controller commands that
    a test can change, and the test in the robot's place on LCM."""

    def __init__(self, wall_clock=None, **options):
        self.options = HardwareOptions(lcm_url="memq://", **options)
        self.lcm = DrakeLcm("memq://")
        builder = DiagramBuilder()
        self.hw = HardwareInterface(self.options, self.lcm, HOME_ARM_POSITIONS,
                                    wall_clock=wall_clock)
        builder.AddSystem(self.hw.diagram)
        self.base = builder.AddSystem(ConstantVectorSource(BASE_COMMAND))
        self.arm = builder.AddSystem(ConstantVectorSource(HOME_ARM_POSITIONS))
        builder.Connect(self.base.get_output_port(),
                        self.hw.diagram.GetInputPort("base.velocity_command"))
        builder.Connect(self.arm.get_output_port(),
                        self.hw.diagram.GetInputPort("arm.position_command"))
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.root = self.simulator.get_mutable_context()
        self.sent = {"base": [], "arm": []}
        channels = self.options.channels
        self.lcm.Subscribe(channels.base_command, lambda data: self.sent[
            "base"].append((self.root.get_time(),
                            messages.decode_base_command(data).values[0])))
        self.lcm.Subscribe(channels.arm_command, lambda data: self.sent[
            "arm"].append((self.root.get_time(),
                           messages.decode_arm_command(data).values[0])))
        self.simulator.Initialize()
        self.tick = 0
        self.utime_offset = 0

    def publish(self, channel, data):
        self.lcm.Publish(getattr(self.options.channels, channel), data)

    def utime(self):
        return int(round(self.tick * H * 1e6)) + self.utime_offset

    def status(self, streams=("base_state", "arm_status", "wrist_wrench",
                              "obstacle_points"), q=HOME_ARM_POSITIONS):
        """The robot's messages of this period (the LIDAR's every
        LIDAR_TICKS periods)."""
        utime = self.utime()
        if "base_state" in streams:
            self.publish("base_state", messages.encode_base_state(
                utime, [0.0, 0.0, 0.0, 0.1, 0.0, 0.0]))
        if "arm_status" in streams:
            self.publish("arm_status", messages.encode_arm_status(
                utime, q, np.zeros(6)))
        if "wrist_wrench" in streams:
            self.publish("wrist_wrench", messages.encode_wrench(utime,
                                                                WRENCH))
        if "obstacle_points" in streams and self.tick % LIDAR_TICKS == 0:
            self.publish("obstacle_points", messages.encode_obstacle_points(
                utime, POINTS))

    def run(self, ticks, status=True, extra=None, phase=0.0):
        """`ticks` control periods, the robot sending its status (`status`
        True for all streams, or the streams to send) `phase` s after the
        start of each one (and `extra(bench)` if given)."""
        for _ in range(ticks):
            if phase:
                self.simulator.AdvanceTo(self.tick * H + phase)
            if status is True:
                self.status()
            elif status:
                self.status(status)
            if extra is not None:
                extra(self)
            self.tick += 1
            self.simulator.AdvanceTo(self.tick * H)

    def output(self, name):
        return self.hw.diagram.GetOutputPort(name).Eval(
            self.hw.diagram.GetMyContextFromRoot(self.root))

    def diagnostics(self):
        return dict(zip(DIAGNOSTICS, self.output("hardware.diagnostics"),
                        strict=True))

    def set_command(self, source, value):
        context = source.GetMyMutableContextFromRoot(self.root)
        source.get_mutable_source_value(context).SetFromVector(value)

    def commands(self, name, after=-1.0):
        """(times, values) of the commands sent after `after` s."""
        rows = [(t, v) for t, v in self.sent[name] if t > after]
        times, values = zip(*rows, strict=True)
        return np.array(times), np.array(values)


def _rows_equal(rows, value):
    assert len(rows) > 0
    np.testing.assert_allclose(rows, np.broadcast_to(value, rows.shape))


def _records(caplog, words):
    return [r for r in caplog.records
            if r.name == "drake_wbc.hardware" and words in r.getMessage()]


def _steps(values):
    """The largest change of the rows of `values` from one to the next."""
    return np.max(np.abs(np.diff(values, axis=0)), axis=0)


def test_watchdog_stops_the_commands_and_lets_them_resume(caplog):
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    bench = Bench()
    limit = bench.options.watchdog_limits.base_state
    recovery = bench.options.watchdog_recovery_time
    bench.run(60)
    last_status = (bench.tick - 1) * H
    times, base = bench.commands("base")
    # The base's command rises from rest within its acceleration limits.
    assert np.all(_steps(base) <= 1.0 * H + 1e-10)
    _rows_equal(base[times > 0.45], BASE_COMMAND)
    assert bench.diagnostics()["watchdog_tripped"] == 0.0
    arm_before = bench.sent["arm"][-1][1]

    bench.run(10, status=False)  # the robot falls silent for 0.1 s
    times, base = bench.commands("base", last_status)
    # Commands sent while the status is not yet too old go on; from the
    # first check after the limit (1 ms) the base gets zero.
    young = times <= last_status + limit
    old = times > last_status + limit + 2 * bench.options.watchdog_period
    assert young.any() and old.any()
    _rows_equal(base[young], BASE_COMMAND)
    np.testing.assert_array_equal(base[old], 0.0)
    for t, q in bench.sent["arm"]:
        if t > last_status + limit + H:
            np.testing.assert_array_equal(q, arm_before)  # held
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_tripped"] == 1.0
    assert diagnostics["watchdog_trips"] == 1.0
    assert diagnostics["base_state_age"] > limit
    assert len(_records(caplog, "watchdog tripped")) == 1

    resumed = bench.tick * H
    bench.run(100)
    times, base = bench.commands("base", resumed)
    # Zero until every stream has been fresh for the recovery time, then
    # back to the controller's command within the acceleration limits.
    np.testing.assert_array_equal(base[times < resumed + recovery], 0.0)
    assert np.all(_steps(base) <= 1.0 * H + 1e-10)
    _rows_equal(base[times > resumed + recovery + 0.35], BASE_COMMAND)
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_tripped"] == 0.0
    assert diagnostics["watchdog_trips"] == 1.0
    assert len(_records(caplog, "watchdog cleared")) == 1
    assert len(_records(caplog, "watchdog tripped")) == 1


def test_the_watchdog_stops_the_base_within_its_limit_and_a_millisecond():
    """The watchdog's latency, from the last status (received between two
    control ticks, as a robot's clock is not the controller's) to the
    first zero base command on the wire: the limit, one check (1 ms) to
    see it and one to send it. Checked at each control tick, it took up
    to a control period more."""
    bench = Bench()
    limit = bench.options.watchdog_limits.base_state
    check = bench.options.watchdog_period
    latencies = []
    for phase in (0.0005, 0.0035, 0.0065, 0.0095):
        bench.run(60, phase=phase)
        last_status = (bench.tick - 1) * H + phase
        bench.run(8, status=("obstacle_points",))
        times, base = bench.commands("base", last_status)
        stopped = times[np.all(base == 0.0, axis=1)]
        latencies.append(stopped[0] - last_status)
        assert np.all(np.any(base[times < stopped[0]] != 0.0, axis=1))
        bench.run(120, phase=phase)  # recover
    print(f"watchdog latency {np.array(latencies) * 1e3} ms")
    assert max(latencies) <= limit + 2 * check + 1e-9


def test_a_stale_obstacle_stream_stops_the_base_and_not_the_arm(caplog):
    """No base motion without fresh obstacle points: when the LIDAR
    stream stops (or freezes), the base stops within its limit, while the
    arm follows the controller; the base resumes once the points have been
    fresh again for the recovery time."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    bench = Bench()
    limit = bench.options.watchdog_limits.obstacle_points
    bench.run(60)
    last_points = (bench.tick - 1 - (bench.tick - 1) % LIDAR_TICKS) * H
    target = HOME_ARM_POSITIONS + 0.05
    bench.set_command(bench.arm, target)
    bench.run(40, status=("base_state", "arm_status", "wrist_wrench"))
    times, base = bench.commands("base", last_points)
    np.testing.assert_array_equal(base[times > last_points + limit + 0.002],
                                  0.0)
    assert np.all(base[times < last_points + limit] != 0.0)
    # The arm went on to its new command.
    np.testing.assert_allclose(bench.sent["arm"][-1][1], target)
    diagnostics = bench.diagnostics()
    assert (diagnostics["base_stopped"], diagnostics["base_stops"]) == (1, 1)
    assert diagnostics["watchdog_tripped"] == 0.0
    assert len(_records(caplog, "base stopped")) == 1
    bench.run(120)
    times, base = bench.commands("base", bench.tick * H - 0.3)
    _rows_equal(base[-5:], BASE_COMMAND)
    assert bench.diagnostics()["base_stopped"] == 0.0
    assert len(_records(caplog, "base cleared")) == 1


def test_a_stale_wrench_stops_everything():
    """No force control, pHRI or compliance without a fresh wrench: a
    stale wrist wrench stops the base and the arm as a stale arm status
    does."""
    bench = Bench()
    bench.run(60)
    target = HOME_ARM_POSITIONS + 0.2
    bench.set_command(bench.arm, target)
    bench.run(20, status=("base_state", "arm_status", "obstacle_points"))
    assert bench.diagnostics()["watchdog_tripped"] == 1.0
    np.testing.assert_array_equal(bench.sent["base"][-1][1], 0.0)
    # The arm, on its way to the new command, stopped short of it within
    # its limits, and holds.
    times, arm = bench.commands("arm", bench.tick * H - 0.05)
    _rows_equal(arm, arm[0])
    assert np.all(arm[0] < target)


def test_commands_resume_within_the_acceleration_limits():
    """After a trip the commands start from what was sent last, not from
    what the controller asked for meanwhile: the base's within its 1 m/s^2,
    the joints' within 1.57 rad/s and 12.56 rad/s^2."""
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(60)
    bench.run(10, status=False)
    target = HOME_ARM_POSITIONS + np.array([0.5, -0.3, 0.2, 0.0, 0.1, -0.4])
    bench.set_command(bench.arm, target)
    bench.set_command(bench.base, [0.8, 0.0, -0.5])
    stopped = bench.tick * H
    bench.run(150)
    times, base = bench.commands("base", stopped)
    assert np.all(_steps(base) <= limits.base_acceleration * H + 1e-10)
    times, arm = bench.commands("arm", stopped)
    rate = np.diff(arm, axis=0) / H
    assert np.all(np.abs(rate) <= limits.joint_speed + 1e-9)
    assert np.all(np.abs(np.diff(rate, axis=0))
                  <= limits.joint_acceleration * H + 1e-9)
    np.testing.assert_allclose(arm[-1], target)  # and it got there
    np.testing.assert_allclose(base[-1], [0.8, 0.0, -0.5])
    print(f"largest steps: base {_steps(base)} m/s, joints "
          f"{np.max(np.abs(np.diff(rate, axis=0)), axis=0) / H} rad/s^2")


MOVED = HOME_ARM_POSITIONS + np.array([0.3, -0.3, 0.0, 0.3, 0.0, 0.0])
"""Where the arm was moved during a stop (by hand, or by its own stop)."""


def _assert_from_rest_at(arm, start, limits):
    """Every arm command of `arm` (rows), as the arm standing at rest at
    `start` sees them, within the joint speed and acceleration limits."""
    seen = np.vstack([start, start, arm])
    rate = np.diff(seen, axis=0) / H
    assert np.all(np.abs(rate) <= limits.joint_speed * (1 + 1e-9))
    assert np.all(np.abs(np.diff(rate, axis=0))
                  <= limits.joint_acceleration * H * (1 + 1e-9))


def test_after_a_stop_the_arm_is_commanded_from_where_it_is(caplog):
    """A stale stream stops everything; meanwhile the arm is moved 0.3 rad
    (on three joints) and reports it. When the stop clears, the guard
    sends where the arm is, at rest, not what it sent last, and holds it
    there while the controller's command (still the old one: the
    controller is in its own safe stop) is farther than the tolerance
    from it; once the controller resumes from there, it follows within
    the limits. It resumed from what it sent last: a jump of 0.3 rad of
    the servo's setpoint, and then drove the arm back to the old
    command."""
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(60)
    bench.run(10, status=False)
    assert bench.diagnostics()["watchdog_tripped"] == 1.0
    stopped = bench.tick * H

    def moved(bench):
        bench.status(q=MOVED)

    with caplog.at_level(logging.WARNING, logger="drake_wbc.hardware"):
        bench.run(80, status=False, extra=moved)
    assert bench.diagnostics()["watchdog_tripped"] == 0.0
    assert len(_records(caplog, "arm elsewhere at t = ")) == 1
    assert "joint 0 is 0.3 rad from the last command sent (tolerance " \
        "0.1 rad)" in caplog.text
    resumed = bench.tick * H
    bench.set_command(bench.arm, MOVED)      # the controller resumes there
    bench.run(10, status=False, extra=moved)
    goal = MOVED + np.array([0.0, 0.0, 0.2, 0.0, -0.1, 0.0])
    bench.set_command(bench.arm, goal)
    bench.run(60, status=False, extra=moved)
    times, arm = bench.commands("arm", stopped)
    away = np.flatnonzero(np.abs(arm - HOME_ARM_POSITIONS).max(axis=1) > 0)
    first = int(away[0])
    np.testing.assert_array_equal(arm[first], MOVED)
    assert times[first] < resumed          # held there before it resumed
    _assert_from_rest_at(arm[first:], MOVED, limits)
    np.testing.assert_allclose(arm[-1], goal)


@pytest.mark.parametrize("beyond", [0.03, 0.2])
def test_an_arm_read_beyond_its_limits_after_a_stop_is_no_restart(
        caplog, beyond):
    """After a stop the arm reads 0.03 rad (or 0.2) beyond joint 0's
    upper limit (3.14): the guard restarted from there held within the
    limits, 3.14 sent after 0.0 (314 rad/s), a jump of the setpoint away
    from the arm too. At the start the same reading is refused
    (start_within_limits); at a restart the guard now keeps its own last
    command and its limits, so nothing jumps, and says so once, naming
    the joint, its reading and its limits. A reading within one period's
    step at the acceleration limit from rest (an encoder at its limit)
    restarts on the limit, as before."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(60)
    bench.run(10, status=False)
    assert bench.diagnostics()["watchdog_tripped"] == 1.0
    before = bench.sent["arm"][-1][1]
    stopped = bench.tick * H
    q = HOME_ARM_POSITIONS.copy()
    q[0] = limits.upper[0] + beyond
    bench.run(80, status=False, extra=lambda bench: bench.status(q=q))
    assert bench.diagnostics()["watchdog_tripped"] == 0.0
    _, arm = bench.commands("arm", stopped)
    rate = np.diff(np.vstack([before, before, arm]), axis=0) / H
    assert np.all(np.abs(rate) <= limits.joint_speed * (1 + 1e-9))
    assert np.all(np.abs(np.diff(rate, axis=0))
                  <= limits.joint_acceleration * H * (1 + 1e-9))
    np.testing.assert_array_equal(arm[-1], HOME_ARM_POSITIONS)
    assert not _records(caplog, "arm elsewhere")
    records = _records(caplog, "arm beyond its limits at t = ")
    assert len(records) == 1
    assert (f"joint 0 reads {q[0]:.6g} rad, beyond its limits "
            "[-3.14, 3.14] rad by more than 0.00126 rad"
            in records[0].getMessage())
    # An encoder's noise at the limit: the restart is on the limit.
    caplog.clear()
    bench.run(10, status=False)
    q[0] = limits.upper[0] + 0.5 * limits.joint_acceleration[0] * H * H
    bench.run(80, status=False, extra=lambda bench: bench.status(q=q))
    assert len(_records(caplog, "arm elsewhere at t = ")) == 1
    assert not _records(caplog, "arm beyond its limits")
    assert bench.sent["arm"][-1][1][0] == limits.upper[0]


def test_a_controller_resuming_where_the_arm_is_is_followed_from_there():
    """No stop of the guard's: the controller, in its own safe stop, held
    its command while the arm was moved 0.3 rad, and then restarts from
    where the arm is, a step of its command of 0.3 rad. The guard sends
    from where the arm is, at rest, within the limits; it followed from
    what it sent last, towards the arm, sending the old position
    first."""
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(60)

    def moved(bench):
        bench.status(q=MOVED)

    bench.run(30, status=False, extra=moved)
    times, arm = bench.commands("arm")
    np.testing.assert_array_equal(arm[-1], HOME_ARM_POSITIONS)
    resumed = bench.tick * H
    goal = MOVED + np.array([0.0, 0.0, 0.2, 0.0, -0.1, 0.0])
    bench.set_command(bench.arm, MOVED + 0.01 * (goal - MOVED))
    bench.run(1, status=False, extra=moved)
    bench.set_command(bench.arm, goal)
    bench.run(60, status=False, extra=moved)
    _, arm = bench.commands("arm", resumed)
    _assert_from_rest_at(arm, MOVED, limits)
    np.testing.assert_allclose(arm[-1], goal)
    # An arm where the last command sent was: a step of the controller's
    # command is followed from there, as ever (here to the arm's 0.3 rad
    # away).
    bench = Bench()
    bench.run(60)
    bench.set_command(bench.arm, MOVED)
    bench.run(5)
    _, arm = bench.commands("arm", 0.6 - 1e-9)
    step = np.abs(arm[0] - HOME_ARM_POSITIONS).max()
    assert 0.0 < step <= limits.joint_acceleration[0] * H * H * (1 + 1e-9)


@pytest.mark.parametrize("tolerance, message", [
    (0.0, "must be greater than 0"), (float("inf"), "must be finite")])
def test_the_guards_arm_tolerance_is_checked(tolerance, message):
    with pytest.raises(ValueError, match=(
            f"arm_follow_tolerance = {tolerance} is not allowed: {message}")):
        HardwareInterface(HardwareOptions(lcm_url="memq://"),
                          DrakeLcm("memq://"), arm_follow_tolerance=tolerance)


def test_a_trip_clears_only_after_the_recovery_time():
    """A status that comes and goes (here one good message every 40 ms)
    stops the robot once, not at every gap, and the commands resume
    only once it has been fresh for the recovery time."""
    bench = Bench()
    bench.run(60)
    for _ in range(20):
        bench.run(1)
        bench.run(3, status=("obstacle_points",))
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_trips"] == 1.0
    assert diagnostics["watchdog_tripped"] == 1.0
    times, base = bench.commands("base", 0.64)
    np.testing.assert_array_equal(base, 0.0)
    bench.run(49)
    assert bench.diagnostics()["watchdog_tripped"] == 1.0
    bench.run(3)
    assert bench.diagnostics()["watchdog_tripped"] == 0.0


def test_bad_messages_never_reach_the_controller():
    bench = Bench()
    q_good = HOME_ARM_POSITIONS + 0.01
    bench.run(5, extra=lambda b: b.publish(
        "arm_status", messages.encode_arm_status(
            b.utime() + 1, q_good, np.zeros(6))))
    bench.run(1, status=False)
    utime = bench.utime()
    bad = {
        "arm_status": [
            messages.encode_arm_status(utime, [np.nan] * 6, np.zeros(6)),
            messages.encode_arm_status(utime + 1, np.zeros(5), np.zeros(5)),
            messages.encode_arm_status(5, np.zeros(6), np.zeros(6)),
            b"not an LCM message"],
        "base_state": [
            messages.encode_arm_status(utime, np.zeros(6), np.zeros(6)),
            messages.encode_base_state(utime, [0, 0, np.inf, 0, 0, 0])],
        "wrist_wrench": [
            messages.encode_wrench(utime, [np.nan, 0, 0, 0, 0, 0]),
            messages.encode_wrench(9, np.ones(6))],
        "obstacle_points": [
            messages.encode_obstacle_points(utime, [[np.nan, 1.0]]),
            messages.encode_obstacle_points(-1, [[3.0, 3.0]]),
            # A flood of points, in sequence and finite: one too many.
            messages.encode_obstacle_points(utime + 2, np.full(
                (bench.options.max_obstacle_points + 1, 2), 3.0))],
    }
    for i in range(4):
        def send(b, i=i):
            for channel, datas in bad.items():
                if i < len(datas):
                    b.publish(channel, datas[i])
        # Only bad status for 4 periods, then nothing: the watchdog is
        # not fed by rejected messages.
        bench.run(1, status=False, extra=send)
        np.testing.assert_array_equal(
            bench.output("arm.position_measured"), q_good)
        np.testing.assert_array_equal(
            bench.output("wrist.wrench_measured"), WRENCH)
        np.testing.assert_array_equal(
            bench.output("lidar.obstacle_points"), POINTS)
        assert np.all(np.isfinite(bench.output("base.state_estimated")))
    diagnostics = bench.diagnostics()
    for channel, datas in bad.items():
        assert diagnostics[f"{channel}_rejected"] == len(datas), channel
    assert diagnostics["watchdog_tripped"] == 1.0
    for _, command in bench.sent["base"] + bench.sent["arm"]:
        assert np.all(np.isfinite(command))
    # A NaN command of the controller is not sent either.
    bench.run(60)
    bench.set_command(bench.arm, np.full(6, np.nan))
    bench.run(3)
    assert bench.diagnostics()["invalid_commands"] >= 1
    for _, command in bench.sent["base"] + bench.sent["arm"]:
        assert np.all(np.isfinite(command))
    np.testing.assert_array_equal(bench.sent["base"][-1][1], 0.0)


def test_a_command_not_finite_is_said_once_and_so_is_its_end(caplog):
    """The controller's base command NaN for 1 s: the guard warned at
    every command time (100 times), without saying which entry. It now
    says once when the command becomes not finite, naming the port and
    the entry, and once when it is finite again; the count of commands
    not sent goes on. The arm's likewise."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    bench = Bench()
    bench.run(60)
    bench.set_command(bench.base, [0.3, np.nan, 0.2])
    bench.run(100)
    bench.set_command(bench.base, BASE_COMMAND)
    bench.run(20)
    assert bench.diagnostics()["invalid_commands"] == 100.0
    bad = _records(caplog, "is not finite")
    assert len(bad) == 1
    assert "(base_velocity_command[1] = nan); not sent" in \
        bad[0].getMessage()
    assert len(_records(caplog, " s is finite again")) == 1
    caplog.clear()
    arm = HOME_ARM_POSITIONS.copy()
    arm[4] = -np.inf
    bench.set_command(bench.arm, arm)
    bench.run(10)
    bench.set_command(bench.arm, HOME_ARM_POSITIONS)
    bench.run(10)
    assert bench.diagnostics()["invalid_commands"] == 110.0
    assert [r.getMessage().split(" s ")[1] for r in caplog.records] == [
        "is not finite (arm_position_command[4] = -inf); not sent (the "
        "base stops, the arm slows down and holds) until it is finite "
        "again", "is finite again; sent within the limits"]


def test_one_future_stamped_message_locks_nothing_out():
    """A message stamped a minute ahead (forged, or a sender's clock
    gone wrong) is rejected; the genuine messages after it are taken and
    the watchdog never trips. It once locked the controller out until a
    restart: every genuine message after it went "backwards"."""
    bench = Bench()
    bench.run(60)
    bench.publish("arm_status", messages.encode_arm_status(
        bench.utime() + 60_000_000, HOME_ARM_POSITIONS + 1.0, np.zeros(6)))
    bench.publish("base_state", messages.encode_base_state(
        bench.utime() + 60_000_000, np.ones(6)))
    bench.run(100)
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_trips"] == 0.0
    assert diagnostics["arm_status_rejected"] == 1.0
    assert diagnostics["arm_status_age"] <= H + 1e-9
    np.testing.assert_array_equal(bench.output("arm.position_measured"),
                                  HOME_ARM_POSITIONS)


def test_a_sender_clock_that_jumps_stops_the_commands_until_it_recovers(
        caplog):
    """The robot's clock jumps back by 50 s (a restart of its driver) and
    later forward by 20 s (a clock step, or another sender on its
    channels): the controller takes the new clock after three consistent
    messages, but as a stale stream: it stops at once, says why, and
    resumes only once every stream has been fresh for the recovery time,
    from rest within the acceleration limits."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    bench = Bench()
    recovery = bench.options.watchdog_recovery_time
    bench.run(60)
    for trips, jump in enumerate((-50_000_000, 20_000_000), start=1):
        bench.utime_offset += jump
        start = bench.tick * H
        bench.run(10)
        diagnostics = bench.diagnostics()
        assert diagnostics["watchdog_trips"] == trips
        assert diagnostics["watchdog_tripped"] == 1.0
        bench.run(110)
        times, base = bench.commands("base", start)
        # Zero from the check after the jump was taken (the third
        # message, 2 periods in) until the recovery time has passed (the
        # LIDAR's, at 1/6 of the rate, a little longer), then from rest
        # within the acceleration limits.
        taken = start + 2 * H + 2 * bench.options.watchdog_period
        stopped = (times > taken) & (times < taken + recovery)
        assert stopped.sum() >= recovery / H - 2
        np.testing.assert_array_equal(base[stopped], 0.0)
        assert np.all(_steps(base[times > taken]) <= 1.0 * H + 1e-10)
        _rows_equal(base[times > bench.tick * H - 0.05], BASE_COMMAND)
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_tripped"] == 0.0
    assert diagnostics["base_state_rejected"] == 4.0  # 2 a jump
    assert diagnostics["base_state_age"] <= H + 1e-9
    decoder = bench.hw.systems["decoder.base_state"]
    reception = decoder.reception(decoder.GetMyContextFromRoot(bench.root))
    assert reception.clock_jumps == 2
    assert len(_records(caplog, "base_state (its sender's clock "
                                "jumped)")) == 2


class SteppedClock:
    """A wall clock for a test: `now` s, moved by the test."""

    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_a_controller_that_missed_the_processor_stops_and_resumes_from_rest(
        caplog):
    """The controller's process misses the processor for 0.4 s while the
    base moves (its clock stands still, the wall clock runs on): longer
    than the robot's command timeout (0.25 s) less a period, so the robot
    has stopped its base on its own meanwhile. At the check after it every
    stream is stale: the base gets zero at once, the arm stops within its
    limits, the run says why, and the commands resume from rest once
    every stream has been fresh for the recovery time. A controller
    slower than real time, or missing the processor for less than that,
    sends on (as late messages would be: the robot still runs the last
    command)."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    clock = SteppedClock()
    bench = Bench(wall_clock=WallClock(clock=clock))
    limits = Limits.of_robot(bench.options)
    recovery = bench.options.watchdog_recovery_time
    assert limits.command_timeout - H == pytest.approx(0.24)

    def wall(step):
        """Each tick, the wall clock `step` s on before it."""
        def extra(bench):
            clock.now += step
        return extra

    bench.run(60, extra=wall(H))
    _rows_equal(bench.commands("base", 0.45)[1], BASE_COMMAND)
    # At two thirds of real time, and a hiccup of 0.2 s: nothing stops.
    bench.run(20, extra=wall(1.5 * H))
    clock.now += 0.2
    bench.run(20, extra=wall(H))
    assert bench.diagnostics()["watchdog_trips"] == 0.0
    _rows_equal(bench.commands("base", bench.tick * H - 0.3)[1],
                BASE_COMMAND)
    # The stall, between two ticks.
    stall = bench.tick * H
    arm_before = bench.sent["arm"][-1][1]
    clock.now += 0.4
    bench.run(1, extra=wall(H))
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_trips"] == 1.0
    assert diagnostics["watchdog_tripped"] == 1.0
    assert len(_records(caplog, "0.410 s of wall clock passed since the "
                                "last check (limit 0.240 s)")) == 1
    bench.run(100, extra=wall(H))
    times, base = bench.commands("base", stall)
    assert times[0] < stall + 2 * bench.options.watchdog_period
    np.testing.assert_array_equal(base[times < stall + recovery], 0.0)
    assert np.all(_steps(base) <= limits.base_acceleration * H + 1e-10)
    _rows_equal(base[times > stall + recovery + 0.35], BASE_COMMAND)
    times, arm = bench.commands("arm", stall)
    rate = np.diff(np.vstack([arm_before, arm]), axis=0) / H
    assert np.all(np.abs(np.diff(rate, axis=0))
                  <= limits.joint_acceleration * H + 1e-9)
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_trips"] == 1.0
    assert diagnostics["check_interval"] == 0.0  # within the last tick
    # A stall that ends between a check and the send after it (the send
    # at a time goes before the check at that time): the send is zero
    # already, and the check after it trips.
    bench.run(60, extra=wall(H))
    _rows_equal(bench.commands("base", bench.tick * H - 0.05)[1],
                BASE_COMMAND)
    stall = bench.tick * H + 0.0015  # after the check at 1 ms
    bench.simulator.AdvanceTo(stall)
    clock.now += 0.4
    bench.run(30, extra=wall(H))
    times, base = bench.commands("base", stall)
    assert times[0] == pytest.approx(stall + 0.0005)  # the send at 2 ms
    np.testing.assert_array_equal(base, 0.0)
    assert bench.diagnostics()["watchdog_trips"] == 2.0


def test_a_controller_too_slow_for_the_robots_timeout_stops(caplog):
    """The controller slows down to 1/30 of real time while the base
    moves (30 ms of wall clock each check, a flood of work, say): no two
    checks are further apart than the stall limit (0.24 s), but two
    commands are 0.3 s apart, longer than the robot's command timeout
    (0.25 s), so the robot stops its base between every two of them, and
    each command started it again with a step. It went on sending; now
    it stops (the base's zero at the next check) and says why, and stays
    stopped while it is that slow."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    clock = SteppedClock()
    bench = Bench(wall_clock=WallClock(clock=clock))
    bench.run(60, extra=lambda _: setattr(clock, "now", clock.now + H))
    _rows_equal(bench.commands("base", 0.45)[1], BASE_COMMAND)
    slow = bench.tick * H
    for _ in range(30):
        bench.status()
        for j in range(1, 11):
            clock.now += 0.03
            bench.simulator.AdvanceTo(bench.tick * H + j * 1e-3)
        bench.tick += 1
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_trips"] == 1.0
    assert diagnostics["watchdog_tripped"] == 1.0
    times, base = bench.commands("base", slow)
    assert times[0] < slow + H  # the last command before is 0.24 s old
    np.testing.assert_array_equal(base[1:], 0.0)
    assert len(_records(caplog, "since the last command time, the next "
                                "0.001 s away at the least (limit 0.250 s "
                                "together)")) == 1


class PacedClock:
    """A wall clock for a test: a controller whose own clock runs `pace`
    times as fast as the wall clock (1: it keeps pace), from the time
    of `bench`'s simulator."""

    def __init__(self):
        self.bench, self.pace, self.start, self.wall = None, 1.0, 0.0, 100.0

    def set_pace(self, pace):
        self.wall, self.start = self(), self.bench.root.get_time()
        self.pace = pace

    def __call__(self):
        time = 0.0 if self.bench is None else self.bench.root.get_time()
        return self.wall + (time - self.start) / self.pace


def test_a_controller_at_pace_runs_at_the_shortest_command_timeout(caplog):
    """A robot command timeout of 0.015 s (accepted: longer than the
    command period) stopped a controller keeping perfect pace at once
    and for good: the guard compared the wall clock since the last
    command time with the timeout less a period (5 ms), which a period
    between two commands exceeds. It now compares what the robot waits at
    the least: that time and the controller's to the next command time,
    against the timeout itself. At the shortest timeout allowed, a
    period and a watchdog period (0.011 s; shorter ones are refused
    naming it), a controller at pace runs without a trip; one at 0.9 of
    real time, its commands 11.1 ms apart, stops (its checks 1.1 ms
    apart, the stall limit's 1 ms), and at 0.6 of real time with a
    timeout of 0.015 s, saying why."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    with pytest.raises(ValueError, match=re.escape(
            "robot_command_timeout = 0.0105 s is not allowed with "
            "publish_period = 0.01 s and watchdog_period = 0.001 s: must be "
            "at least their sum, 0.011 s")):
        Bench(robot_command_timeout=0.0105)
    for timeout, pace in ((0.011, 0.9), (0.015, 0.6)):
        caplog.clear()
        clock = PacedClock()
        bench = Bench(wall_clock=WallClock(clock=clock),
                      robot_command_timeout=timeout)
        clock.bench = bench
        bench.run(200)
        assert bench.diagnostics()["watchdog_trips"] == 0.0
        _rows_equal(bench.commands("base", 1.0)[1], BASE_COMMAND)
        assert not _records(caplog, "watchdog tripped")
        clock.set_pace(pace)
        bench.run(20)
        assert bench.diagnostics()["watchdog_tripped"] == 1.0
    # At 0.6 of real time the checks are 1.7 ms apart, within the stall
    # limit (5 ms), and the commands 16.7 ms: the stop comes 2 ms of the
    # controller's time before the next command time.
    assert len(_records(caplog, "0.013 s of wall clock passed since the "
                                "last command time, the next 0.002 s away "
                                "at the least (limit 0.015 s together)")) \
        == 1


def test_the_wall_clock_is_in_controller_seconds():
    """WallClock.now: the wall clock times the real-time rate."""
    clock = SteppedClock()
    wall_clock = WallClock(rate=0.5, clock=clock)
    before = wall_clock.now()
    clock.now += 2.0  # one controller second at half real time
    assert wall_clock.now() - before == pytest.approx(1.0)
    with pytest.raises(ValueError, match="rate = 0.0 is not allowed"):
        WallClock(rate=0)


def test_the_final_stop_follows_the_runs_commands_on_the_robot():
    """The stop a deployment sends when it ends is stamped on the run's
    time base, after its last command: a robot whose receiver took the
    run's commands takes every copy of the stop in sequence, also when
    the controller's clock ended 0.4 s behind the wall clock."""
    bench = Bench()
    offset = 1.7e9
    bench.hw.set_time_offset(bench.root, offset)
    stamps = []
    bench.lcm.Subscribe(bench.options.channels.base_command, lambda data:
                        stamps.append(messages.decode_base_command(data)))
    bench.run(60)
    bench.simulator.AdvanceTo(bench.tick * H + 0.004)
    # The robot's receiver took the run's last command at its now, the
    # wall clock 0.4 s ahead of the controller's.
    last = stamps[-1]
    now = 1e-6 * last.utime + 0.4
    reception = codecs.take(codecs.Reception(None, (np.zeros(3),), -np.inf),
                            last, now)
    count = len(stamps)
    send_stop(bench.lcm, bench.options, HOME_ARM_POSITIONS,
              bench.hw.sender, bench.hw.command_utime(bench.root) + 1)
    bench.lcm.HandleSubscriptions(0)
    stops = stamps[count:]
    assert len(stops) == STOP_REPEATS
    for i, stop in enumerate(stops):
        np.testing.assert_array_equal(stop.values[0], 0.0)
        reception = codecs.take(reception, stop, now + 0.002 * (i + 1))
        assert reception.utime == stop.utime  # taken
        assert reception.rejected == 0


def test_the_final_stop_brakes_a_moving_arm_within_its_limits():
    """A deployment that ends while the arm moves at full speed (1.57
    rad/s): the stop brakes it within 12.56 rad/s^2, one command a period
    with the base at zero, and holds it where it comes to rest, every
    command in sequence on the robot. (It was held at once: a step of 157
    rad/s^2.)"""
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(3)
    bench.set_command(bench.arm, HOME_ARM_POSITIONS + 1.0)
    bench.run(40)
    guard = bench.hw.systems["guard"]
    sent = guard.stored(guard.GetMyContextFromRoot(bench.root))
    np.testing.assert_allclose(sent.arm_velocity, 1.57)
    arms, bases = [], []
    bench.lcm.Subscribe(bench.options.channels.arm_command, lambda data:
                        arms.append(messages.decode_arm_command(data)))
    bench.lcm.Subscribe(bench.options.channels.base_command, lambda data:
                        bases.append(messages.decode_base_command(data)))
    held = send_stop(bench.lcm, bench.options, sent.arm, bench.hw.sender,
                     bench.hw.command_utime(bench.root) + 1,
                     arm_velocity=sent.arm_velocity, limits=limits)
    bench.lcm.HandleSubscriptions(0)
    q = np.array([sent.arm - sent.arm_velocity * H, sent.arm]
                 + [m.values[0] for m in arms])
    rate = np.diff(q[:-STOP_REPEATS + 1], axis=0) / H
    assert np.all(np.abs(np.diff(rate, axis=0))
                  <= limits.joint_acceleration * H + 1e-9)
    np.testing.assert_array_equal(rate[-1], 0.0)
    np.testing.assert_array_equal(q[-STOP_REPEATS:], np.broadcast_to(
        held, (STOP_REPEATS, 6)))
    for m in bases:
        np.testing.assert_array_equal(m.values[0], 0.0)
    stamps = [m.utime for m in arms]
    assert np.all(np.diff(stamps) > 0)
    assert len(arms) == 13 + STOP_REPEATS  # 1.57 / (12.56 * 0.01) periods


def test_the_final_stop_holds_an_arm_whose_rate_is_not_known():
    """A rate that is not finite cannot be braked from (the ramp from NaN
    never came to rest, and the stop hung): the joint is held at once,
    the others brake as before."""
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    arms = []
    bench.lcm.Subscribe(bench.options.channels.arm_command, lambda data:
                        arms.append(messages.decode_arm_command(data)))
    velocity = np.zeros(6)
    velocity[0], velocity[1] = np.nan, 0.2
    held = send_stop(bench.lcm, bench.options, HOME_ARM_POSITIONS,
                     bench.hw.sender, 1, arm_velocity=velocity,
                     limits=limits)
    bench.lcm.HandleSubscriptions(0)
    assert np.isfinite(held).all()
    assert held[0] == HOME_ARM_POSITIONS[0]
    assert held[1] > HOME_ARM_POSITIONS[1]
    assert len(arms) == 2 + STOP_REPEATS  # 0.2 / (12.56 * 0.01) periods
    assert all(np.isfinite(m.values[0]).all() for m in arms)


def test_deploy_does_not_start_on_a_base_state_that_stopped():
    """The robot sends each status once, then nothing: deploy waited for
    the next base state, went on without it, and ran the controller on
    the state heard last (commands went out until the watchdog tripped).
    It now stops before the start, says why, and sends nothing."""
    scenario = load_scenario(find_scenario("hardware"))
    options = replace(scenario.hardware, lcm_url="memq://")
    lcm = DrakeLcm("memq://")
    channels = options.channels
    sent = []
    for channel in (channels.base_command, channels.arm_command):
        lcm.Subscribe(channel, lambda data: sent.append(data))
    statuses = [
        (channels.base_state, messages.encode_base_state(1, np.zeros(6))),
        (channels.arm_status, messages.encode_arm_status(
            1, HOME_ARM_POSITIONS, np.zeros(6))),
        (channels.wrist_wrench, messages.encode_wrench(1, np.zeros(6))),
        (channels.obstacle_points,
         messages.encode_obstacle_points(1, np.zeros((0, 2))))]
    subscribed = []

    def once():
        """Polled while deploy waits (subscribed by then): the statuses,
        the first time only."""
        if not subscribed:
            subscribed.append(True)
            for channel, data in statuses:
                lcm.Publish(channel, data)
        return False

    with pytest.raises(TimeoutError, match=re.escape(
            f"no status on {channels.base_state} for "
            f"{options.watchdog_limits.base_state:g} s")):
        deploy(scenario, options=options, duration=0.2, lcm=lcm, stop=once)
    lcm.HandleSubscriptions(0)
    assert subscribed and not sent


def test_a_flood_hides_no_genuine_message():
    """200 garbage messages a control period on every status channel
    (20,000 a second, after each genuine one): every genuine message is
    still taken in, so the watchdog never trips; every garbage one is
    rejected."""
    bench = Bench()
    garbage = [b"garbage", messages.encode_base_command(0, np.zeros(3)),
               messages.encode_arm_status(1, np.zeros(5), np.zeros(5))]

    def flood(b):
        for channel in ("base_state", "arm_status", "wrist_wrench",
                        "obstacle_points"):
            for i in range(200):
                b.publish(channel, garbage[i % 3])

    bench.run(60)
    bench.run(50, extra=flood)
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_trips"] == 0.0
    assert diagnostics["base_stops"] == 0.0
    assert diagnostics["base_state_rejected"] == 200 * 50
    assert diagnostics["arm_status_age"] <= H + 1e-9
    times, base = bench.commands("base", 0.6)
    _rows_equal(base, BASE_COMMAND)


def test_arm_commands_are_rate_and_position_limited():
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(3)
    target = HOME_ARM_POSITIONS.copy()
    target[0] += 0.5
    target[4] = limits.upper[4] + 1.0
    bench.set_command(bench.arm, target)
    bench.run(150)  # 1.41 rad at 1.57 rad/s on joint 5
    q = np.array([command for _, command in bench.sent["arm"]])
    rate = np.diff(q, axis=0) / H
    assert np.all(np.abs(rate) <= 1.57 + 1e-9)
    assert np.all(np.abs(np.diff(rate, axis=0)) <= 12.56 * H + 1e-9)
    assert np.max(np.abs(rate[:, 4])) == pytest.approx(1.57)
    assert q[-1][0] == pytest.approx(target[0])
    assert q[-1][4] == pytest.approx(limits.upper[4])
    assert np.all(q <= limits.upper) and np.all(q >= limits.lower)
    assert bench.diagnostics()["arm_command_saturated"] == 1.0


def test_a_huge_finite_arm_command_never_turns_the_commands_into_nan():
    """A controller's arm command that is finite but absurd (1e306 rad),
    then a sane one: the target's rate between them overflows, and the
    arm's commands once became NaN from then on (they were sent, and the
    guard's state stayed NaN). Every command sent stays finite and within
    the limits, and the arm gets to the sane command."""
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(3)
    bench.set_command(bench.arm, np.full(6, 1e306))
    bench.run(1)
    bench.set_command(bench.arm, HOME_ARM_POSITIONS)
    bench.run(40)
    q = np.array([command for _, command in bench.sent["arm"]])
    assert np.all(np.isfinite(q))
    assert np.all(q <= limits.upper) and np.all(q >= limits.lower)
    rate = np.diff(q, axis=0) / H
    assert np.all(np.abs(rate) <= limits.joint_speed + 1e-9)
    assert np.all(np.abs(np.diff(rate, axis=0))
                  <= limits.joint_acceleration * H + 1e-9)
    np.testing.assert_allclose(q[-1], HOME_ARM_POSITIONS)


def test_an_arm_found_beyond_its_limits_is_refused_not_jumped_back():
    """The robot's measured arm positions beyond a joint's limits (3.3 rad
    on joint 0, limit 3.14): the guard's first command, held within the
    limits, jumped 0.16 rad in one period (16 rad/s). The interface now
    refuses to start from there, naming the joint and its limits."""
    bench = Bench()
    q0 = HOME_ARM_POSITIONS.copy()
    q0[0] = 3.3
    with pytest.raises(ValueError, match=re.escape(
            "positions[0] = 3.3 is not allowed: must be within the joint's "
            "limits [-3.14, 3.14] rad")):
        bench.hw.set_arm_command(bench.root, q0)
    with pytest.raises(ValueError, match=re.escape(
            "initial_arm_positions[0] = 3.3 is not allowed")):
        HardwareInterface(bench.options, bench.lcm, q0)
    limits = Limits.of_robot(bench.options)
    with pytest.raises(ValueError, match=re.escape(
            "initial_positions[0] = 3.3 is not allowed")):
        ArmCommandLimiter(H, 0.007, q0, limits)


def test_the_guards_arm_follow_tolerance_goes_by_the_name_its_error_gives():
    """The command guard's tolerance was `arm_tolerance` while its error
    named `arm_follow_tolerance`: CommandGuard(arm_follow_tolerance=...),
    as the error and the HardwareInterface call it, was refused as an
    unknown argument. It now has the one name throughout."""
    options = HardwareOptions()
    guard = CommandGuard(options, HOME_ARM_POSITIONS,
                         arm_follow_tolerance=0.15)
    assert guard.config.arm_follow_tolerance == 0.15
    with pytest.raises(ValueError, match=re.escape(
            "arm_follow_tolerance = 0.0 is not allowed")):
        CommandGuard(options, HOME_ARM_POSITIONS, arm_follow_tolerance=0.0)


def test_an_arm_resting_at_a_limit_with_an_encoders_noise_starts_there():
    """An arm read a hair beyond a limit (at rest at it, with an encoder's
    noise) starts at the limit: the first command's step is within what
    the acceleration limit allows in one period (joint_acceleration h^2,
    1.26e-3 rad here); beyond that it is refused."""
    limits = Limits.of_robot(HardwareOptions())
    slack = float(limits.joint_acceleration[0]) * H * H
    q0 = HOME_ARM_POSITIONS.copy()
    q0[0] = float(limits.upper[0]) + 0.9 * slack
    limiter = ArmCommandLimiter(H, 0.007, q0, limits)
    state = limiter.CreateDefaultContext().get_abstract_state(0).get_value()
    assert state.command[0] == limits.upper[0]
    bench = Bench()
    bench.hw.set_arm_command(bench.root, q0)
    guard = bench.hw.systems["guard"]
    held = guard.stored(guard.GetMyContextFromRoot(bench.root)).arm
    assert held[0] == limits.upper[0]
    q0[0] = float(limits.upper[0]) + 1.1 * slack
    with pytest.raises(ValueError, match=re.escape(
            f"initial_positions[0] = {float(q0[0])!r} is not allowed")):
        ArmCommandLimiter(H, 0.007, q0, limits)


def test_a_stalled_controllers_bunched_commands_do_not_fault_the_arm():
    """A controller that stalls for five periods and then sends the five
    commands it owes together (each one period on from the one before, at
    1 rad/s): the robot side's limiter took each command at once on
    arrival, so two of them on both sides of its update were two steps
    within one period of the arm's servo, which faulted the arm (its rate
    changed at 37 rad/s^2, limit 12.56). Now the arm gets one step a
    period, and the servo (the station's, checking the arm's own limits)
    takes every one."""
    from drake_wbc.robot.model import ArmKinematics
    from drake_wbc.station.arm_supervisor import ArmCommandSupervisor

    arm = ArmKinematics()
    limits = Limits.of_robot(HardwareOptions())
    q0 = arm.home.copy()
    builder = DiagramBuilder()
    limiter = builder.AddSystem(ArmCommandLimiter(H, 0.007, q0, limits))
    servo = builder.AddSystem(ArmCommandSupervisor(
        H, q0, arm.model.limits, arm.model.description.arm.joints))
    builder.Connect(limiter.get_output_port(0), servo.get_input_port(0))
    simulator = Simulator(builder.Build())
    root = simulator.get_mutable_context()
    context = limiter.GetMyMutableContextFromRoot(root)
    limiter.get_input_port(0).FixValue(context, q0)
    simulator.Initialize()
    arrivals = []
    for k in range(1, 60):
        q = q0.copy()
        q[0] += min(k, 50) * H  # 1 rad/s, then at rest
        # Sent 2 ms after each tick, but those of ticks 20 to 24 late,
        # together, just before the servo's sample at 0.25 s.
        at = (k * H + 0.002 if not 20 <= k <= 24
              else 0.248 + 0.0003 * (k - 20))
        arrivals.append((at, q))
    taken = []
    for at, q in sorted(arrivals, key=lambda arrival: arrival[0]):
        simulator.AdvanceTo(at)
        limiter.get_input_port(0).FixValue(context, q)
    for k in range(int(round(at / H)) + 1, 80):
        simulator.AdvanceTo(k * H)
        taken.append(servo.get_output_port(0).Eval(
            servo.GetMyContextFromRoot(root))[0])
    assert servo.fault(servo.GetMyContextFromRoot(root)) is None
    assert taken[-1] == pytest.approx(q0[0] + 0.5, abs=1e-12)


def test_limits_wider_than_the_arms_own_are_refused():
    for name, value, own in (("joint_speed_limit", 100.0, "1.57 rad/s"),
                             ("joint_acceleration_limit", 1e6,
                              "12.56 rad/s^2")):
        with pytest.raises(ValueError, match=re.escape(
                f"hardware.{name} = {value!r} is not allowed: must be at "
                f"most the robot's own {own}")):
            Limits.of_robot(HardwareOptions(**{name: value}))


def test_base_saturation_keeps_the_direction():
    v, changed = saturate_base_velocity([3.0, 4.0, -2.5], 1.0, 1.0)
    np.testing.assert_allclose(v, [0.6, 0.8, -1.0])
    assert changed
    v, changed = saturate_base_velocity([0.3, 0.4, 0.5], 1.0, 1.0)
    np.testing.assert_array_equal(v, [0.3, 0.4, 0.5])
    assert not changed


LIMITS = Limits(1.0, 1.0, np.ones(3), np.full(6, 2.0), np.full(6, 10.0),
                -np.full(6, 5.0), np.full(6, 5.0))


def test_brake_speed_closed_form():
    """From brake_speed(d), slowing by a h a period, a joint travels d and
    stops: d a whole number of staircases (v = m a h) or not."""
    a, h = 10.0, 0.01
    for m in (1, 2, 5, 40):
        d = a * h * h * m * (m + 1) / 2
        assert brake_speed(d, a, h) == pytest.approx(m * a * h)
    for d in (0.0, 1e-6, 3e-4, 0.0019, 0.05, 1.234):
        v = brake_speed(d, a, h)
        travel = h * sum(max(v - k * a * h, 0.0) for k in range(1000))
        assert travel == pytest.approx(d, abs=1e-15)
        assert h * sum(max(v + 1e-9 - k * a * h, 0.0)
                       for k in range(1000)) > d


def test_follow_passes_a_command_within_the_limits_bit_for_bit():
    last = np.full(6, 0.1)
    target = last + 1.5 * 0.01 * np.array([1, -1, 0.5, 0, 1, -0.2])
    rate = (target - last) / 0.01
    q, v, limited = follow_arm_command(target, rate, last, rate, 0.01,
                                       LIMITS)
    assert q.tobytes() == target.tobytes() and not limited


def test_follow_reaches_a_far_target_without_overshoot():
    """From rest to a target 1 rad away: accelerate at the limit, cruise
    at the speed limit, brake at the limit and arrive at rest, never
    past the target."""
    h, q, v = 0.01, np.zeros(6), np.zeros(6)
    target = np.array([1.0, -1.0, 0.3, 0.0, 0.02, -0.5])
    path = [q]
    for _ in range(200):
        q, v, _ = follow_arm_command(target, np.zeros(6), q, v, h, LIMITS)
        path.append(q)
    path = np.array(path)
    rate = np.diff(path, axis=0) / h
    assert np.all(np.abs(rate) <= 2.0 + 1e-12)
    assert np.all(np.abs(np.diff(rate, axis=0)) <= 10.0 * h + 1e-12)
    np.testing.assert_array_equal(path[-1], target)
    for j in range(6):
        assert np.all(np.abs(path[:, j]) <= np.abs(target[j]) + 1e-9)
    # 1 rad: 0.2 s up to 2 rad/s, 0.2 s down, 0.3 s cruising: 0.7 s.
    arrived = np.flatnonzero(np.all(path == target, axis=1))[0]
    assert arrived * h == pytest.approx(0.7, abs=0.03)


def test_follow_catches_a_moving_target_and_then_passes_it():
    """A target moving at 1 rad/s, 0.2 rad ahead of a joint at rest: the
    joint catches up and from then on the target passes unchanged."""
    h, q, v = 0.01, np.zeros(6), np.zeros(6)
    rate = np.full(6, 1.0)
    for k in range(100):
        target = 0.2 + rate * h * k
        q, v, limited = follow_arm_command(target, rate, q, v, h, LIMITS)
    assert not limited
    np.testing.assert_array_equal(q, target)


def test_follow_stays_finite_for_any_finite_target():
    """A target or a target rate near the largest float (a forged arm
    command of 1e306 rad on the robot's side, then a genuine one) gives a
    command within the limits, not NaN."""
    h, q, v = 0.01, np.zeros(6), np.zeros(6)
    taken = np.zeros(6)
    for target in (np.full(6, 1e306), np.full(6, 0.1),
                   np.full(6, -1.7e308), np.full(6, 0.1)):
        q, v, limited = follow_arm_command(
            target, target_rate(target, taken, h), q, v, h, LIMITS)
        taken = target
        assert limited
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(v))
        assert np.all(np.abs(v) <= 2.0) and np.all(np.abs(q) <= 5.0)


def test_follow_brakes_before_a_position_limit():
    """A target that speeds up to 2 rad/s and runs on past the 5 rad
    limit: the joint brakes in time and comes to rest on the limit within
    10 rad/s^2 (it was followed at full speed up to the limit and stopped
    there within a period: 100 rad/s^2), and the commands before the
    braking pass unchanged."""
    h, q, v, taken = 0.01, np.zeros(6), np.zeros(6), np.zeros(6)
    target, rate, path, passed = np.zeros(6), np.zeros(6), [q], 0
    for _ in range(400):
        rate = np.minimum(rate + 10.0 * h, 2.0)
        target = target + rate * h
        q, v, limited = follow_arm_command(
            target, target_rate(target, taken, h), q, v, h, LIMITS)
        taken = target
        passed += not limited
        path.append(q)
    path = np.array(path)
    speeds = np.diff(path, axis=0) / h
    assert np.all(np.abs(np.diff(speeds, axis=0)) <= 10.0 * h * (1 + 1e-9))
    assert np.all(np.abs(speeds) <= 2.0 * (1 + 1e-9))
    np.testing.assert_array_equal(path[-1], 5.0)
    assert passed > 200  # 4 rad of the way: 0.2 s speeding up, 1.9 s at 2


def test_stop_arm_slows_down_at_the_limit():
    h, q, v = 0.01, np.zeros(6), np.array([2.0, -2.0, 0.05, 0, 1.0, -0.3])
    for _ in range(25):
        q, v = stop_arm(q, v, h, LIMITS)
    np.testing.assert_array_equal(v, 0.0)
    # Each joint travelled h^2 a m (m - 1) / 2 + ... : about v^2 / (2 a).
    np.testing.assert_allclose(q[:2], [0.19, -0.19], atol=0.011)


def test_a_stream_stays_watched_when_the_controllers_time_is_set_back():
    """A stream's age is the receiver's clock since its last message: with
    the controller's time set back 0.5 s (a context reused for another
    run, a simulator restarted at an earlier time), every age was
    negative, within every watchdog limit, and a robot that had gone
    silent was taken as fresh for 0.5 s, the commands going out as if it
    were there. An age that the clock cannot tell (a message received
    after now) is no fresh stream: the watchdog trips at once, and the
    commands resume from rest after the recovery time once the robot is
    heard again."""
    bench = Bench()
    bench.run(100)
    assert bench.diagnostics()["watchdog_tripped"] == 0.0
    bench.root.SetTime(0.5)
    bench.tick = 50
    bench.simulator.Initialize()
    before = len(bench.sent["base"])
    bench.run(5, status=False)
    assert bench.diagnostics()["watchdog_tripped"] == 1.0
    # The check at 0.501 s trips; from the command after it, zero.
    times, base = (np.array(column) for column in zip(
        *bench.sent["base"][before:], strict=True))
    assert len(times) and np.all(base[times > 0.502] == 0.0)
    assert np.any(times > 0.502)
    bench.utime_offset = int(0.5e6)  # the robot's stamps go on
    tripped = len(bench.sent["base"])
    bench.run(80)
    assert bench.diagnostics()["watchdog_tripped"] == 0.0
    base = np.array([v for _, v in bench.sent["base"][tripped:]])
    limits = bench.hw.systems["guard"].limits
    assert np.all(np.abs(np.diff(base, axis=0))
                  <= limits.base_acceleration * H * (1.0 + 1e-6))
    assert base[-1, 0] > 0.0
