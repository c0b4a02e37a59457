"""The hardware interface's safety, with real LCM (memq://) and the test
playing the robot: the watchdog stops the commands when the status stops
and lets them resume; bad messages never reach the controller's inputs;
every command sent is within the robot's limits."""

import logging

import numpy as np
import pytest
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_wbc.hardware import messages
from drake_wbc.hardware.interface import DIAGNOSTICS, HardwareInterface
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.hardware.safety import (
    Limits,
    guarded_commands,
    saturate_arm_command,
    saturate_base_velocity,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS

H = 0.01
BASE_COMMAND = np.array([0.3, -0.1, 0.2])


class Bench:
    """The interface in a Diagram, with constant controller commands that
    a test can change, and the test in the robot's place on LCM."""

    def __init__(self):
        self.options = HardwareOptions(lcm_url="memq://")
        self.lcm = DrakeLcm("memq://")
        builder = DiagramBuilder()
        self.hw = HardwareInterface(self.options, self.lcm, HOME_ARM_POSITIONS)
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

    def publish(self, channel, data):
        self.lcm.Publish(getattr(self.options.channels, channel), data)

    def status(self, q=HOME_ARM_POSITIONS):
        utime = int(round(self.tick * H * 1e6))
        self.publish("base_state", messages.encode_base_state(
            utime, [0.0, 0.0, 0.0, 0.1, 0.0, 0.0]))
        self.publish("arm_status", messages.encode_arm_status(
            utime, q, np.zeros(6)))

    def run(self, ticks, status=True, extra=None):
        """`ticks` control periods, the robot sending its status at the
        start of each one (and `extra(bench)` if given)."""
        for _ in range(ticks):
            if status:
                self.status()
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

    def set_arm_command(self, q):
        context = self.arm.GetMyMutableContextFromRoot(self.root)
        self.arm.get_mutable_source_value(context).SetFromVector(q)


def _rows_equal(rows, value):
    assert len(rows) > 0
    np.testing.assert_allclose(rows, np.broadcast_to(value, rows.shape))


def _watchdog_records(caplog, word):
    return [r for r in caplog.records
            if r.name == "drake_wbc.hardware" and f"watchdog {word}" in
            r.getMessage()]


def test_watchdog_stops_the_commands_and_lets_them_resume(caplog):
    caplog.set_level(logging.WARNING, logger="drake_wbc.hardware")
    bench = Bench()
    limit = bench.options.watchdog_limit
    offset = bench.options.publish_offset
    bench.run(20)
    last_status = (bench.tick - 1) * H
    times, base = map(np.array, zip(*bench.sent["base"], strict=True))
    _rows_equal(base[times > 0.05], BASE_COMMAND)
    assert bench.diagnostics()["watchdog_tripped"] == 0.0
    arm_before = bench.sent["arm"][-1][1]

    bench.run(10, status=False)  # the robot falls silent for 0.1 s
    times, base = map(np.array, zip(*bench.sent["base"], strict=True))
    # Commands sent while the status is not yet too old go on; from the
    # first check after the limit (a guard tick) the base gets zero.
    young = (times > last_status) & (times <= last_status + limit)
    old = times > last_status + limit + H + offset
    assert young.any() and old.any()
    _rows_equal(base[young], BASE_COMMAND)
    np.testing.assert_array_equal(base[old], 0.0)
    for t, q in bench.sent["arm"]:
        if t > last_status + limit + H + offset:
            np.testing.assert_array_equal(q, arm_before)  # held
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_tripped"] == 1.0
    assert diagnostics["watchdog_trips"] == 1.0
    assert diagnostics["base_state_age"] > limit
    assert len(_watchdog_records(caplog, "tripped")) == 1

    resumed = bench.tick * H
    bench.run(10)
    times, base = map(np.array, zip(*bench.sent["base"], strict=True))
    _rows_equal(base[times > resumed + H + offset], BASE_COMMAND)
    diagnostics = bench.diagnostics()
    assert diagnostics["watchdog_tripped"] == 0.0
    assert diagnostics["watchdog_trips"] == 1.0
    assert len(_watchdog_records(caplog, "cleared")) == 1
    assert len(_watchdog_records(caplog, "tripped")) == 1


def test_bad_messages_never_reach_the_controller():
    bench = Bench()
    q_good = HOME_ARM_POSITIONS + 0.01
    bench.run(5, extra=lambda b: b.publish(
        "arm_status", messages.encode_arm_status(
            int(round(b.tick * H * 1e6)) + 1, q_good, np.zeros(6))))
    wrench = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    points = np.array([[1.0, 0.5], [2.0, -0.5]])
    bench.publish("wrist_wrench", messages.encode_wrench(10, wrench))
    bench.publish("obstacle_points",
                  messages.encode_obstacle_points(10, points))
    bench.run(1, status=False)
    utime = 10**9
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
            messages.encode_obstacle_points(9, [[3.0, 3.0]])],
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
            bench.output("wrist.wrench_measured"), wrench)
        np.testing.assert_array_equal(
            bench.output("lidar.obstacle_points"), points)
        assert np.all(np.isfinite(bench.output("base.state_estimated")))
    diagnostics = bench.diagnostics()
    for channel, datas in bad.items():
        assert diagnostics[f"{channel}_rejected"] == len(datas), channel
    assert diagnostics["watchdog_tripped"] == 1.0
    for _, command in bench.sent["base"] + bench.sent["arm"]:
        assert np.all(np.isfinite(command))
    # A NaN command of the controller is not sent either.
    bench.run(3)
    bench.set_arm_command(np.full(6, np.nan))
    bench.run(3)
    assert bench.diagnostics()["invalid_commands"] >= 1
    for _, command in bench.sent["base"] + bench.sent["arm"]:
        assert np.all(np.isfinite(command))
    np.testing.assert_array_equal(bench.sent["base"][-1][1], 0.0)


