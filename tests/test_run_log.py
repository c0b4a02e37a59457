"""The run's log: SignalLogger's one sink against one LogVectorOutput a
signal, and RunLog's files."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    DiscreteTimeDelay,
    LogVectorOutput,
    Sine,
)

from drake_wbc.controller.run_log import RunLog, SignalLogger, advance_times
from drake_wbc.robot.description import load_robot_description, models_dir


def _signals(builder):
    """Named ports of a few sizes: a sine (3), its copy delayed by two
    updates of 3 ms (3, discrete, at another rate than the log's), a
    constant (1) and an empty constant (0)."""
    sine = builder.AddSystem(Sine([1.0, 2.0, 0.5], [3.0, 1.0, 7.0],
                                  [0.0, 0.3, 1.0], 3))
    delay = builder.AddSystem(DiscreteTimeDelay(0.003, 2, 3))
    builder.Connect(sine.get_output_port(0), delay.get_input_port())
    constant = builder.AddSystem(ConstantVectorSource([4.0]))
    empty = builder.AddSystem(ConstantVectorSource(np.zeros(0)))
    return {"sine": sine.get_output_port(0),
            "delayed": delay.get_output_port(),
            "alpha": constant.get_output_port(),
            "nothing": empty.get_output_port()}


def test_one_sink_logs_what_one_logger_a_signal_logs():
    builder = DiagramBuilder()
    ports = _signals(builder)
    log = SignalLogger(builder, ports, 0.01,
                       columns={"delayed": ("a", "b", "c")})
    alone = {name: LogVectorOutput(port, builder, 0.01)
             for name, port in ports.items() if port.size() > 0}
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.5)
    root = simulator.get_context()
    run = log.run_log(root, real_time_factor=3.0)
    assert list(run.signals) == ["sine", "delayed", "alpha"]
    assert "nothing" not in run
    assert run.real_time_factor == 3.0
    assert len(run.time) == 51
    for name, logger in alone.items():
        reference = logger.FindLog(root)
        np.testing.assert_array_equal(run.time, reference.sample_times())
        np.testing.assert_array_equal(run[name], reference.data().T)
    assert run.columns == {"sine": ("x0", "y0", "x1"),  # unnamed
                           "delayed": ("a", "b", "c"),  # named here
                           "alpha": ("alpha",)}  # named in run_log.SIGNALS


def test_a_log_without_signals_is_refused():
    builder = DiagramBuilder()
    ports = _signals(builder)
    with pytest.raises(ValueError, match="ports = .* at least one port"):
        SignalLogger(builder, {"nothing": ports["nothing"]}, 0.01)
    with pytest.raises(ValueError,
                       match=r"columns\['delayed'\] = .* have 3 names"):
        SignalLogger(builder, ports, 0.01, columns={"delayed": ("a",)})


def test_run_log_files_read_back(tmp_path):
    builder = DiagramBuilder()
    log = SignalLogger(builder, _signals(builder), 0.02)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.2)
    run = log.run_log(simulator.get_context())
    npz = run.save(tmp_path / "run")
    back = RunLog.load(npz)
    np.testing.assert_array_equal(back.time, run.time)
    assert back.columns == run.columns
    for name in run.signals:
        np.testing.assert_array_equal(back[name], run[name])
    table = np.loadtxt(tmp_path / "run.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 0], run.time, rtol=1e-8)
    np.testing.assert_allclose(table[:, 1:4], run["sine"], rtol=1e-8,
                               atol=1e-12)


def _robot_log(robot, period=0.05, duration=0.2):
    """The RunLog of a robot's arm standing at home: its measured and
    commanded positions, one entry a joint of the robot's description."""
    home = np.asarray(robot.arm.home, dtype=float)
    builder = DiagramBuilder()
    source = builder.AddSystem(ConstantVectorSource(home))
    log = SignalLogger(builder, {
        "arm.position_measured": source.get_output_port(),
        "arm.position_command": source.get_output_port()}, period)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    return log.run_log(simulator.get_context())


def test_a_seven_joint_arms_columns_are_one_a_joint(tmp_path):
    """The second shipped robot's seven joints: q1, ..., q7 in the log and
    in the CSV, whose header has as many fields as each row."""
    robot = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    n = robot.num_arm_joints
    assert n == 7
    run = _robot_log(robot)
    expected = tuple(f"q{i}" for i in range(1, n + 1))
    assert run.columns == {"arm.position_measured": expected,
                           "arm.position_command": expected}
    run.save(tmp_path / "run")
    lines = (tmp_path / "run.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header == ["time"] + [f"{signal}.{name}" for signal in run.columns
                                 for name in expected]
    assert {len(line.split(",")) for line in lines[1:]} == {len(header)}
    table = np.loadtxt(tmp_path / "run.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 1:1 + n], run["arm.position_measured"],
                               rtol=1e-8)


def test_an_lcm_logs_joint_columns_are_one_a_joint(tmp_path):
    """A seven-joint arm's status read from an LCM log: positions q1, ...,
    q7 and velocities v1, ..., v7."""
    import lcm

    from drake_wbc.deployment.lcm_logs import read_lcm_log
    from drake_wbc.hardware import messages
    from drake_wbc.hardware.options import HardwareOptions

    robot = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    n = robot.num_arm_joints
    home = np.asarray(robot.arm.home, dtype=float)
    path = tmp_path / "run.lcmlog"
    channel = HardwareOptions().channels.arm_status
    log = lcm.EventLog(str(path), "w", overwrite=True)
    for k in range(3):
        log.write_event(k * 10000, channel, messages.encode_arm_status(
            0.01 * k, home, np.zeros(n)))
    log.close()
    run = read_lcm_log(path)
    assert run["arm.position_measured"].shape[1] == n
    assert run.columns["arm.position_measured"] == tuple(
        f"q{i}" for i in range(1, n + 1))
    assert run.columns["arm.velocity_estimated"] == tuple(
        f"v{i}" for i in range(1, n + 1))


def test_an_lcm_log_skips_an_arm_message_of_another_joint_count(tmp_path):
    """One stray seven-joint arm status among a six-joint robot's: reading
    the log failed on it (numpy's "inhomogeneous shape"), where its
    docstring says bad messages are skipped. Decoded with the robot's
    joint count (that of most of its arm status messages), the stray one
    is skipped, as the robot and the controller refuse it; so is an arm
    command of another count."""
    import lcm

    from drake_wbc.deployment.lcm_logs import read_lcm_log
    from drake_wbc.hardware import messages
    from drake_wbc.hardware.options import HardwareOptions

    channels = HardwareOptions().channels
    path = tmp_path / "run.lcmlog"
    log = lcm.EventLog(str(path), "w", overwrite=True)
    for k in range(20):
        t = 1_000_000 + k * 10_000
        log.write_event(t, channels.arm_status, messages.encode_arm_status(
            t, np.full(6, 0.01 * k), np.zeros(6)))
        log.write_event(t, channels.arm_command, messages.encode_arm_command(
            t, np.full(6, 0.01 * k)))
        if k == 10:
            log.write_event(t + 1, channels.arm_status,
                            messages.encode_arm_status(t, np.ones(7),
                                                       np.ones(7)))
            log.write_event(t + 1, channels.arm_command,
                            messages.encode_arm_command(t, np.ones(7)))
    log.close()
    run = read_lcm_log(path)
    expected = np.repeat(0.01 * np.arange(20)[:, None], 6, axis=1)
    np.testing.assert_allclose(run["arm.position_measured"], expected)
    np.testing.assert_allclose(run["arm.position_command"], expected)


def test_an_lcm_log_keeps_the_commands_of_the_sender_obeyed(tmp_path):
    """A second sender's arm command in the middle of a controller's: the
    robot refused it (one sender at a time), the log read it as sent. Now
    only the commands of the sender the robot obeyed are: the first
    heard, until it has been quiet for sender_release_time, when the
    next one takes the channels."""
    import lcm

    from drake_wbc.deployment.lcm_logs import read_lcm_log
    from drake_wbc.hardware import messages
    from drake_wbc.hardware.options import HardwareOptions

    options = HardwareOptions()
    channels = options.channels
    path = tmp_path / "run.lcmlog"
    log = lcm.EventLog(str(path), "w", overwrite=True)
    for k in range(20):
        t = 1_000_000 + k * 10_000
        log.write_event(t, channels.arm_command, messages.encode_arm_command(
            t, np.zeros(6), sender=111))
        log.write_event(t, channels.base_command,
                        messages.encode_base_command(t, np.zeros(3),
                                                     sender=111))
        if k == 10:
            for channel, data in (
                    (channels.arm_command, messages.encode_arm_command(
                        t, np.ones(6), sender=222)),
                    (channels.base_command, messages.encode_base_command(
                        t, np.ones(3), sender=222))):
                log.write_event(t + 50, channel, data)
    # The first sender quiet for longer than the release time: the second
    # takes the channels.
    later = 1_190_000 + int(1e6 * options.sender_release_time) + 10_000
    log.write_event(later, channels.arm_command, messages.encode_arm_command(
        later, np.ones(6), sender=222))
    log.close()
    run = read_lcm_log(path)
    command = run["arm.position_command"]
    np.testing.assert_array_equal(command[:-1], 0.0)
    np.testing.assert_array_equal(command[-1], 1.0)
    np.testing.assert_array_equal(run["base.velocity_command"], 0.0)


def test_the_real_time_factor_reads_back(tmp_path):
    """save then load gives the run's real-time factor, and NaN back for
    a run that does not know it."""
    builder = DiagramBuilder()
    log = SignalLogger(builder, _signals(builder), 0.02)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.1)
    for factor in (2.5, np.nan):
        run = log.run_log(simulator.get_context(), real_time_factor=factor)
        back = RunLog.load(run.save(tmp_path / "run"))
        np.testing.assert_equal(back.real_time_factor, factor)


