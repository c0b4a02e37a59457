"""The controller over LCM against the simulated robot in one Diagram
(memq://, simulated time) reproduces the in-process simulation, and
`drake-wbc plot` draws the run from a log of its messages."""

import json

import lcm
import numpy as np
import pytest
from pydrake.systems.framework import PortDataType

from drake_wbc.cli.main import main
from drake_wbc.controller.diagram import STATION_INPUTS
from drake_wbc.deployment.lcm_logs import read_lcm_log
from drake_wbc.deployment.loopback import (
    build_loopback,
    make_simulator,
    simulate_loopback,
)
from drake_wbc.experiments import trajectory_tracking
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.hardware import messages
from drake_wbc.hardware.interface import DIAGNOSTICS, HardwareInterface
from drake_wbc.math.safety import STATUS_FIELDS

DURATION = 2.5
"""s: the robot at rest, then 1.5 s of the 0.1 m/s step."""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    scenario = load_scenario(find_scenario("trajectory_tracking"))
    scenario.duration = DURATION
    variant = scenario.variants[0]  # with the base filter
    loop = build_loopback(scenario, variant)
    simulator = make_simulator(loop)
    root = simulator.get_context()
    path = tmp_path_factory.mktemp("lcm") / "run.lcmlog"
    event_log = lcm.EventLog(str(path), "w", overwrite=True)
    # Every message, stamped with the simulated time at its reception,
    # as lcm-logger would with the wall clock.
    loop.lcm.SubscribeAllChannels(lambda channel, data: event_log.write_event(
        int(round(root.get_time() * 1e6)), channel, data))
    over_lcm = simulate_loopback(loop, simulator=simulator)
    event_log.close()
    in_process = simulate(build_closed_loop(scenario, variant))
    return dict(scenario=scenario, loop=loop, over_lcm=over_lcm,
                in_process=in_process, path=path,
                folder=tmp_path_factory.mktemp("plot"))


def test_the_interface_offers_the_stations_ports(runs):
    station = runs["loop"].robot.station.diagram
    hardware = runs["loop"].side.hardware.diagram
    assert isinstance(runs["loop"].side.hardware, HardwareInterface)
    for name in STATION_INPUTS + ("arm.velocity_estimated",):
        ours, theirs = hardware.GetOutputPort(name), station.GetOutputPort(
            name)
        assert ours.get_data_type() == theirs.get_data_type(), name
        if ours.get_data_type() == PortDataType.kVectorValued:
            assert ours.size() == theirs.size(), name
        else:
            assert type(ours.Allocate().get_value()) is type(
                theirs.Allocate().get_value()), name
    for name in ("base.velocity_command", "arm.position_command"):
        assert (hardware.GetInputPort(name).size()
                == station.GetInputPort(name).size())


def test_the_run_over_lcm_reproduces_the_simulation(runs):
    over_lcm, in_process = runs["over_lcm"], runs["in_process"]
    # Neither arm faulted (the robot side's behind its limiter).
    assert over_lcm.arm_fault == in_process.arm_fault == "none"
    h = runs["scenario"].controller.time_step
    n = min(len(over_lcm.time), len(in_process.time))
    np.testing.assert_allclose(over_lcm.time[:n], in_process.time[:n])
    path = over_lcm["truth.end_effector_pose"][:n, :3]
    reference = in_process["truth.end_effector_pose"][:n, :3]
    speed = np.linalg.norm(
        in_process["truth.end_effector_velocity"][:n, :3], axis=1)
    # Over LCM the controller reads each status up to one control period
    # late (the robot sends it at the tick, the controller's update at
    # the same tick has already run) and the base receives its command
    # publish_offset later; the arm's command reaches the arm's driver
    # before it samples, as in process. Were the whole motion one
    # control period late, the path would differ by max |V_ee| h at most.
    tolerance = np.max(speed) * h
    error = np.max(np.linalg.norm(path - reference, axis=1))
    print(f"end effector path: largest difference {error * 1e3:.3f} mm, "
          f"tolerance {tolerance * 1e3:.3f} mm, travel "
          f"{np.linalg.norm(reference[-1] - reference[0]) * 1e3:.1f} mm")
    assert np.linalg.norm(reference[-1] - reference[0]) > 0.1
    assert error < tolerance
    # The commands sent are the controller's (nothing was limited).
    diagnostics = dict(zip(DIAGNOSTICS, over_lcm["hardware.diagnostics"].T,
                           strict=True))
    for name in ("watchdog_trips", "base_command_saturated",
                 "arm_command_saturated", "invalid_commands"):
        assert np.all(diagnostics[name] == 0.0), name
    for name in ("base_state", "arm_status", "wrist_wrench",
                 "obstacle_points"):
        assert np.all(diagnostics[f"{name}_rejected"] == 0.0), name
    status_period = runs["loop"].side.options.status_period
    assert np.all(diagnostics["base_state_age"][1:]
                  <= status_period + 1e-9)


