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

import sys
import time as wall_clock
from dataclasses import dataclass

from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_wbc.controller.run_log import SIGNALS, SignalLogger, advance_times
from drake_wbc.controller.task import add_controller
from drake_wbc.experiments.scenario import (
    Scenario,
    Variant,
    controller_arm,
    controller_for,
    scenario_station,
)
from drake_wbc.math.validation import checked_instance
from drake_wbc.station.simulation import SimulatedStation

MAX_CHUNK = 1.0
"""s: the longest stretch `simulate` advances the Simulator at once."""


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
    station = scenario_station(scenario)
    builder.AddNamedSystem("station", station.diagram)
    controller, sources = add_controller(
        builder, controller_for(scenario, variant), scenario.task,
        station.diagram, arm=controller_arm(scenario))
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
    """Simulated time, real-time factor and the time left on one line of
    stderr, redrawn in place on a terminal; elsewhere (a log file, a
    pipe) a new line each tenth of the run and at least every
    `LINE_INTERVAL` s of wall time, so that a long run is never silent.
    `what` says what the time is (`drake-wbc deploy`: "run", on the
    robot). With `duration` None (a run until Ctrl-C) the line has no
    bar and no time left."""

    LINE_INTERVAL = 10.0
    """s of wall time between two lines at most, off a terminal."""

    def __init__(self, label, duration, stream=None, what="simulated"):
        self.label, self.duration, self.what = label, duration, what
        self.stream = stream or sys.stderr
        self.start = wall_clock.perf_counter()
        self._next_line = 0.0
        self._last_line = None  # wall time of the last line written
        self._last_t = None  # and its t
        self._width = 0  # of the text drawn in place

    def text(self, t, elapsed, done=False):
        """The line at run time `t` after `elapsed` s of wall time."""
        rtf = t / elapsed if elapsed > 0.0 else 0.0
        if self.duration is None:
            return (f"{self.label}: {t:8.2f} s {self.what}, real-time "
                    f"factor {rtf:4.2f} (Ctrl-C stops)")
        width = 24
        filled = int(width * min(t / self.duration, 1.0))
        if done:
            left = f"took {wall_time_text(elapsed)}"
        elif rtf > 0.0 and t > 0.0:
            left = f"about {wall_time_text((self.duration - t) / rtf)} left"
        else:
            left = "time left not known yet"
        return (f"{self.label}: [{'#' * filled}{'.' * (width - filled)}] "
                f"{t:6.2f} / {self.duration:.2f} s {self.what}, "
                f"real-time factor {rtf:4.2f}, {left}")

    def update(self, t, done=False):
        now = wall_clock.perf_counter()
        elapsed = now - self.start
        rtf = t / elapsed if elapsed > 0.0 else 0.0
        text = self.text(t, elapsed, done)
        if self.stream.isatty():
            padding = " " * max(0, self._width - len(text))
            self._width = len(text)
            self.stream.write("\r" + text + padding
                              + ("\n" if done else ""))
        elif (done and t != self._last_t) or (
                self.duration is not None and t >= self._next_line) or (
                self._last_line is None
                or now - self._last_line >= self.LINE_INTERVAL):
            self.stream.write(text + "\n")
            self._last_line, self._last_t = now, t
            if self.duration is not None:
                self._next_line = t + self.duration / 10.0
        self.stream.flush()
        return rtf


def wall_time_text(seconds):
    """A wall time for the progress line: "0.4 s", "42 s", "3 min 20 s",
    "2 h 5 min"."""
    if seconds < 9.95:
        return f"{seconds:.1f} s"
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60} min"


def start_simulator(loop):
    """A Simulator of the ClosedLoop `loop`, initialized at its start: the
    station's initial state (at rest, in static equilibrium) and the
    controller started from the scenario's arm positions."""
    simulator = Simulator(loop.diagram)
    root = simulator.get_mutable_context()
    loop.station.set_initial_state(root)
    loop.controller.initialize(
        root, arm_position=loop.scenario.station.initial_arm_positions)
    simulator.Initialize()
    return simulator


def simulate(loop, duration=None, progress=False):
    """Runs a ClosedLoop from its initial state for `duration` s (the
    scenario's if None).

    Returns:
        RunLog: the logged signals, and what the station said of its
        arm (`fault_message`).
    """
    duration = loop.scenario.duration if duration is None else duration
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    meter = Progress(loop.variant.label or loop.variant.name, duration) \
        if progress else None
    # Two hundred steps of the bar, none longer than a simulated second:
    # the line moves (and Ctrl-C answers) every few seconds of wall time.
    chunk = min(max(duration / 200.0, loop.scenario.controller.time_step),
                MAX_CHUNK)
    started = wall_clock.perf_counter()
    for t in advance_times(duration, chunk):
        simulator.AdvanceTo(t)
        if meter is not None and t < duration:
            meter.update(t)
    elapsed = wall_clock.perf_counter() - started
    if meter is not None:
        meter.update(duration, done=True)
    return loop.logger.run_log(root, real_time_factor=duration / elapsed,
                               arm_fault=fault_message(loop.station, root))


def fault_message(station, root):
    """The SimulatedStation `station`'s arm fault in the root context
    `root`, in one sentence, or "none" (RunLog.arm_fault)."""
    fault = station.arm_fault(root)
    return "none" if fault is None else fault.message()