def test_names_that_do_not_fit_the_signal_are_refused():
    """A signal that SIGNALS names with a fixed tuple, logged from a port
    of another size, is refused rather than mislabelled."""
    from drake_wbc.controller.run_log import SIGNALS

    builder = DiagramBuilder()
    size = len(SIGNALS["alpha"]) + 1
    source = builder.AddSystem(ConstantVectorSource(np.zeros(size)))
    with pytest.raises(ValueError,
                       match=rf"SIGNALS\['alpha'\] = .* have {size} names"):
        SignalLogger(builder, {"alpha": source.get_output_port()}, 0.01)


@pytest.mark.parametrize("size", [1, 3])
def test_a_bases_passive_joints_are_one_column_a_joint(size):
    """A robot whose base has another number of passive joints than the
    shipped mount's roll and pitch (base.passive_joints: one pitch
    spring, or a suspension's three): its truth.mount_angles are logged
    one column a joint, passive1, ..., rather than refused (which stopped
    every run of that robot); the shipped two keep their names."""
    builder = DiagramBuilder()
    ports = {"truth.mount_angles": builder.AddSystem(ConstantVectorSource(
        np.zeros(size))).get_output_port()}
    log = SignalLogger(builder, ports, 0.01)
    assert log.columns["truth.mount_angles"] == tuple(
        f"passive{i}" for i in range(1, size + 1))
    ports["truth.mount_angles"] = builder.AddSystem(ConstantVectorSource(
        np.zeros(2))).get_output_port()
    assert SignalLogger(builder, ports, 0.01).columns[
        "truth.mount_angles"] == ("roll", "pitch")


