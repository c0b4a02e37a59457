"""`robot-sim` and `deploy` in two processes over real UDP multicast,
inside a private network namespace (multicast routed over its loopback,
so no packet leaves it), logged by the real `lcm-logger`: the run
reaches its end within the bounds the simulated run meets, Ctrl-C stops
a deployment cleanly, and `plot` draws the logged run."""

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import lcm
import numpy as np
import pytest

from drake_wbc.cli.hardware import INTERRUPTED
from drake_wbc.cli.main import main
from drake_wbc.deployment.lcm_logs import (
    deployments,
    read_events,
    read_lcm_log,
)
from drake_wbc.experiments import trajectory_tracking
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.hardware import messages
from drake_wbc.hardware.interface import DIAGNOSTICS
from drake_wbc.robot.model import ArmKinematics

URL = "udpm://239.255.76.67:7667?ttl=0"

FORGER = (
    "import time; import lcm; "
    "from drake_wbc.hardware.lcmtypes.drake_wbc_lcm import arm_command_t; "
    "bus = lcm.LCM('{url}'); m = arm_command_t(); m.sender = 42; "
    "m.num_joints = 6; m.position = [1.0, 0.55, 2.0, 1.0, 2.15, 1.0]; "
    "[(setattr(m, 'utime', int(time.time() * 1e6)), "
    "bus.publish('WBC_ARM_COMMAND', m.encode()), time.sleep(0.01)) "
    "for _ in range(30)]")
"""A second sender: 30 arm commands 1 rad from home, 100 Hz, sender 42."""

RATE = 1.0
"""The real-time rate of both processes: real time, as on the robot (the
robot side runs at about 8 times real time on this 2-core machine, the
controller at about 6)."""

LIMIT = 0.05
"""s: the watchdog limit of the 100 Hz streams in these runs."""


SCRIPT = """
ip link set lo up
ip route add 224.0.0.0/4 dev lo
cd {folder}
{logger} --quiet -l '{url}' -f run.lcmlog & LOGGER=$!
{python} -m drake_wbc.cli robot-sim scenario.yaml \\
    --realtime-rate {rate} > robot.out 2>&1 & ROBOT=$!
{python} -m drake_wbc.cli deploy scenario.yaml \\
    --realtime-rate {rate} > deploy.out 2>&1
echo $? > deploy.code
# Starts a deployment in the background (`deploy_running NAME ARGS`:
# its output in NAME.out, its process in $PID, its environment's
# additions in $DEPLOY_ENV) and returns once it runs.
deploy_running() {{
    name=$1
    shift
    env $DEPLOY_ENV {python} -m drake_wbc.cli deploy scenario.yaml "$@" \
        --realtime-rate {rate} > $name.out 2>&1 &
    PID=$!
    for i in $(seq 300); do
        grep -q running $name.out && break
        sleep 0.1
    done
}}
# A second deployment, stopped by SIGINT once it runs (the programs
# handle SIGINT themselves, which a background job of sh ignores), on
# Python's debug allocator, which aborts the process when anything
# allocates a Python object without holding the GIL (as a handler
# called by C++ inside Simulator.AdvanceTo would: Python 3.12 and later
# crash there).
DEPLOY_ENV=PYTHONMALLOC=debug
deploy_running stopped --duration 60
DEPLOY_ENV=
sleep 1
kill -INT $PID; wait $PID; echo $? > stopped.code
# A third deployment: while the base moves, the robot freezes for 0.3 s
# (SIGSTOP: every stream stops at once), and a second sender tries the
# command channels.
deploy_running frozen --duration 3
sleep 1.0
kill -STOP $ROBOT; sleep 0.3; kill -CONT $ROBOT
{python} -c "{forger}" > forger.out 2>&1
wait $PID; echo $? > frozen.code
# A fourth: while the base moves, the controller itself freezes for 0.4 s
# (its clock stands still, the robot's command timeout runs on).
deploy_running stalled --duration 3
sleep 1.0
kill -STOP $PID; sleep 0.4; kill -CONT $PID
wait $PID; echo $? > stalled.code
kill -INT $ROBOT; wait $ROBOT; echo $? > robot.code
kill -TERM $LOGGER; wait $LOGGER
"""


