"""The LCM messages of the hardware interface: the generated types match
their .lcm files, every message survives a round trip, and what the
controller must not see (malformed bytes, wrong sizes, NaN, time going
backwards) is rejected."""

import copy
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.hardware import codecs, messages
from drake_wbc.hardware.options import (
    ChannelNames,
    HardwareOptions,
    WatchdogLimits,
    command_timeout_of,
)
from drake_wbc.hardware.safety import Limits
from drake_wbc.robot.description import shipped_robot

LCMTYPES = Path(messages.__file__).parent / "lcmtypes"


def test_generated_python_matches_the_lcm_files(tmp_path):
    readme = (LCMTYPES / "README.md").read_text()
    assert "lcm-gen -p --ppath . *.lcm" in readme
    lcm_gen = Path(sys.executable).parent / "lcm-gen"
    sources = sorted(LCMTYPES.glob("*.lcm"))
    subprocess.run([str(lcm_gen), "-p", "--ppath", str(tmp_path),
                    *map(str, sources)], check=True, capture_output=True)
    generated = sorted(p.name for p in (tmp_path / "drake_wbc_lcm").glob(
        "*.py"))
    committed = sorted(p.name for p in (LCMTYPES / "drake_wbc_lcm").glob(
        "*.py"))
    assert generated == committed
    for name in generated:
        assert ((tmp_path / "drake_wbc_lcm" / name).read_bytes()
                == (LCMTYPES / "drake_wbc_lcm" / name).read_bytes()), name


@pytest.mark.parametrize("name, values", [
    ("base_command", ([0.1, -0.2, 0.3],)),
    ("arm_command", ([0.0, -0.45, 1.0, 0.0, 1.15, 0.5],)),
    ("base_state", ([1.0, 2.0, 0.5, 0.1, 0.0, -0.1],)),
    ("arm_status", (np.arange(6.0), -np.arange(6.0))),
    ("wrist_wrench", ([1.0, 2.0, -10.0, 0.1, 0.2, 0.3],)),
    ("obstacle_points", (np.array([[1.0, 2.0], [-0.5, 0.25]]),)),
])
def test_round_trip(name, values):
    kind = codecs.message_formats(6)[name]
    decoded = kind.decode(kind.encode(1234567, *values))
    assert decoded.utime == 1234567
    for got, sent in zip(decoded.values, values, strict=True):
        np.testing.assert_array_equal(got, sent)


def test_points_of_another_shape_are_not_encoded():
    """(M, 3) points (x, y, z) were reshaped into 3 M / 2 points of mixed
    coordinates, an obstacle at (0.5, 3.0) among them; now refused,
    naming the shape. No points, of any empty shape, are none."""
    with pytest.raises(ValueError, match=re.escape(
            "points has shape (2, 3), which is not allowed: must be "
            "(M, 2)")):
        messages.encode_obstacle_points(1, [[1.0, 2.0, 0.5],
                                            [3.0, 4.0, 0.5]])
    with pytest.raises(ValueError, match=re.escape("shape (4,)")):
        messages.encode_obstacle_points(1, [1.0, 2.0, 3.0, 4.0])
    for none in ([], np.zeros((0, 2)), np.zeros((0, 3))):
        decoded = messages.decode_obstacle_points(
            messages.encode_obstacle_points(1, none))
        assert decoded.values[0].shape == (0, 2)


def test_signal_bundle_round_trip():
    data = messages.encode_signal_bundle(
        7, 0.25, {"a": [1.0, 2.0], "b": [3.0], "none": []})
    utime, time, signals = messages.decode_signal_bundle(data)
    assert (utime, time) == (7, 0.25)
    np.testing.assert_array_equal(signals["a"], [1.0, 2.0])
    np.testing.assert_array_equal(signals["b"], [3.0])
    assert signals["none"].size == 0


def test_malformed_messages_are_rejected():
    status = messages.encode_arm_status(1, np.zeros(6), np.zeros(6))
    bad = {
        "truncated": status[:-3],
        "trailing bytes": status + b"\0",
        "another type": messages.encode_base_state(1, np.zeros(6)),
        "garbage": b"\x01\x02\x03",
        "empty": b"",
        "five joints": messages.encode_arm_status(1, np.zeros(5),
                                                  np.zeros(5)),
        "NaN": messages.encode_arm_status(
            1, [0, 0, np.nan, 0, 0, 0], np.zeros(6)),
        "infinity": messages.encode_arm_status(
            1, np.zeros(6), [0, 0, 0, np.inf, 0, 0]),
    }
    for case, data in bad.items():
        with pytest.raises(messages.MessageError):
            messages.decode_arm_status(data, num_joints=6)
        print(case, "rejected")
    with pytest.raises(messages.MessageError, match="finite"):
        messages.decode_obstacle_points(messages.encode_obstacle_points(
            1, [[0.0, np.nan]]))
    with pytest.raises(messages.MessageError, match="finite"):
        messages.decode_base_command(messages.encode_base_command(
            1, [np.nan, 0.0, 0.0]))
    # A flood of points: refused beyond the most allowed, taken up to it.
    points = np.ones((11, 2))
    with pytest.raises(messages.MessageError, match=r"num_points = 11 is "
                       r"not allowed: must be at most 10 \(hardware"):
        messages.decode_obstacle_points(
            messages.encode_obstacle_points(1, points), max_points=10)
    decoded = messages.decode_obstacle_points(
        messages.encode_obstacle_points(1, points[:10]), max_points=10)
    np.testing.assert_array_equal(decoded.values[0], points[:10])


