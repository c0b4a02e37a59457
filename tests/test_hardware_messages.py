"""The LCM messages of the hardware interface: the generated types match
their .lcm files, every message survives a round trip, and what the
controller must not see (malformed bytes, wrong sizes, NaN, time going
backwards) is rejected."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.hardware import codecs, messages
from drake_wbc.hardware.options import ChannelNames, HardwareOptions

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
    kind = codecs.FORMATS[name]
    decoded = kind.decode(kind.encode(1234567, *values))
    assert decoded.utime == 1234567
    for got, sent in zip(decoded.values, values, strict=True):
        np.testing.assert_array_equal(got, sent)


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
            messages.decode_arm_status(data)
        print(case, "rejected")
    with pytest.raises(messages.MessageError, match="finite"):
        messages.decode_obstacle_points(messages.encode_obstacle_points(
            1, [[0.0, np.nan]]))
    with pytest.raises(messages.MessageError, match="finite"):
        messages.decode_base_command(messages.encode_base_command(
            1, [np.nan, 0.0, 0.0]))


def test_receive_keeps_the_last_good_message():
    decode = messages.decode_base_state
    start = codecs.Reception(b"", None, (np.zeros(6),), -np.inf, 0)

    def state(utime, value):
        return messages.encode_base_state(utime, np.full(6, value))

    r = codecs.receive(start, b"", 0.0, decode)
    assert r is start  # the subscriber's empty default is no message
    r = codecs.receive(r, state(100, 1.0), 0.01, decode)
    assert (r.utime, r.received, r.rejected) == (100, 0.01, 0)
    np.testing.assert_array_equal(r.values[0], np.ones(6))
    # The same bytes again change nothing.
    assert codecs.receive(r, state(100, 1.0), 0.02, decode) is r
    # A repeat of the time stamp is ignored, not counted, not fresh.
    repeat = codecs.receive(r, state(100, 5.0), 0.02, decode)
    assert (repeat.received, repeat.rejected) == (0.01, 0)
    np.testing.assert_array_equal(repeat.values[0], np.ones(6))
    # Time going backwards, NaN, malformed: counted, last good kept.
    for i, data in enumerate([state(50, 2.0), state(200, np.nan),
                              state(200, 3.0)[:-1]]):
        r = codecs.receive(r, data, 0.03 + i, decode)
        assert r.rejected == i + 1 and r.utime == 100 and r.received == 0.01
        np.testing.assert_array_equal(r.values[0], np.ones(6))
    assert "backwards" in codecs.receive(
        codecs.receive(start, state(9, 0), 0, decode), state(8, 0), 0,
        decode).reason
    r = codecs.receive(r, state(300, 4.0), 1.0, decode)
    assert (r.utime, r.received, r.rejected) == (300, 1.0, 3)


def test_options_are_checked():
    with pytest.raises(ValueError, match="watchdog_limit = -1.0"):
        HardwareOptions(watchdog_limit=-1.0)
    with pytest.raises(ValueError, match="lcm_url = 'tcp://x'"):
        HardwareOptions(lcm_url="tcp://x")
    with pytest.raises(ValueError, match="publish_offset = 0.02"):
        HardwareOptions(publish_offset=0.02)
    with pytest.raises(ValueError, match="arm_command = 'A'.*base_command"):
        ChannelNames(base_command="A", arm_command="A")
    with pytest.raises(ValueError, match="truth = 'has space'"):
        ChannelNames(truth="has space")


def test_the_hardware_scenario_loads():
    scenario = load_scenario(find_scenario("hardware"))
    assert scenario.hardware == HardwareOptions()
    assert scenario.hardware.publish_period == scenario.controller.time_step
    assert load_scenario(find_scenario("trajectory_tracking")).hardware \
        is None
    with pytest.raises(ValueError, match="hardware.channels.truth"):
        load_scenario(text="hardware: {channels: {truth: ''}}")
