"""Running a scenario: the controller against the simulated station.

`build_closed_loop` wires one run of a scenario into a Diagram (station,
controller, task inputs, logs, optionally the Meshcat replay);
`simulate` runs it with Drake's Simulator and returns its logs. The
command line's `drake-wbc run` goes through `run_scenario`
(drake_wbc.experiments.reports), which adds metrics, plots and files.

    scenario = load_scenario(find_scenario("trajectory_tracking"))
    log = simulate(build_closed_loop(scenario, scenario.variants[0]))
    log["truth.end_effector_velocity"]   # (N, 6)
"""

import copy
import sys
import time as wall_clock
from dataclasses import dataclass

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    LogVectorOutput,
    Multiplexer,
    TrajectorySource,
)
from pydrake.trajectories import PiecewisePolynomial

from drake_wbc.controller import build_controller
from drake_wbc.controller.diagram import STATION_INPUTS
from drake_wbc.experiments.scenario import TASK_SIZES, Scenario, Variant
from drake_wbc.math.safety import STATUS_FIELDS
from drake_wbc.math.validation import checked_instance
from drake_wbc.station.simulation import SimulatedStation

SIGNALS = {
    # station: what the robot's sensors report
    "base.state_estimated": ("x", "y", "yaw", "vx", "vy", "wz"),
    "arm.position_measured": tuple(f"q{i}" for i in range(1, 7)),
    "wrist.wrench_measured": ("fx", "fy", "fz", "tx", "ty", "tz"),
    # station: ground truth, for metrics
    "truth.end_effector_pose": ("x", "y", "z", "roll", "pitch", "yaw"),
    "truth.end_effector_velocity": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "truth.base_pose": ("x", "y", "yaw"),
    "truth.base_loop_velocity": ("vx", "vy", "wz"),
    "truth.mount_angles": ("roll", "pitch"),
    "truth.wrist_wrench": ("fx", "fy", "fz", "tx", "ty", "tz"),
    "truth.hand_force": ("fx", "fy", "fz", "tx", "ty", "tz"),
    "truth.people_positions": None,  # x0, y0, x1, y1, ...
    # controller: commands and diagnostics
    "base.velocity_command": ("vx", "vy", "wz"),
    "arm.position_command": tuple(f"q{i}" for i in range(1, 7)),
    "capability": ("C_m",),
    "alpha": ("alpha",),
    "sigma_xy": ("sigma_xy",),
    "sigma_phi": ("sigma_phi",),
    "end_effector_deviation": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "base_velocity": ("vx", "vy", "wz"),
    "filtered_base_velocity": ("vx", "vy", "wz"),
    "arm_velocity_command": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "arm_limited": ("limited",),
    "base_saturation": ("limited", "velocity_scale", "acceleration_scale"),
    "safety_status": STATUS_FIELDS,
    # task
    "reference_velocity": ("vx", "vy", "vz", "wx", "wy", "wz"),
}
"""The logged signals and the names of their columns."""


@dataclass
class ClosedLoop:
    """One run, built: the Diagram and its parts.

    Attributes:
        diagram: station, controller, task sources and the logger.
        station: the SimulatedStation.
        controller: the drake_wbc.controller.diagram.Controller.
        logger: the SignalLogger of SIGNALS.
        scenario, variant: what it was built from.
        recorder: the ReplayRecorder, or None.
    """

    diagram: object
    station: SimulatedStation
    controller: object
    logger: "SignalLogger"
    scenario: Scenario
    variant: Variant
    recorder: object = None


class SignalLogger:
    """Named signals of a Diagram sampled together by one VectorLogSink.

    The ports are stacked by a Multiplexer into a single
    LogVectorOutput: one periodic publish a sample for all of them
    instead of one per signal (two dozen sinks cost a closed-loop run
    about 7% of its time). `run_log` splits the stack again by name.

    Args:
        builder: the DiagramBuilder holding the ports' systems.
        ports: dict signal name -> vector OutputPort, in logging order
            (ports of size 0 are left out).
        period: the sample period in s.
        columns: dict signal name -> column names, for the signals that
            SIGNALS does not name (x0, y0, x1, ... where neither does).
    """

    def __init__(self, builder, ports, period, columns=None):
        given = list(ports)
        ports = {name: port for name, port in ports.items()
                 if port.size() > 0}
        if not ports:
            raise ValueError(f"ports = {given!r} is not allowed: must "
                             "name at least one port of size > 0")
        sizes = [port.size() for port in ports.values()]
        mux = builder.AddNamedSystem("log.signals", Multiplexer(sizes))
        for i, port in enumerate(ports.values()):
            builder.Connect(port, mux.get_input_port(i))
        self.sink = LogVectorOutput(mux.get_output_port(), builder, period)
        self.sink.set_name("log.sink")
        ends = np.cumsum([0] + sizes)
        self.slices = {name: slice(int(a), int(b)) for name, a, b in
                       zip(ports, ends[:-1], ends[1:], strict=True)}
        columns = columns or {}
        for name, names in columns.items():
            if name in ports and len(names) != ports[name].size():
                raise ValueError(
                    f"columns[{name!r}] = {names!r} is not allowed: must "
                    f"have {ports[name].size()} names, one per entry of "
                    "the port")
        self.columns = {
            name: columns.get(name) or SIGNALS.get(name) or tuple(
                f"{'xy'[i % 2]}{i // 2}" for i in range(part.stop - part.start))
            for name, part in self.slices.items()}

    def run_log(self, root_context, real_time_factor=np.nan):
        """The RunLog of the samples taken in `root_context`."""
        log = self.sink.FindLog(root_context)
        data = log.data().T
        n = min(len(log.sample_times()), len(data))
        signals = {name: data[:n, part].copy()
                   for name, part in self.slices.items()}
        return RunLog(np.asarray(log.sample_times()[:n]), signals,
                      dict(self.columns), real_time_factor)