def test_arm_commands_are_rate_and_position_limited():
    bench = Bench()
    limits = Limits.of_robot(bench.options)
    bench.run(3)
    target = HOME_ARM_POSITIONS.copy()
    target[0] += 0.5
    target[4] = limits.upper[4] + 1.0
    bench.set_arm_command(target)
    bench.run(100)  # 1.41 rad at 1.57 rad/s on joint 5
    q = np.array([command for _, command in bench.sent["arm"]])
    step = np.max(np.abs(np.diff(q, axis=0)), axis=0)
    assert np.all(step <= 1.57 * H + 1e-12)
    assert step[0] == pytest.approx(1.57 * H)
    assert q[-1][0] == pytest.approx(target[0])
    assert q[-1][4] == pytest.approx(limits.upper[4])
    assert np.all(q <= limits.upper) and np.all(q >= limits.lower)
    assert bench.diagnostics()["arm_command_saturated"] == 1.0


def test_base_saturation_keeps_the_direction():
    v, changed = saturate_base_velocity([3.0, 4.0, -2.5], 1.0, 1.0)
    np.testing.assert_allclose(v, [0.6, 0.8, -1.0])
    assert changed
    v, changed = saturate_base_velocity([0.3, 0.4, 0.5], 1.0, 1.0)
    np.testing.assert_array_equal(v, [0.3, 0.4, 0.5])
    assert not changed


def test_arm_saturation_closed_form():
    limits = Limits(1.0, 1.0, np.full(6, 2.0), -np.ones(6), np.ones(6))
    last = np.zeros(6)
    command = np.array([0.5, -0.5, 0.01, -0.01, 3.0, 0.0])
    q, changed = saturate_arm_command(command, last, 0.1, limits)
    np.testing.assert_allclose(q, [0.2, -0.2, 0.01, -0.01, 0.2, 0.0])
    assert changed
    q, _ = saturate_arm_command([5.0] * 6, np.full(6, 0.95), 0.1, limits)
    np.testing.assert_allclose(q, np.ones(6))


def test_guarded_commands_stop_on_stale_status():
    limits = Limits(1.0, 1.0, np.full(6, 1.57), -np.ones(6) * 3,
                    np.ones(6) * 3)
    last = np.full(6, 0.1)
    result = guarded_commands([0.5, 0, 0], np.zeros(6), last,
                              [0.0, 0.031], 0.03, 0.01, limits)
    assert result.tripped
    np.testing.assert_array_equal(result.base, 0.0)
    np.testing.assert_array_equal(result.arm, last)
    result = guarded_commands([0.5, 0, 0], np.zeros(6), last,
                              [0.0, 0.03], 0.03, 0.01, limits)
    assert not result.tripped
    np.testing.assert_array_equal(result.base, [0.5, 0, 0])
