"""The robot's side of the protocol protects itself (drake_wbc/hardware/
README.md): it obeys one sender at a time, judges time stamps as the
controller does, and limits the arm's commands in rate and acceleration
itself, so that a forged packet neither jerks the arm nor locks the real
controller out. The simulated robot (RobotSide) over memq://, with the
test as the controller and as a second sender."""

import logging

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_wbc.deployment.robot_side import RobotSide
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.hardware import messages
from drake_wbc.hardware.codecs import COMMAND_STATUS, QUEUE_LIMIT
from drake_wbc.hardware.options import HardwareOptions

H = 0.01
CONTROLLER, OTHER = 1234567, 7654321


class Robot:
    """The simulated robot in a Diagram, the test on its command channels
    and recording the arm command its arm gets every period."""

    def __init__(self):
        scenario = load_scenario(find_scenario("hardware"))
        self.options = HardwareOptions(lcm_url="memq://")
        self.lcm = DrakeLcm("memq://")
        builder = DiagramBuilder()
        self.robot = RobotSide(scenario, self.options, self.lcm)
        builder.AddSystem(self.robot.diagram)
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.root = self.simulator.get_mutable_context()
        self.robot.set_initial_state(self.root)
        self.simulator.Initialize()
        self.home = np.array(scenario.station.initial_arm_positions)
        self.tick = 0
        self.arm = []  # (t, the arm's command)

    def send(self, positions, sender=CONTROLLER, utime=None, base=None):
        utime = int(round(self.tick * H * 1e6)) if utime is None else utime
        channels = self.options.channels
        self.lcm.Publish(channels.arm_command, messages.encode_arm_command(
            utime, positions, sender))
        if base is not None:
            self.lcm.Publish(channels.base_command,
                             messages.encode_base_command(utime, base,
                                                          sender))

    def run(self, ticks, positions=None, extra=None):
        """`ticks` periods; the controller sends `positions` (if given)
        2 ms into each, then `extra(robot)`."""
        for _ in range(ticks):
            self.simulator.AdvanceTo(self.tick * H + 0.002)
            if positions is not None:
                self.send(positions)
            if extra is not None:
                extra(self)
            self.simulator.AdvanceTo(self.tick * H + 0.009)
            self.arm.append((self.root.get_time(), self.port(
                "arm_limiter", "positions").copy()))
            self.tick += 1

    def port(self, system, name):
        system = self.robot.systems[system]
        return system.GetOutputPort(name).Eval(
            system.GetMyContextFromRoot(self.root))

    def arm_fault(self):
        """The station's arm.fault (1 once its arm faulted)."""
        diagram = self.robot.diagram
        return diagram.GetOutputPort("arm.fault").Eval(
            diagram.GetMyContextFromRoot(self.root))[0]

    def status(self):
        return dict(zip(COMMAND_STATUS, self.port("commands", "status"),
                        strict=True))

    def rates(self):
        q = np.array([q for _, q in self.arm])
        return np.diff(q, axis=0) / H


def test_a_forged_packet_neither_jerks_the_arm_nor_locks_it_out():
    """The controller holds the arm at home; a packet of its own sender's
    identity (spoofed), stamped a little ahead of its clock, asks for 1 rad
    on every joint. Once it moved the arm 1 rad at once and, stamped a
    minute ahead, made the robot ignore its controller for 60 s. Here the
    arm moves within 1.57 rad/s and 12.56 rad/s^2 and is back under its
    controller's command within a few periods: the robot takes its
    controller's clock back after three of its messages (the forged
    stamp is ahead of theirs), and meanwhile the arm heads for the forged
    command no faster than its limits allow."""
    r = Robot()
    r.run(20, r.home)
    forged = int(round(r.tick * H * 1e6)) + 50_000  # 0.05 s ahead
    r.run(1, r.home, extra=lambda b: b.send(b.home + 1.0, utime=forged))
    # And one a minute ahead: out of sequence, rejected.
    r.run(1, r.home, extra=lambda b: b.send(b.home + 1.0,
                                            utime=forged + 60_000_000))
    r.run(60, r.home)
    rates = r.rates()
    assert np.all(np.abs(rates) <= 1.57 + 1e-9)
    assert np.all(np.abs(np.diff(rates, axis=0)) <= 12.56 * H + 1e-9)
    q = np.array([q for _, q in r.arm])
    excursion = np.max(np.abs(q - r.home))
    print(f"largest excursion {excursion:.4f} rad; status {r.status()}")
    assert excursion < 0.05
    np.testing.assert_array_equal(q[-1], r.home)
    assert r.status()["arm_command_rejected"] >= 1
    # The station's arm, which refuses what the real one would, took it.
    assert r.arm_fault() == 0.0


def test_the_robots_limiter_keeps_its_arm_from_faulting():
    """The controller itself jumps 0.3 rad on every joint: the station's
    arm would fault on that (tests/test_arm_fault.py), but the robot
    side's limiter leads it there within its limits, and it arrives."""
    r = Robot()
    r.run(5, r.home)
    r.run(150, r.home + 0.3)
    assert r.arm_fault() == 0.0
    q = np.array([q for _, q in r.arm])
    np.testing.assert_array_equal(q[-1], r.home + 0.3)
    measured = r.robot.diagram.GetOutputPort("arm.position_measured").Eval(
        r.robot.diagram.GetMyContextFromRoot(r.root))
    np.testing.assert_allclose(measured, r.home + 0.3, atol=2e-3)