def schedule_source(schedule, size):
    """A source system that plays a scenario's Schedule (a constant zero
    of `size` for an empty one)."""
    if not schedule.times:
        return ConstantVectorSource(np.zeros(size))
    times = np.asarray(schedule.times, dtype=float)
    values = np.asarray(schedule.values, dtype=float).T
    if len(times) == 1:
        return ConstantVectorSource(values[:, 0])
    if schedule.interpolation == "linear":
        trajectory = PiecewisePolynomial.FirstOrderHold(times, values)
    else:
        # A last break one second on, so that the last value holds too
        # (a trajectory is constant beyond its ends).
        times = np.append(times, times[-1] + 1.0)
        values = np.column_stack([values, values[:, -1]])
        trajectory = PiecewisePolynomial.ZeroOrderHold(times, values)
    return TrajectorySource(trajectory)


def add_controller(builder, scenario, variant, station):
    """Adds the controller of `scenario` (its `variant`) and the task's
    sources to `builder`, and connects the controller to `station` (a
    Diagram already in `builder` with the station's ports: the simulated
    station or the LCM hardware interface, the same wiring for both).

    Returns:
        (controller, sources): the drake_wbc.controller.diagram.Controller and a
        dict of the task's sources (TrajectorySources) by input name.
    """
    params = copy.deepcopy(scenario.controller)
    params.base_filter.enabled = variant.base_filter
    if variant.movement is not None:
        params.whole_body_cdmp.movement = variant.movement
    controller = build_controller(params)
    builder.AddNamedSystem("controller", controller.diagram)
    for name in STATION_INPUTS:
        builder.Connect(station.GetOutputPort(name),
                        controller.diagram.GetInputPort(name))
    for name in ("base.velocity_command", "arm.position_command"):
        builder.Connect(controller.diagram.GetOutputPort(name),
                        station.GetInputPort(name))
    sources = {}
    for name, size in TASK_SIZES.items():
        schedule = getattr(scenario.task, name)
        if name == "reference_velocity" or schedule.times:
            sources[name] = builder.AddNamedSystem(
                f"task.{name}", schedule_source(schedule, size))
            builder.Connect(sources[name].get_output_port(),
                            controller.diagram.GetInputPort(name))
    player = controller.stages["whole_body_cdmp"].player
    if player is not None and player.tracking_gain > 0.0:
        _add_movement_tracking(builder, controller, sources, station, player)
    return controller, sources


def _add_movement_tracking(builder, controller, sources, station, player):
    """Adds the learned movement's tracking (MovementTracking) to the
    task's reference velocity (cdmp.MovementReplay.tracking_gain)."""
    from pydrake.systems.primitives import Adder

    from drake_wbc.stages.whole_body_cdmp import MovementTracking

    tracking = builder.AddNamedSystem("task.movement_tracking",
                                      MovementTracking(player))
    for name in ("base.state_estimated", "arm.position_measured"):
        builder.Connect(station.GetOutputPort(name),
                        tracking.GetInputPort(name))
    adder = builder.AddNamedSystem("task.reference_velocity_sum",
                                   Adder(2, 6))
    reference = controller.diagram.GetInputPort("reference_velocity")
    builder.Disconnect(sources["reference_velocity"].get_output_port(),
                       reference)
    builder.Connect(sources["reference_velocity"].get_output_port(),
                    adder.get_input_port(0))
    builder.Connect(tracking.get_output_port(), adder.get_input_port(1))
    builder.Connect(adder.get_output_port(), reference)
    sources["reference_velocity"] = adder