@pytest.mark.parametrize("n", [6, 7])
def test_the_arm_messages_carry_the_arms_joints(n):
    """An arm of n joints: its formats take n joints and refuse another
    count; the decoders without a count take any."""
    formats = codecs.message_formats(n)
    q = np.linspace(-1.0, 1.0, n)
    status = formats["arm_status"].encode(5, q, -q)
    np.testing.assert_array_equal(formats["arm_status"].decode(
        status).values[1], -q)
    assert dict(formats["arm_command"].ports)["positions"] == n
    other = codecs.message_formats(n + 1)
    with pytest.raises(messages.MessageError, match=f"must have {n + 1}"):
        other["arm_status"].decode(status)
    assert messages.decode_arm_status(status).values[0].size == n
    with pytest.raises(ValueError, match="num_joints = None"):
        codecs.MessageEncoder("arm_command")


def _state(utime, value=1.0):
    return messages.encode_base_state(utime, np.full(6, value))


START = codecs.Reception(None, (np.zeros(6),), -np.inf)


def test_receive_keeps_the_last_good_message():
    decode = messages.decode_base_state
    r = codecs.receive(START, _state(100), 0.01, decode)
    assert (r.utime, r.received, r.rejected) == (100, 0.01, 0)
    np.testing.assert_array_equal(r.values[0], np.ones(6))
    # A repeat of the time stamp is ignored, not counted, not fresh.
    repeat = codecs.receive(r, _state(100, 5.0), 0.02, decode)
    assert (repeat.received, repeat.rejected) == (0.01, 0)
    np.testing.assert_array_equal(repeat.values[0], np.ones(6))
    # Time going backwards, NaN, malformed: counted, last good kept.
    for i, data in enumerate([_state(50, 2.0), _state(200, np.nan),
                              _state(200, 3.0)[:-1]]):
        r = codecs.receive(r, data, 0.03 + i, decode)
        assert r.rejected == i + 1 and r.utime == 100 and r.received == 0.01
        np.testing.assert_array_equal(r.values[0], np.ones(6))
    assert "behind" in codecs.receive(
        codecs.receive(START, _state(9), 0, decode), _state(8), 0,
        decode).reason
    r = codecs.receive(r, _state(300, 4.0), 1.0, decode)
    assert (r.utime, r.received, r.rejected) == (300, 1.0, 3)


def test_a_stamp_ahead_of_the_receivers_clock_is_out_of_sequence():
    """The sender's stamps may run ahead of the receiver's clock since the
    last good message by the tolerance, no more: a message stamped 60 s
    ahead is rejected, and the genuine ones that follow are taken."""
    decode, rules = messages.decode_base_state, codecs.ClockRules(0.1, 3)
    r = codecs.receive(START, _state(1_000_000), 1.0, decode, rules)
    # 0.01 s of the receiver's clock later: up to 0.11 s ahead is fine.
    ok = codecs.receive(r, _state(1_110_000), 1.01, decode, rules)
    assert (ok.utime, ok.rejected) == (1_110_000, 0)
    forged = codecs.receive(r, _state(61_000_000, 9.0), 1.01, decode, rules)
    assert (forged.utime, forged.rejected) == (1_000_000, 1)
    assert "ahead of the receiver's clock" in forged.reason
    genuine = codecs.receive(forged, _state(1_020_000), 1.02, decode, rules)
    assert (genuine.utime, genuine.received) == (1_020_000, 1.02)
    np.testing.assert_array_equal(genuine.values[0], np.ones(6))