def test_plot_draws_the_run_from_its_lcm_log(runs, capsys):
    scenario, folder = runs["scenario"], runs["folder"]
    log = read_lcm_log(runs["path"])
    over_lcm = runs["over_lcm"]
    # On the controller's clock, each signal as the loggers sampled it.
    n = min(len(log.time), len(over_lcm.time))
    np.testing.assert_allclose(log.time[:n], over_lcm.time[:n], atol=1e-9)
    for name in ("truth.end_effector_pose", "base.state_estimated",
                 "capability", "reference_velocity"):
        np.testing.assert_allclose(log[name][1:n], over_lcm[name][1:n],
                                   atol=1e-9, err_msg=name)
    ours = trajectory_tracking.compute_metrics(scenario, {"filtered": log})
    theirs = trajectory_tracking.compute_metrics(
        scenario, {"filtered": over_lcm})
    for key, value in theirs.items():
        assert ours[key] == pytest.approx(value, rel=0.02, abs=1e-4), key

    scenario_file = folder / "tracking.yaml"
    text = find_scenario("trajectory_tracking").read_text()
    scenario_file.write_text(text.replace("duration: 4.0", "duration: 2.5"))
    code = main(["plot", str(runs["path"]), "--scenario", str(scenario_file),
                 "--output", str(folder / "out")])
    assert code == 0
    written = capsys.readouterr().out.strip().splitlines()[-1]
    assert "trajectory_tracking.png" in written
    # The last line names every file written.
    assert sorted(written.split(": ", 1)[1].split(", ")) == sorted(
        path.name for path in (folder / "out").iterdir())
    for name in ("trajectory_tracking.png", "hardware.png"):
        assert (folder / "out" / name).stat().st_size > 10_000
    assert (folder / "out" / "log_filtered.npz").is_file()
    assert main(["plot", str(runs["path"]), "--output",
                 str(folder / "generic")]) == 0
    assert (folder / "generic" / "overview_run.png").is_file()


def test_plot_computes_the_metrics_on_the_robot_that_ran(tmp_path, capsys):
    """A deployment of the second shipped robot (seven joints, given as
    --robot, as `deploy --robot` would): `plot --robot` computes the
    metrics on that arm; without it the command says that the log's arm
    is not the scenario's robot's and what to give."""
    from drake_wbc.experiments.scenario import with_robot
    from drake_wbc.robot.description import models_dir

    robot = models_dir() / "lbr_omni.robot.yaml"
    scenario = with_robot(load_scenario(find_scenario("trajectory_tracking")),
                          robot, echo=None)
    scenario.duration = DURATION
    loop = build_loopback(scenario, scenario.variants[0])
    simulator = make_simulator(loop)
    root = simulator.get_context()
    path = tmp_path / "run.lcmlog"
    event_log = lcm.EventLog(str(path), "w", overwrite=True)
    loop.lcm.SubscribeAllChannels(lambda channel, data: event_log.write_event(
        int(round(root.get_time() * 1e6)), channel, data))
    simulate_loopback(loop, simulator=simulator)
    event_log.close()
    assert main(["plot", str(path), "--scenario", "trajectory_tracking",
                 "--robot", str(robot), "--output",
                 str(tmp_path / "out")]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    margin = summary["runs"]["filtered"]["min_joint_limit_margin_rad"]
    assert 0.0 < margin < np.pi
    capsys.readouterr()
    assert main(["plot", str(path), "--scenario", "trajectory_tracking",
                 "--output", str(tmp_path / "shipped")]) != 0
    assert ("its robot mcr's arm has 6 joints, the log's 7; give the robot "
            "that ran (drake-wbc plot --robot FILE)") in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--scenario", "trajectory_tracking", "--variant", "nosuch"],
     "--variant = 'nosuch' is not allowed: must be one of filtered, "
     "unfiltered"),
    (["--deployment", "3"], "--deployment = 3 is not allowed: the log holds "
     "1 run(s) of the controller clock")])