def _namespaces_allowed():
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return False, "unshare or ip is not installed"
    result = subprocess.run(
        ["unshare", "-n", "sh", "-c",
         "ip link set lo up && ip route add 224.0.0.0/4 dev lo"],
        capture_output=True, text=True)
    if result.returncode != 0:
        return False, ("private network namespaces are not permitted here "
                       f"(unshare -n: {result.stderr.strip()})")
    return True, ""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    allowed, reason = _namespaces_allowed()
    if not allowed:
        pytest.skip(reason)
    folder = tmp_path_factory.mktemp("processes")
    # The hardware scenario, shortened: at rest until 0.5 s, the step
    # until 2.0 s.
    text = find_scenario("hardware").read_text()
    text = text.replace("duration: 4.0", "duration: 2.0").replace(
        "times: [0.0, 1.0, 2.5]", "times: [0.0, 0.5, 1.6]")
    # Five periods of the 100 Hz streams, not three, and the LIDAR's at
    # the robot's command timeout: on this 2-core machine shared with other
    # work a process may miss the processor for 20 ms, and each stop holds
    # the robot for a second.
    for name in ("base_state", "arm_status", "wrist_wrench"):
        text = text.replace(f"    {name}: 0.03", f"    {name}: {LIMIT}")
    text = text.replace("    obstacle_points: 0.2 ",
                        "    obstacle_points: 0.25 ")
    (folder / "scenario.yaml").write_text(text)
    # lcm-logger itself, not pip's wrapper script (which would not pass
    # the signal on).
    logger = Path(lcm.LCM_BIN_DIR) / "lcm-logger"
    script = SCRIPT.format(folder=folder, logger=logger,
                           python=sys.executable, url=URL, rate=RATE,
                           forger=FORGER.format(url=URL))
    process = subprocess.Popen(["unshare", "-n", "sh", "-c", script],
                               start_new_session=True)
    try:
        assert process.wait(timeout=240) == 0
    finally:
        if process.poll() is None:  # hung: end the whole session
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    names = ("robot", "deploy", "stopped", "frozen", "stalled")
    outputs = {name: (folder / f"{name}.out").read_text() for name in names}
    codes = {name: int((folder / f"{name}.code").read_text())
             for name in names}
    print(outputs)
    return dict(folder=folder, outputs=outputs, codes=codes,
                scenario=load_scenario(folder / "scenario.yaml"))