def test_a_second_sender_is_refused_until_the_first_falls_quiet():
    r = Robot()
    r.run(20, r.home)
    # Another controller starts while the first one runs: refused, on
    # both channels.
    r.run(30, r.home, extra=lambda b: b.send(b.home + 0.3, OTHER,
                                             base=[0.5, 0.0, 0.0]))
    status = r.status()
    assert status["refused"] == 60
    assert status["sender_changes"] == 0
    np.testing.assert_array_equal(r.arm[-1][1], r.home)
    np.testing.assert_array_equal(r.port("commands", "velocity"), 0.0)
    # The first one falls quiet: after the sender release time (1 s) the
    # other one takes the channels, and the arm goes to its command within
    # the arm's limits.
    r.run(95, extra=lambda b: b.send(b.home + 0.3, OTHER))
    assert r.status()["sender_changes"] == 0
    np.testing.assert_array_equal(r.arm[-1][1], r.home)
    r.run(60, extra=lambda b: b.send(b.home + 0.3, OTHER))
    assert r.status()["sender_changes"] == 1
    np.testing.assert_allclose(r.arm[-1][1], r.home + 0.3)
    rates = r.rates()
    assert np.all(np.abs(rates) <= 1.57 + 1e-9)
    assert np.all(np.abs(np.diff(rates, axis=0)) <= 12.56 * H + 1e-9)
    assert np.max(np.abs(rates)) > 1.0


def test_commands_within_the_limits_pass_unchanged():
    """What the controller sends within the arm's limits is what the arm
    gets, bit for bit (the loopback tests compare whole runs)."""
    r = Robot()
    wave = [r.home + 0.2 * (1.0 - np.cos(np.pi * k * H)) for k in
            range(100)]
    for q in wave:
        r.run(1, q)
    got = np.array([q for _, q in r.arm])
    np.testing.assert_array_equal(got, np.array(wave))
    assert r.port("arm_limiter", "limited")[0] == 0.0


def test_the_robots_command_timeout_holds_when_its_clock_is_set_back():
    """The robot stops its base when no command came for its command
    timeout, judged on its own clock: with that clock set back 0.5 s
    (a reset of the robot's clock, a restarted simulation), the last
    command's age was negative, never beyond the timeout, and a base
    whose controller had gone silent went on at its last command for
    0.75 s. A command taken in after now has no age the clock can tell:
    the base stops."""
    from drake_wbc.hardware.codecs import CommandReceiver

    lcm = DrakeLcm("memq://")
    receiver = CommandReceiver(lcm, ("BASE", "ARM"), np.zeros(6),
                               timeout=0.25, release_time=1.0)
    simulator = Simulator(receiver)
    context = simulator.get_mutable_context()
    simulator.Initialize()
    command = [0.3, 0.0, 0.1]
    for k in range(1, 101):
        lcm.Publish("BASE", messages.encode_base_command(
            k * 10_000, command, sender=7))
        lcm.HandleSubscriptions(0)
        simulator.AdvanceTo(k * 0.01)
    velocity = receiver.GetOutputPort("velocity")
    np.testing.assert_array_equal(velocity.Eval(context), command)
    simulator.AdvanceTo(1.3)
    np.testing.assert_array_equal(velocity.Eval(context), 0.0)
    context.SetTime(0.5)
    simulator.Initialize()
    simulator.AdvanceTo(0.6)
    np.testing.assert_array_equal(velocity.Eval(context), 0.0)


def test_each_command_channel_says_its_own_rejections(caplog):
    """One arm command of 7 joints, and 1.5 s later one base command with
    a NaN: the warning of the second joined the reasons of both channels'
    last rejections, the arm's 1.5 s old. Each channel now says its own,
    of its messages rejected since its last warning. A flood of base
    commands beyond the mailbox (QUEUE_LIMIT in one step) drops the
    oldest: counted on the base's channel, where they were, not always
    on the arm's."""
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    r = Robot()
    channels = r.options.channels
    r.run(5, positions=r.home)
    r.lcm.Publish(channels.arm_command, messages.encode_arm_command(
        r.tick * 10_000, np.zeros(7), CONTROLLER))
    r.run(150, positions=r.home)
    r.lcm.Publish(channels.base_command, messages.encode_base_command(
        r.tick * 10_000, [np.nan, 0.0, 0.0], CONTROLLER))
    r.run(2, positions=r.home)
    rejected = [record.getMessage() for record in caplog.records
                if "rejected" in record.getMessage()]
    assert rejected == [
        f"arm_command on {channels.arm_command}: 1 message(s) rejected: "
        "position has 7 entries, which is not allowed: must have 6",
        f"base_command on {channels.base_command}: 1 message(s) rejected: "
        "velocity = [nan  0.  0.] is not allowed: every entry must be "
        "finite (no NaN or infinity)"]
    assert (r.status()["base_command_rejected"],
            r.status()["arm_command_rejected"]) == (1.0, 1.0)
    caplog.clear()
    r.run(100, positions=r.home)
    command = messages.encode_base_command(r.tick * 10_000, np.zeros(3),
                                           CONTROLLER)
    for _ in range(QUEUE_LIMIT + 5):  # repeats of one stamp: no rejection
        r.lcm.Publish(channels.base_command, command)
    r.run(1, positions=r.home)
    assert (r.status()["base_command_rejected"],
            r.status()["arm_command_rejected"]) == (6.0, 1.0)
    assert [record.getMessage() for record in caplog.records] == [
        f"base_command on {channels.base_command}: 5 message(s) rejected "
        f"in the last 1.02 s: 5 dropped: more than {QUEUE_LIMIT} messages "
        "in one step"]