def test_a_jumped_clock_is_taken_after_consistent_messages():
    """A sender whose clock jumps (back: a restart; forward: a clock
    step) is rejected until `resync_messages` consecutive messages are in
    sequence among themselves; the last of them is taken."""
    decode, rules = messages.decode_base_state, codecs.ClockRules(0.1, 3)
    for jump in (-50_000_000, +50_000_000):
        r = codecs.receive(START, _state(60_000_000), 0.0, decode, rules)
        for k in range(1, 4):
            utime = 60_000_000 + jump + 10_000 * k
            r = codecs.receive(r, _state(utime, 2.0), 0.01 * k, decode,
                               rules)
            if k < 3:
                assert (r.utime, r.rejected, r.run_length) == (
                    60_000_000, k, k)
        assert (r.utime, r.received, r.rejected, r.clock_jumps) == (
            utime, 0.03, 2, 1)
        np.testing.assert_array_equal(r.values[0], np.full(6, 2.0))
    # A run broken by a message out of sequence with it starts again.
    r = codecs.receive(START, _state(60_000_000), 0.0, decode, rules)
    for k, utime in enumerate((5_000, 15_000, 1_000, 11_000, 21_000)):
        r = codecs.receive(r, _state(utime), 0.01 * (k + 1), decode, rules)
    assert (r.utime, r.clock_jumps, r.rejected) == (21_000, 1, 4)


def test_admit_locks_in_one_sender_until_it_falls_quiet():
    lock = codecs.SenderLock()
    lock, obeyed, new = codecs.admit(lock, 7, 0.0, 0.25)
    assert (lock.sender, obeyed, new) == (7, True, True)
    lock, obeyed, _ = codecs.admit(lock, 8, 0.2, 0.25)
    assert (lock.sender, obeyed, lock.refused) == (7, False, 1)
    lock, obeyed, new = codecs.admit(lock, 7, 0.2, 0.25)
    assert (obeyed, new, lock.heard) == (True, False, 0.2)
    lock, obeyed, new = codecs.admit(lock, 8, 0.45, 0.25)
    assert (obeyed, lock.sender) == (False, 7)  # 0.25 s quiet: not yet
    lock, obeyed, new = codecs.admit(lock, 8, 0.46, 0.25)
    assert (lock.sender, obeyed, new, lock.changes) == (8, True, True, 1)


def test_options_are_checked():
    with pytest.raises(ValueError, match="base_state = -1.0"):
        WatchdogLimits(base_state=-1.0)
    with pytest.raises(ValueError, match="lcm_url = 'tcp://x'"):
        HardwareOptions(lcm_url="tcp://x")
    with pytest.raises(ValueError, match="publish_offset = 0.02"):
        HardwareOptions(publish_offset=0.02)
    with pytest.raises(ValueError, match="arm_command = 'A'.*base_command"):
        ChannelNames(base_command="A", arm_command="A")
    with pytest.raises(ValueError, match="truth = 'has space'"):
        ChannelNames(truth="has space")
    with pytest.raises(ValueError, match="publish_period = 0.01.*"
                                         "watchdog_period = 0.003"):
        HardwareOptions(watchdog_period=0.003)
    with pytest.raises(ValueError, match="clock_resync_messages = 1"):
        HardwareOptions(clock_resync_messages=1)
    with pytest.raises(ValueError, match="max_obstacle_points = 0"):
        HardwareOptions(max_obstacle_points=0)
    with pytest.raises(ValueError,
                       match=r"obstacle_points = 0.05 s.*\(0.06667 s\)"):
        WatchdogLimits(obstacle_points=0.05)


@pytest.mark.parametrize("field, value, own", [
    ("base_speed_limit", 100.0, "1.0 m/s"),
    ("base_yaw_rate_limit", 3.0, "1.0 rad/s"),
    ("base_acceleration_limit", 1e9, "1.0 m/s^2"),
    ("base_yaw_acceleration_limit", 2.0, "1.0 rad/s^2"),
])
def test_base_limits_may_only_tighten_the_robots_own(field, value, own):
    """Checked against the robot's description when the command guard's
    limits are made (the shipped base's 1.0 each)."""
    with pytest.raises(ValueError, match=re.escape(
            f"hardware.{field} = {value!r} is not allowed: must be at most "
            f"the robot's own {own}")):
        Limits.of_robot(HardwareOptions(**{field: value}))
    limits = Limits.of_robot(HardwareOptions(**{field: 0.5}))
    assert 0.5 in (limits.base_speed, limits.base_yaw_rate,
                   *limits.base_acceleration)
    own = Limits.of_robot(HardwareOptions())
    assert (own.base_speed, own.base_yaw_rate) == (1.0, 1.0)
    np.testing.assert_array_equal(own.base_acceleration, np.ones(3))