def build_closed_loop(scenario, variant=None, replay=False):
    """Wires one run of `scenario` (its first variant if None).

    Args:
        scenario: a Scenario.
        variant: one of scenario.variants.
        replay: add a Meshcat recorder for the replay page.

    Returns:
        ClosedLoop.
    """
    scenario = checked_instance("scenario", scenario, Scenario, Scenario)
    variant = variant or scenario.variants[0]
    builder = DiagramBuilder()
    station = SimulatedStation(scenario.station, scenario.scene)
    builder.AddNamedSystem("station", station.diagram)
    controller, sources = add_controller(builder, scenario, variant,
                                         station.diagram)
    ports = {}
    for name in SIGNALS:
        for system in (station.diagram, controller.diagram):
            if system.HasOutputPort(name):
                ports[name] = system.GetOutputPort(name)
                break
        else:
            ports[name] = sources["reference_velocity"].get_output_port()
    logger = SignalLogger(builder, ports, scenario.outputs.log_period)
    recorder = None
    if replay:
        from drake_wbc.experiments.replay import ReplayRecorder

        recorder = ReplayRecorder.add_to(
            builder, station.diagram.GetOutputPort("query_object"),
            publish_period=1.0 / scenario.outputs.replay_frame_rate)
    diagram = builder.Build()
    diagram.set_name(f"closed_loop_{variant.name}")
    return ClosedLoop(diagram, station, controller, logger, scenario,
                      variant, recorder)


class Progress:
    """Simulated time and real-time factor on one line of stderr (a new
    line each tenth of the run when stderr is not a terminal)."""

    def __init__(self, label, duration, stream=None):
        self.label, self.duration = label, duration
        self.stream = stream or sys.stderr
        self.start = wall_clock.perf_counter()
        self._next_line = 0.0

    def update(self, t, done=False):
        elapsed = wall_clock.perf_counter() - self.start
        rtf = t / elapsed if elapsed > 0.0 else 0.0
        width = 24
        filled = int(width * min(t / self.duration, 1.0))
        text = (f"{self.label}: [{'#' * filled}{'.' * (width - filled)}] "
                f"{t:6.2f} / {self.duration:.2f} s simulated, "
                f"real-time factor {rtf:4.2f}")
        if self.stream.isatty():
            self.stream.write("\r" + text + ("\n" if done else ""))
        elif done or t >= self._next_line:
            self.stream.write(text + "\n")
            self._next_line = t + self.duration / 10.0
        self.stream.flush()
        return rtf


def simulate(loop, duration=None, progress=False):
    """Runs a ClosedLoop from its initial state for `duration` s (the
    scenario's if None).

    Returns:
        RunLog: the logged signals.
    """
    duration = loop.scenario.duration if duration is None else duration
    simulator = Simulator(loop.diagram)
    root = simulator.get_mutable_context()
    loop.station.set_initial_state(root)
    loop.controller.initialize(
        root, arm_position=loop.scenario.station.initial_arm_positions)
    simulator.Initialize()
    meter = Progress(loop.variant.label or loop.variant.name, duration) \
        if progress else None
    chunk = max(duration / 200.0, loop.scenario.controller.time_step)
    t = 0.0
    started = wall_clock.perf_counter()
    while t < duration - 1e-12:
        t = min(t + chunk, duration)
        simulator.AdvanceTo(t)
        if meter is not None:
            meter.update(t)
    elapsed = wall_clock.perf_counter() - started
    if meter is not None:
        meter.update(duration, done=True)
    return loop.logger.run_log(root, real_time_factor=duration / elapsed)


class RunLog:
    """The signals of one run: `log[name]` is an (N, k) array sampled at
    `log.time` (N,); `log.columns[name]` names its k columns.

    Attributes:
        time: (N,) sample times in s.
        signals: dict name -> (N, k) array.
        columns: dict name -> tuple of column names.
        real_time_factor: simulated over wall-clock time of the run.
    """

    def __init__(self, time, signals, columns, real_time_factor=np.nan):
        self.time, self.signals, self.columns = time, signals, columns
        self.real_time_factor = real_time_factor

    def __getitem__(self, name):
        return self.signals[name]

    def __contains__(self, name):
        return name in self.signals

    def save(self, path):
        """Writes the log as NPZ (arrays `time` and one per signal, and
        `header`, a JSON description of the columns and units) and as CSV
        next to it (one column per signal's component)."""
        import json

        header = json.dumps({
            "time": "s",
            "signals": {k: list(v) for k, v in self.columns.items()},
            "units": "SI: m, rad, s, N, N m; twists [v; w]; see "
                     "drake_wbc.experiments.runner.SIGNALS",
        })
        np.savez_compressed(path.with_suffix(".npz"), time=self.time,
                            header=header, **self.signals)
        names = ["time"] + [f"{k}.{c}" for k, cols in self.columns.items()
                            for c in cols]
        table = np.column_stack([self.time] + list(self.signals.values()))
        np.savetxt(path.with_suffix(".csv"), table, delimiter=",",
                   header=",".join(names), comments="", fmt="%.9g")
        return path.with_suffix(".npz")

    @classmethod
    def load(cls, path):
        """Reads a log written by `save` (the .npz file)."""
        import json

        with np.load(path) as data:
            header = json.loads(str(data["header"]))
            signals = {k: data[k] for k in header["signals"]}
            columns = {k: tuple(v) for k, v in header["signals"].items()}
            return cls(data["time"], signals, columns)