def test_the_run_reaches_its_end_within_the_simulated_bounds(run):
    assert run["codes"]["deploy"] == 0, run["outputs"]["deploy"]
    assert "finished at t = 2.00 s" in run["outputs"]["deploy"]
    assert "rejected 0" in run["outputs"]["deploy"]
    # A progress line while it runs (the run said nothing between its
    # start and its end).
    assert "deploy filtered: [" in run["outputs"]["deploy"]
    assert "2.00 / 2.00 s run, real-time factor" in run["outputs"]["deploy"]
    scenario = run["scenario"]
    log = read_lcm_log(run["folder"] / "run.lcmlog", scenario.hardware)
    assert log.time[-1] == pytest.approx(scenario.duration)
    for name in ("truth.end_effector_velocity", "base.velocity_command",
                 "capability", "arm.position_measured"):
        assert np.all(np.isfinite(log[name])), name
    # The bound of tests/test_experiment_trajectory_tracking.py on the
    # simulated run: the end effector tracks the step once settled (the
    # in-process simulation of this scenario: 0.0955 m/s here).
    late = (log.time > 1.3) & (log.time < 1.6)
    v = log["truth.end_effector_velocity"][late, 0]
    metrics = trajectory_tracking.compute_metrics(scenario, {"run": log})
    print(f"late mean V_ee x {np.mean(v):.4f} m/s; {metrics}")
    # Two processes on unsynchronised real-time clocks: on a busy machine
    # a late status or command shifts the step's transient into the window
    # (0.085 and 0.144 m/s seen at load 7), so the window's mean is held
    # to half the step either way; the in-process run of the same scenario
    # (tests/test_experiment_trajectory_tracking.py) holds it to 0.01.
    assert np.mean(v) == pytest.approx(0.1, abs=0.05)
    # The error in the base's band: 5.2 mm/s in the in-process simulation
    # of this scenario; the two unsynchronised real-time clocks add some,
    # the more the busier the machine (10.8, 14.4 and 16.3 mm/s seen, the
    # first on the code before the people tracking too), while a
    # controller that does not track the step is off by the step's 0.1 m/s.
    assert metrics["run.error_rms_base_band_m_s"] < 5 * 0.0052
    # And on the base's command: the filter of eq. (filtering) rises no
    # faster than omega_f / e per unit step; here, as sent, message by
    # message.
    h = scenario.controller.time_step
    omega_f = scenario.controller.base_filter.omega_f
    events = read_events(run["folder"] / "run.lcmlog")
    stamps = np.array([stamp for stamp, _ in events["WBC_CONTROLLER"]])
    times = [messages.decode_signal_bundle(data)[1]
             for _, data in events["WBC_CONTROLLER"]]
    end = stamps[deployments(times)[0]][-1]  # the first run's last tick
    sent = np.array([messages.decode_base_command(data).values[0]
                     for stamp, data in events["WBC_BASE_COMMAND"]
                     if stamp <= end])
    slope = np.abs(np.diff(sent[:, 0]))
    assert len(slope) > 150
    assert np.max(slope) <= 0.05 * omega_f / np.e * h * 1.01


def test_ctrl_c_stops_the_robot_first(run):
    assert run["codes"]["stopped"] == INTERRUPTED, run["outputs"]["stopped"]
    assert "stopped at t =" in run["outputs"]["stopped"]
    assert "sent zero base velocity and held the arm" in \
        run["outputs"]["stopped"]
    assert run["codes"]["robot"] == INTERRUPTED
    events = read_events(run["folder"] / "run.lcmlog")
    base = [messages.decode_base_command(data).values[0]
            for _, data in events["WBC_BASE_COMMAND"]]
    arm = [messages.decode_arm_command(data).values[0]
           for _, data in events["WBC_ARM_COMMAND"]]
    # The stop: zero base velocity, the arm's last command repeated.
    np.testing.assert_array_equal(base[-3:], 0.0)
    for command in arm[-3:]:
        np.testing.assert_array_equal(command, arm[-4])


def test_plot_draws_the_logged_run(run, capsys):
    folder = run["folder"]
    code = main(["plot", str(folder / "run.lcmlog"), "--scenario",
                 str(folder / "scenario.yaml"), "--output",
                 str(folder / "plot")])
    assert code == 0
    capsys.readouterr()
    for name in ("trajectory_tracking.png", "hardware.png"):
        assert (folder / "plot" / name).stat().st_size > 10_000


def test_teach_learns_from_the_logged_run(run, tmp_path):
    """Teaching from the robot: `drake-wbc teach --log` learns the logged
    run's end-effector motion (here the tracking step, between markers
    given by hand), from the measured joints and odometry in the log."""
    from drake_wbc.math.demonstration import tcp_poses
    from drake_wbc.math.movement import LearnedMovement

    folder = run["folder"]
    file = tmp_path / "movement.yaml"
    code = main(["teach", str(folder / "scenario.yaml"), "--log",
                 str(folder / "run.lcmlog"), "--start", "0.3", "--stop",
                 "1.9", "--output", str(tmp_path), "--movement", str(file)])
    assert code == 0
    movement = LearnedMovement.load(file)
    log = read_lcm_log(folder / "run.lcmlog", run["scenario"].hardware)
    pose = tcp_poses(log["base.state_estimated"][:, :3],
                     log["arm.position_measured"], ArmKinematics())
    for when, learned in ((0.3, movement.start), (1.9, movement.goal)):
        index = np.searchsorted(log.time, when)
        np.testing.assert_allclose(learned, pose[index], atol=2e-3)
    # The step moved the end effector about 0.1 m along x in 1.1 s.
    assert movement.goal[0] - movement.start[0] == pytest.approx(0.11,
                                                                 abs=0.03)