def test_plot_names_its_options_as_typed(runs, extra, message, tmp_path,
                                         capsys):
    assert main(["plot", str(runs["path"]), *extra, "--output",
                 str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith(f"drake-wbc plot: {message}")


def test_a_forged_wrench_beyond_the_sensors_range_stops_the_robot(caplog):
    """A forged (or broken) wrist message of 1e30 N, finite and stamped
    in sequence with the genuine ones, went through the interface's
    decoder and the controller's guard as a real force. Over LCM, against
    the simulated robot: the controller stops safely and names it (the
    base sent zero, the arm braking within its acceleration limits), and
    resumes from rest within the limits once the genuine readings have
    been valid for the hold time."""
    scenario = load_scenario(find_scenario("trajectory_tracking"))
    loop = build_loopback(scenario, scenario.variants[0])
    simulator = make_simulator(loop)
    root = simulator.get_context()
    channel = loop.side.options.channels.wrist_wrench
    genuine = []
    loop.lcm.Subscribe(channel, lambda data: genuine.append(
        messages.decode_wrench(data)))
    simulator.Initialize()
    simulator.AdvanceTo(1.0)
    assert loop.side.controller.safety_reason(root) == ""
    # For 20 ms, each millisecond a message 1 us after the robot's last.
    for k in range(1, 21):
        last = max(m.utime for m in genuine if m.values[0][2] < 1e3)
        loop.lcm.Publish(channel, messages.encode_wrench(
            last + 1, [0.0, 0.0, 1e30, 0.0, 0.0, 0.0]))
        simulator.AdvanceTo(1.0 + 1e-3 * k)
    simulator.AdvanceTo(1.05)
    assert ("wrist.wrench_measured[2] = 1e+30 is out of the range"
            in loop.side.controller.safety_reason(root))
    simulator.AdvanceTo(2.5)
    loop.lcm.HandleSubscriptions(0)
    log = loop.logger.run_log(root, 1.0)
    status = log["safety_status"]
    stopped = status[:, STATUS_FIELDS.index("stopped")] == 1.0
    assert stopped.any() and not stopped[-1]
    assert status[-1, STATUS_FIELDS.index("trips")] == 1.0
    base, arm = log["base.velocity_command"], log["arm.position_command"]
    h = scenario.controller.time_step
    tripped = int(np.flatnonzero(stopped)[0])
    # Sent: zero at the stop, from rest within the acceleration limits
    # after it; the arm within its acceleration limit throughout.
    np.testing.assert_array_equal(base[tripped + 1:][stopped[
        tripped + 1:]], 0.0)
    limits = loop.side.hardware.systems["guard"].limits
    steps = np.abs(np.diff(base[tripped + 1:], axis=0)) / h
    assert np.all(steps <= limits.base_acceleration * (1.0 + 1e-9))
    acceleration = np.abs(np.diff(arm, 2, axis=0)) / h ** 2
    assert np.all(acceleration <= limits.joint_acceleration * (1.0 + 1e-9))


ON_THE_DEBUG_ALLOCATOR = """
from drake_wbc.deployment.loopback import build_loopback, simulate_loopback
from drake_wbc.experiments.scenario import find_scenario, load_scenario

loop = build_loopback(load_scenario(find_scenario("hardware")))
print(simulate_loopback(loop, 0.1).time[-1])
"""
"""A short loopback run: every message on memq:// reaches a receiver's
Python handler, while the Simulator advances."""


def test_no_message_is_handled_without_the_gil():
    """pydrake's LcmInterfaceSystem calls the Python handlers subscribed
    on a DrakeLcm from Simulator.AdvanceTo, which has released the GIL,
    and its binding makes each message's bytes object before taking the
    GIL back: Python 3.12 and later crashed there (a segmentation fault
    at the first message), 3.11 allocated without the GIL. Python's
    debug allocator aborts the process on such an allocation; the
    receivers are pumped from Python (LcmPump)."""
    import os
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-c", ON_THE_DEBUG_ALLOCATOR], capture_output=True,
        text=True, timeout=300, env={**os.environ, "PYTHONMALLOC": "debug"})
    assert done.returncode == 0, done.stderr[-2000:]
    assert float(done.stdout.strip().splitlines()[-1]) == pytest.approx(0.1)


def _flat_names(diagram):
    """The names of a Diagram's leaf systems, in the order the Diagram
    updates them (the order they were added, sub-diagrams in place)."""
    names = []
    for system in diagram.GetSystems():
        inner = getattr(system, "GetSystems", None)
        names += ([f"{system.get_name()}/{name}"
                   for name in _flat_names(system)] if inner
                  else [system.get_name()])
    return names


def test_the_pump_delivers_before_any_receiver_takes_in():
    """LcmPump delivers at the start of a step, as a per-step update in
    the Diagram's order: a receiver updated before it would take every
    message a step late. In the loopback, the controller side's pump
    serves both sides; a robot side alone has its own."""
    from pydrake.lcm import DrakeLcm

    from drake_wbc.deployment.robot_side import RobotSide

    scenario = load_scenario(find_scenario("hardware"))
    receivers = ("decoder.", "commands")
    for diagram in (build_loopback(scenario).diagram,
                    RobotSide(scenario, lcm=DrakeLcm("memq://")).diagram):
        names = _flat_names(diagram)
        pumps = [i for i, name in enumerate(names)
                 if name.rsplit("/", 1)[-1] == "pump"]
        taking = [i for i, name in enumerate(names)
                  if name.rsplit("/", 1)[-1].startswith(receivers)]
        assert len(pumps) == 1 and taking, names
        assert pumps[0] < min(taking), names