def test_the_command_timeout_may_only_tighten_the_robots_own():
    """Checked against the robot's description (the shipped base's own
    0.25 s) when the command guard's limits are made, and its default."""
    base = shipped_robot().base
    with pytest.raises(ValueError, match=re.escape(
            "robot_command_timeout = 60.0 is not allowed: must be at most "
            "the robot's own 0.25 s")):
        Limits.of_robot(HardwareOptions(robot_command_timeout=60.0,
                                        sender_release_time=60.0))
    assert command_timeout_of(HardwareOptions(), base) == 0.25
    assert command_timeout_of(HardwareOptions(robot_command_timeout=0.1),
                              base) == 0.1
    slower = copy.deepcopy(base)
    slower.command_timeout = 0.5
    assert command_timeout_of(HardwareOptions(), slower) == 0.5
    with pytest.raises(ValueError, match="sender_release_time = 0.1 s.*"
                                         "robot_command_timeout = 0.25"):
        command_timeout_of(HardwareOptions(sender_release_time=0.1), base)
    with pytest.raises(ValueError, match=re.escape(
            "watchdog_limits.obstacle_points = 0.2 is not allowed: must be "
            "at most the robot's own command timeout 0.15 s")):
        quick = copy.deepcopy(base)
        quick.command_timeout = 0.15
        command_timeout_of(HardwareOptions(sender_release_time=1.0), quick)


def test_the_command_timeout_outlasts_a_command_period():
    """A robot command timeout no longer than the command period stops
    the base between every two commands (and left the command guard's
    stall limit, the timeout less a period, below zero), and one shorter
    than a period and a watchdog period the guard at every check (its
    stall limit below the time between two checks): refused, the
    robot's own too."""
    with pytest.raises(ValueError, match=re.escape(
            "robot_command_timeout = 0.03 s is not allowed with "
            "publish_period = 0.05 s and watchdog_period = 0.001 s: must "
            "be at least their sum, 0.051 s")):
        Limits.of_robot(HardwareOptions(publish_period=0.05,
                                        robot_command_timeout=0.03))
    base = copy.deepcopy(shipped_robot().base)
    base.command_timeout = 0.1
    lidar = WatchdogLimits(obstacle_points=0.1)
    with pytest.raises(ValueError, match=re.escape(
            "robot_command_timeout = 0.1 s (the robot's own) is not allowed "
            "with publish_period = 0.1 s")):
        command_timeout_of(HardwareOptions(publish_period=0.1,
                                           watchdog_limits=lidar), base)
    assert command_timeout_of(HardwareOptions(
        publish_period=0.05, watchdog_limits=lidar), base) == 0.1


@pytest.mark.parametrize("stream", ["base_state", "arm_status",
                                    "wrist_wrench", "obstacle_points"])
def test_a_watchdog_limit_cannot_disable_the_watchdog(stream):
    with pytest.raises(ValueError, match=(
            rf"hardware.watchdog_limits.{stream} = 1000000.0 is not allowed: "
            r"must be at most the robot's own command timeout 0.25 s")):
        load_scenario(text=f"hardware: {{watchdog_limits: {{{stream}: 1e6}}}}")


def test_the_hardware_scenario_loads():
    scenario = load_scenario(find_scenario("hardware"))
    assert scenario.hardware == HardwareOptions()
    assert scenario.hardware.publish_period == scenario.controller.time_step
    assert load_scenario(find_scenario("trajectory_tracking")).hardware \
        is None
    with pytest.raises(ValueError, match="hardware.channels.truth"):
        load_scenario(text="hardware: {channels: {truth: ''}}")


def test_a_signal_during_the_wait_for_messages_is_no_failure():
    """A signal that lands while QueuedLcm waits for a message (Ctrl-C,
    which robot-sim and deploy turn into a stop) made lcm give up with
    -1, and the program end in an OSError with exit code 1 instead of
    stopping (lcm's memq:// provider waits as udpm:// does): the wait is
    made once more, and ends as a wait without messages does."""
    import signal
    import time

    bus = codecs.QueuedLcm("memq://")
    bus.Subscribe("CHANNEL", lambda data: None)
    alarms = []
    previous = signal.signal(signal.SIGALRM,
                             lambda *_: alarms.append(time.monotonic()))
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        started = time.monotonic()
        assert bus.HandleSubscriptions(300) == 0
        ended = time.monotonic()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
    assert len(alarms) == 1 and started < alarms[0] < ended


def test_a_flood_that_never_pauses_does_not_hold_the_poll():
    """Messages arriving as fast as QueuedLcm delivers them (here each
    delivery brings the next, 5 QUEUE_LIMIT of them): one poll delivered
    until the flood paused, so a flood that never pauses held the
    program's LcmPump, and with it the guard's checks, for good (787,845
    messages in 2 s, and counting). A poll delivers at most QUEUE_LIMIT;
    the next poll goes on."""
    bus = codecs.QueuedLcm("memq://")
    delivered = []

    def handle(data):
        delivered.append(data)
        if len(delivered) < 5 * codecs.QUEUE_LIMIT:
            bus._lcm.publish("FLOOD", b"garbage")

    bus.Subscribe("FLOOD", handle)
    bus._lcm.publish("FLOOD", b"garbage")
    assert bus.HandleSubscriptions(0) == codecs.QUEUE_LIMIT
    assert bus.HandleSubscriptions(0) == codecs.QUEUE_LIMIT