WATCHED = ("WBC_BASE_STATE", "WBC_ARM_STATUS", "WBC_WRIST_WRENCH")
"""The robot's 100 Hz streams, each of which stops everything when
stale."""


@pytest.fixture(scope="module")
def frozen(run):
    """The third deployment's messages, on the logger's clock: the robot
    froze for 0.3 s while its base moved."""
    events = read_events(run["folder"] / "run.lcmlog")
    stamps = np.array([stamp for stamp, _ in events["WBC_CONTROLLER"]])
    times = [messages.decode_signal_bundle(data)[1]
             for _, data in events["WBC_CONTROLLER"]]
    window = stamps[deployments(times)[2]]
    start, end = window[0], window[-1]

    def inside(channel):
        return [(t, data) for t, data in events[channel] if start <= t <= end]

    status = {name: np.array([t for t, _ in inside(name)])
              for name in WATCHED}
    gaps = np.diff(status["WBC_BASE_STATE"])
    assert np.max(gaps) > 0.25, "the robot did not freeze"
    freeze = status["WBC_BASE_STATE"][np.argmax(gaps)]
    # The last status of the stream that fell silent first.
    last = min(t[t <= freeze + 0.02].max() for t in status.values())
    arm = [(t, messages.decode_arm_command(data))
           for t, data in inside("WBC_ARM_COMMAND")]
    controller = arm[0][1].sender
    # (logger's time, velocity, how far the controller's stamp is behind
    # the logger's time), of the controller's base commands.
    base = [(t, decoded.values[0], t - 1e-6 * decoded.utime)
            for t, decoded in ((t, messages.decode_base_command(data))
                               for t, data in inside("WBC_BASE_COMMAND"))
            if decoded.sender == controller]
    return dict(last=last, base=base, arm=arm, controller=controller,
                events=events, start=start, end=end)


def test_the_watchdog_stops_the_base_on_the_wire_within_its_limit(frozen,
                                                                  run):
    """The watchdog's latency, from the robot's last status to the first
    zero base command: on the controller's clock the watchdog limit, a
    check (1 ms) to see it and one to send it (the promise of
    drake_wbc/hardware/README.md), as the wire tells it: the command's
    stamp and the status's reception (WBC_CONTROLLER's time less the
    stream's age in `hardware.diagnostics`), both on the controller's
    clock. On the logger's clock, the same plus what the machine took
    from the controller's process meanwhile."""
    limit = run["scenario"].hardware.watchdog_limits.base_state
    last = frozen["last"]
    # The base moving when the status froze, so that the first zero
    # command after it is the watchdog's. (Not every command of the 0.1 s
    # before: on a loaded machine a late status may trip the watchdog
    # there once, and the command resumes from rest before the freeze.)
    before = [v for t, v, _ in frozen["base"] if t <= last]
    assert before and np.any(before[-1]), "the base was still"
    t_zero, stamp = next((t, t - lag) for t, v, lag in frozen["base"]
                         if t > last and not np.any(v))
    column = {name: i for i, name in enumerate(DIAGNOSTICS)}
    bundles = []
    for t, data in frozen["events"]["WBC_CONTROLLER"]:
        utime, time, signals = messages.decode_signal_bundle(data)
        if frozen["start"] <= t <= frozen["end"]:
            bundles.append((utime * 1e-6 - time, time,
                            signals["hardware.diagnostics"]))
    offset = bundles[0][0]
    zero = stamp - offset  # on the controller's clock
    _, time, diagnostics = max((b for b in bundles if b[1] <= zero),
                               key=lambda b: b[1])
    received = min(time - diagnostics[column[f"{name}_age"]]
                   for name in ("base_state", "arm_status", "wrist_wrench"))
    latency = zero - received
    on_the_wire = t_zero - last
    print(f"watchdog latency: {latency * 1e3:.1f} ms on the controller's "
          f"clock, {on_the_wire * 1e3:.1f} ms on the wire")
    # Both ends are read from time stamps in whole microseconds (the
    # messages' utime), each off by up to 1 us: 52.00106 ms was seen.
    assert limit < latency <= limit + 0.002 + 2e-6
    # The logger stamps both messages on arrival, in a third process: on a
    # busy machine the statuses reach it late, bunched (49.95 and 25.0 ms
    # seen at load 2 to 7, with 51.0 ms on the controller's clock), so its
    # clock shows only that the stop is not grossly early; the controller's
    # clock above is the exact check.
    assert on_the_wire > 0.5 * limit
    assert "watchdog tripped" in run["outputs"]["frozen"]
    assert "watchdog cleared" in run["outputs"]["frozen"]