@pytest.mark.parametrize("duration, chunk", [
    (47.0, 47.0 / 200), (11.0, 11.0 / 200), (0.1, 0.01), (1.0, 0.3),
    (0.005, 0.01), (0.0, 0.01)])
def test_a_run_advances_to_its_end_exactly(duration, chunk):
    """The chunks' ends are k chunk, the last the duration itself; summed
    instead, 200 chunks of 0.235 s end 8.5e-14 s short of 47 s (and
    ten of 0.01 s short of 0.1 s)."""
    times = list(advance_times(duration, chunk))
    assert times[-1] == duration
    assert all(np.diff(times) > 0.0)
    assert times[:-1] == [k * chunk for k in range(1, len(times))]
    assert len(times) == max(1, round(np.ceil(duration / chunk - 1e-9)))
    with pytest.raises(ValueError, match="chunk = 0.0 is not allowed"):
        advance_times(duration, 0.0)


def test_a_days_times_are_made_one_at_a_time():
    """A day in 0.01 s chunks is 8.6 million times: they were made as one
    list (about 300 MB) before the run's first step."""
    import itertools
    import tracemalloc

    tracing = tracemalloc.is_tracing()  # PYTHONTRACEMALLOC, say
    tracemalloc.start()
    tracemalloc.reset_peak()
    before = tracemalloc.get_traced_memory()[0]
    try:
        first = list(itertools.islice(advance_times(86400.0, 0.01), 3))
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        if not tracing:
            tracemalloc.stop()
    assert first == [0.01, 0.02, 0.03]
    assert peak < 1e6


def test_a_runs_log_holds_its_last_sample():
    """A 0.1 s run of a scenario logs its sample at 0.1 s (the run ended
    1.4e-17 s short of it, and the log at 0.09)."""
    from drake_wbc.experiments.runner import build_closed_loop, simulate
    from drake_wbc.experiments.scenario import find_scenario, load_scenario

    log = simulate(build_closed_loop(load_scenario(find_scenario(
        "trajectory_tracking"))), duration=0.1)
    assert log.time[-1] == pytest.approx(0.1, abs=1e-12)
    assert log.time.size == 11