def test_no_command_jumps_after_the_trip(frozen, run):
    """After the robot came back, the commands resumed from what was sent
    last, within the acceleration limits, message by message: the base's
    1 m/s^2 and the joints' 12.56 rad/s^2 (a stop to zero is the one step
    the base's command may take)."""
    h = run["scenario"].hardware.publish_period
    velocity = np.array([v for t, v, _ in frozen["base"]
                         if t > frozen["last"]])
    steps = np.abs(np.diff(velocity, axis=0))
    rising = np.any(steps > 0, axis=1) & np.any(velocity[1:] != 0, axis=1)
    largest = np.max(steps[rising]) if rising.any() else 0.0
    print(f"largest base command step after the trip: {largest:.5f} m/s")
    assert largest <= 1.0 * h + 1e-9
    arm = np.array([d.values[0] for t, d in frozen["arm"]
                    if d.sender == frozen["controller"]])
    acceleration = np.abs(np.diff(arm, 2, axis=0)) / h**2
    print(f"largest joint acceleration: {np.max(acceleration):.3f} rad/s^2")
    assert np.max(acceleration) <= 12.56 + 1e-6


def test_a_controller_that_misses_the_processor_stops_the_robot(run):
    """The fourth deployment's controller froze for 0.4 s while its base
    moved: its clock stood still, and the robot's own command timeout
    stopped the base. Its first base command after the freeze is zero, not
    the speed it had before (a step for a robot at rest), it says why, and
    the commands resume from rest within the acceleration limits."""
    h = run["scenario"].hardware.publish_period
    events = read_events(run["folder"] / "run.lcmlog")
    times = [messages.decode_signal_bundle(data)[1]
             for _, data in events["WBC_CONTROLLER"]]
    stamps = np.array([stamp for stamp, _ in events["WBC_CONTROLLER"]])
    window = stamps[deployments(times)[3]]
    base = [(t, messages.decode_base_command(data).values[0])
            for t, data in events["WBC_BASE_COMMAND"]
            if window[0] <= t <= window[-1]]
    sent = np.array([t for t, _ in base])
    velocity = np.array([v for _, v in base])
    gap = int(np.argmax(np.diff(sent)))
    assert sent[gap + 1] - sent[gap] > 0.3, "the controller did not freeze"
    assert np.any(velocity[gap]), "the base was still"
    np.testing.assert_array_equal(velocity[gap + 1], 0.0)
    after = velocity[gap + 1:]
    steps = np.abs(np.diff(after, axis=0))
    assert np.all(steps <= 1.0 * h + 1e-9)
    assert np.any(after[-1]), "the commands did not resume"
    output = run["outputs"]["stalled"]
    assert "of wall clock passed since the last check" in output
    assert "watchdog cleared" in output
    assert run["codes"]["stalled"] == 0


def test_the_robot_refuses_a_second_sender(frozen, run):
    """A second sender's arm commands (joint 1 at 1 rad) were refused by
    the robot, which kept obeying its controller: its joint 1, which the
    tracking task leaves at 0, never moved."""
    senders = {d.sender for _, d in frozen["arm"]}
    assert 42 in senders and len(senders) == 2
    assert "refused" in run["outputs"]["robot"]
    positions = np.array([
        messages.decode_arm_status(data).values[0]
        for t, data in frozen["events"]["WBC_ARM_STATUS"]
        if frozen["start"] <= t <= frozen["end"] + 0.5])
    print(f"joint 1 within {np.max(np.abs(positions[:, 0])):.2e} rad of 0")
    assert np.max(np.abs(positions[:, 0])) < 0.01
    assert run["codes"]["frozen"] == 0, run["outputs"]["frozen"]


FLOOD = """
import json
import sys
import time

import numpy as np
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_wbc.hardware import messages
from drake_wbc.hardware.interface import DIAGNOSTICS, HardwareInterface
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.robot.model import HOME_ARM_POSITIONS as HOME

URL = "udpm://239.255.76.67:7667?ttl=0"
lcm, robot = DrakeLcm(URL), DrakeLcm(URL)
builder = DiagramBuilder()
hw = HardwareInterface(HardwareOptions(lcm_url=URL), lcm, HOME)
builder.AddSystem(hw.diagram)
for port, value in (("base.velocity_command", np.zeros(3)),
                    ("arm.position_command", HOME)):
    source = builder.AddSystem(ConstantVectorSource(value))
    builder.Connect(source.get_output_port(), hw.diagram.GetInputPort(port))
simulator = Simulator(builder.Build())
root = simulator.get_mutable_context()
simulator.Initialize()
garbage = int(sys.argv[1])
for k in range(100):
    utime = k * 10_000
    for data in ([b"garbage"] * garbage
                 + [messages.encode_base_state(utime, np.zeros(6))]
                 + [b"garbage"] * garbage):
        robot.Publish("WBC_BASE_STATE", data)
    robot.Publish("WBC_ARM_STATUS", messages.encode_arm_status(
        utime, HOME, np.zeros(6)))
    robot.Publish("WBC_WRIST_WRENCH", messages.encode_wrench(
        utime, np.zeros(6)))
    if k % 6 == 0:
        robot.Publish("WBC_OBSTACLE_POINTS", messages.encode_obstacle_points(
            utime, np.zeros((0, 2))))
    time.sleep(0.002)  # all of it on the wire before the next step
    simulator.AdvanceTo((k + 1) * 0.01)
values = hw.diagram.GetOutputPort("hardware.diagnostics").Eval(
    hw.diagram.GetMyContextFromRoot(root))
print(json.dumps(dict(zip(DIAGNOSTICS, values.tolist()))))
"""
"""The hardware interface over UDP multicast, the script playing the
robot: 10 garbage messages on WBC_BASE_STATE before and after each
genuine one, every control period for 1 s; prints the diagnostics."""


def test_a_flood_over_udp_hides_no_genuine_message(tmp_path):
    """Over real UDP multicast DrakeLcm keeps one message a subscription
    between two polls, the oldest: in a flood the genuine base state was
    never seen, and the robot never started. The receivers keep every
    message (QueuedLcm): all garbage is rejected, every genuine message
    taken."""
    allowed, reason = _namespaces_allowed()
    if not allowed:
        pytest.skip(reason)
    (tmp_path / "flood.py").write_text(FLOOD)
    result = subprocess.run(
        ["unshare", "-n", "sh", "-c",
         "ip link set lo up; ip route add 224.0.0.0/4 dev lo; "
         f"{sys.executable} {tmp_path / 'flood.py'} 10"],
        capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    diagnostics = json.loads(result.stdout.strip().splitlines()[-1])
    print(diagnostics)
    assert diagnostics["watchdog_trips"] == 0
    assert diagnostics["watchdog_tripped"] == 0
    assert diagnostics["base_state_rejected"] == 2000
    assert diagnostics["base_state_age"] <= 0.01 + 1e-9
