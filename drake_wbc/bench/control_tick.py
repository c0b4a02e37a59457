"""One control tick of the controller Diagram, whole and stage by stage,
as the robot sees it.

The controller runs alone in a Simulator (no plant) against measurements
that change every tick, on the robot of its ArmKinematics (the shipped
one, or any described robot's): the robot near its home pose, each arm
joint
moving on a slow sine of its own (a new arm configuration every tick, so
that no kinematics memo can hit, as on the robot), the base state and the
obstacle points (scattered around the base, rotating slowly) changing
with it, the tool's weight on the wrist sensor at that configuration (no
external wrench), and a constant reference twist. Tick k writes the
measurement set k (they cycle after `measurement_sets`, far more than
any memo holds), advances with AdvanceTo((k + 1) h) (one discrete update
exactly: adding h to the context's time accumulates rounding, and some
ticks then do two updates and the next none), and pulls the exported
commands a station reads (STATION_COMMANDS), after the update as the
hardware interface does. Each batch of ticks starts from the
controller's initial state at time 0: against measurements that do not
follow the commands the loop is open, and over many batches the
commanded arm would drift towards its limits and a singularity, where a
closed loop does not stay.

Per stage, each stage gets a context of its own with the state it has in
the running diagram; a tick of it is: fix its inputs to the values they
had at the next tick of the running diagram (recorded over
`measurement_sets` ticks, so they too change every tick), evaluate every
output, and the periodic discrete update when it has state. The cost of
fixing the inputs alone is reported next to it (the `inputs` column), so
that the net cost of the stage is plain.
"""

from dataclasses import replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import InitializeParams, Simulator
from pydrake.systems.framework import PortDataType

from drake_wbc.controller import ControllerParameters, build_controller
from drake_wbc.controller.diagram import STATION_INPUTS
from drake_wbc.math.validation import positive, whole_number
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.wrench import tool_weight_reading

REFERENCE_VELOCITY = np.array([0.1, 0.05, 0.0, 0.0, 0.0, 0.05])
"""The reference twist V_ee^ref (T_w) of the ticks."""

BASE_STATE = np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0])
"""The measured base state: at the origin, yawed 0.3 rad, at rest."""


SHIPPED_CLEARANCE = 0.5
"""The radius in m of the circle through the corners of the shipped
base's 0.8 x 0.6 m footprint, obstacle_points' default."""


def obstacle_points(count, seed=0, clearance=SHIPPED_CLEARANCE):
    """`count` obstacle points (count, 2) in T_b, seeded: a quarter of
    them between 0.05 and 0.4 m outside the circle of radius `clearance`
    around the base's centre (the circle through the footprint's corners:
    all outside the footprint, most within the repulsive field's
    d_th = 0.5 m of it), the rest 0.5 to 4.5 m outside that circle, like
    LIDAR returns on walls (for the shipped base, 0.55 to 0.9 m and 1 to
    5 m from its centre)."""
    count = whole_number("count", count, minimum=0)
    clearance = positive("clearance", clearance)
    rng = np.random.default_rng(seed)
    near = count // 4
    radius = np.concatenate(
        [rng.uniform(clearance + 0.05, clearance + 0.4, near),
         rng.uniform(clearance + 0.5, clearance + 4.5, count - near)])
    angle = rng.uniform(-np.pi, np.pi, count)
    return np.column_stack([radius * np.cos(angle),
                            radius * np.sin(angle)])


STATION_COMMANDS = ("base.velocity_command", "arm.position_command")
"""The controller's outputs that a station (simulated or the hardware
interface) reads every tick."""

RESTART = InitializeParams(suppress_initialization_events=True)
"""How a batch restarts the Simulator after the context is set back to
the initial one (time 0; its state is already the initialized one)."""

OPEN_LOOP_TOLERANCE = 100.0
"""rad: the arm-follow tolerance of a ControllerTicker's controller
(SafetyParameters.arm_follow_tolerance), wider than any arm's travel:
its measurements do not follow its commands."""

MEASUREMENT_SETS = 100
"""Measurement sets a ControllerTicker cycles through (a new one each
tick)."""


def robot_of(arm):
    """(home (n,), clearance) of the robot of `arm`: its arm's home and
    the radius in m of the circle through the corners of its base's
    footprint (its description's footprint_half_sizes). An ArmKinematics
    of a checkout from before robot descriptions, which
    tools/bench_against.py runs this ticker on, has neither: the shipped
    robot's, as that checkout's bench had them."""
    description = getattr(getattr(arm, "model", None), "description", None)
    if description is None:
        from drake_wbc.robot.model import HOME_ARM_POSITIONS

        return np.asarray(HOME_ARM_POSITIONS, dtype=float), SHIPPED_CLEARANCE
    a, b = description.base.footprint_half_sizes
    return arm.home, float(np.hypot(a, b))


def measurements(arm, num_points, k, count=MEASUREMENT_SETS):
    """The station inputs of tick `k` (of `count` in a cycle) for the
    robot of `arm` (ArmKinematics): every entry of the arm's n joints
    (about its home) and of the base state on a sine of its own with
    period `count` ticks (amplitudes 0.02 rad and 1e-3), the obstacle
    points (outside that base's footprint) turned by 0.2 rad over the
    cycle, the tool's weight on the wrist at that arm configuration."""
    home, clearance = robot_of(arm)
    cycle = 2.0 * np.pi * k / count
    q = home + 0.02 * np.sin(cycle + np.arange(len(home)) * (np.pi / 7))
    base_phase = cycle + np.arange(len(BASE_STATE)) * (np.pi / 7)
    angle = 0.2 * np.sin(cycle)
    c, s = np.cos(angle), np.sin(angle)
    points = obstacle_points(num_points, clearance=clearance)
    return {
        "base.state_estimated": BASE_STATE + 1e-3 * np.cos(base_phase),
        "arm.position_measured": q,
        "wrist.wrench_measured": tool_weight_reading(arm, q),
        "lidar.obstacle_points": AbstractValue.Make(
            points @ np.array([[c, s], [-s, c]])),
    }


class Fixed:
    """An input port's fixed value in a context, written again on demand
    (which invalidates what depends on it, as a new message does).

    Args:
        port: an InputPort.
        context: its system's context.
        values: the values written in turn, each a vector (array) or an
            AbstractValue.
    """

    def __init__(self, port, context, values):
        self.values, self.turn = values, 0
        self.fixed = port.FixValue(context, values[0])
        self.is_vector = not isinstance(values[0], AbstractValue)

    def restart(self):
        """The next `write` writes the first value again."""
        self.turn = len(self.values) - 1

    def write(self):
        self.turn = (self.turn + 1) % len(self.values)
        value = self.values[self.turn]
        data = self.fixed.GetMutableData()
        if self.is_vector:
            data.get_mutable_value().SetFromVector(value)
        else:
            data.SetFrom(value)


class DiagramTicker:
    """A Diagram with the controller's ports in a Simulator of its own,
    with fixed inputs written again every tick: a measurement set each
    tick, the reference twist fixed.

    Args:
        diagram: the Diagram (the controller's input and output ports).
        stages: its stages by name (systems of `diagram`).
        time_step: control period h in s.
        values: the measurement sets (`measurements`), written in turn.
        initialize: initialize(context), called before the Simulator's
            Initialize (None: nothing to do).
    """

    def __init__(self, diagram, stages, time_step, values, initialize=None):
        self.diagram, self.stages = diagram, stages
        self.time_step, self.values = time_step, values
        self.simulator = Simulator(diagram)
        self.context = self.simulator.get_mutable_context()
        self.fixed = [
            Fixed(diagram.GetInputPort(name), self.context,
                  [values[name] for values in self.values])
            for name in STATION_INPUTS]
        self.commands = [diagram.GetOutputPort(name)
                         for name in STATION_COMMANDS]
        diagram.GetInputPort("reference_velocity").FixValue(
            self.context, REFERENCE_VELOCITY)
        if initialize is not None:
            initialize(self.context)
        self.simulator.Initialize()
        self._start = self.context.Clone()
        self.tick_count = 0

    def refresh(self):
        """Writes the station inputs again (the next measurement set)."""
        for fixed in self.fixed:
            fixed.write()

    def restart(self):
        """Back to the initial state at time 0; the next tick writes the
        first measurement set."""
        self.context.SetTimeStateAndParametersFrom(self._start)
        self.simulator.Initialize(RESTART)
        self.tick_count = 0
        for fixed in self.fixed:
            fixed.restart()

    def advance(self, refresh=True, pull=True):
        """One tick from the current state: the next measurements written
        (if `refresh`), AdvanceTo((k + 1) h), the commands pulled (if
        `pull`)."""
        if refresh:
            self.refresh()
        self.tick_count += 1
        self.simulator.AdvanceTo(self.tick_count * self.time_step)
        if pull:
            for port in self.commands:
                port.Eval(self.context)

    def ticks(self, count, refresh=True, pull=True):
        """A timing.interleave contender: `count` ticks from the initial
        state (see `advance`)."""
        count = whole_number("count", count, minimum=1)

        def run():
            self.restart()
            for _ in range(count):
                self.advance(refresh, pull)
            return count

        return run


class ControllerTicker(DiagramTicker):
    """The controller Diagram, ticked (DiagramTicker) against
    measurements new every tick.

    Args:
        arm: a shared ArmKinematics, of the robot whose controller ticks
            (build_controller's `robot`: its limits, footprint and
            tuning).
        time_step: control period h in s (0.01 s: 100 Hz, the paper's).
        num_points: number of obstacle points on lidar.obstacle_points.
        measurement_sets: how many different measurement sets the ticks
            cycle through (>= 2: a new one every tick).
    """

    def __init__(self, arm, time_step=0.01, num_points=300,
                 measurement_sets=MEASUREMENT_SETS):
        time_step = positive("time_step", time_step)
        count = whole_number("measurement_sets", measurement_sets,
                             minimum=2)
        params = ControllerParameters(time_step=time_step)
        if hasattr(params.safety, "arm_follow_tolerance"):
            # The arm measured here does not follow the commands (no
            # plant: the loop is open), which the guard would take for an
            # arm stopped on its own and stop the controller within the
            # batch; its check still runs every tick.
            params = replace(params, safety=replace(
                params.safety, arm_follow_tolerance=OPEN_LOOP_TOLERANCE))
        self.controller = build_controller(params, arm)
        super().__init__(
            self.controller.diagram, self.controller.stages, time_step,
            [measurements(arm, num_points, k, count) for k in range(count)],
            initialize=self.controller.initialize)


class StageTicker:
    """One stage of a running ControllerTicker, in a context of its own.

    Args:
        ticker: a ControllerTicker (after at least one tick, so that every
            connected input has its running value), or a
            drake_wbc.bench.framework_floor.FloorTicker (its hollow
            stages).
        name: the stage's name (a key of the ticker's `stages`).
        ports: the stage's connected input ports.
        values: for each port, the values it had over successive ticks of
            the running diagram (written in turn, one set a tick).
    """

    def __init__(self, ticker, name, ports, values):
        stage = ticker.stages[name]
        inner = stage.GetMyContextFromRoot(ticker.context)
        self.stage, self.name = stage, name
        self.context = stage.CreateDefaultContext()
        self.context.SetTimeStateAndParametersFrom(inner)
        self.inputs = [Fixed(port, self.context, seen)
                       for port, seen in zip(ports, values, strict=True)]
        self.outputs = [stage.get_output_port(i)
                        for i in range(stage.num_output_ports())]
        self.has_state = self.context.num_discrete_state_groups() > 0

    def refresh(self):
        for fixed in self.inputs:
            fixed.write()

    def tick(self):
        """Inputs fixed again, every output evaluated, the discrete
        update computed."""
        self.refresh()
        for port in self.outputs:
            port.Eval(self.context)
        if self.has_state:
            self.stage.EvalUniquePeriodicDiscreteUpdate(self.context)

    def contender(self, count, inputs_only=False):
        """A timing.interleave contender: `count` stage ticks (or only
        the fixing of the inputs, if `inputs_only`)."""
        count = whole_number("count", count, minimum=1)
        work = self.refresh if inputs_only else self.tick

        def run():
            for _ in range(count):
                work()
            return count

        return run


def _input_value(port, context):
    if port.get_data_type() == PortDataType.kVectorValued:
        return np.array(port.Eval(context))
    return port.EvalAbstract(context).Clone()


def stage_tickers(ticker, ticks=None):
    """A StageTicker for every stage of `ticker` (a ControllerTicker or a
    FloorTicker: its `stages`), with the inputs each stage had over
    `ticks` successive ticks (the ticker's measurement sets if None) of
    the running diagram, from its initial state."""
    ticks = len(ticker.values) if ticks is None else whole_number(
        "ticks", ticks, minimum=2)
    ticker.restart()
    ticker.advance()
    stages = ticker.stages
    ports, values = {}, {}
    for name, stage in stages.items():
        inner = stage.GetMyContextFromRoot(ticker.context)
        ports[name] = [port for port in (stage.get_input_port(i) for i in
                                         range(stage.num_input_ports()))
                       if port.HasValue(inner)]  # optional ones left out
        values[name] = [[] for _ in ports[name]]
    for _ in range(ticks):
        ticker.advance()
        for name, stage in stages.items():
            inner = stage.GetMyContextFromRoot(ticker.context)
            for port, seen in zip(ports[name], values[name], strict=True):
                seen.append(_input_value(port, inner))
    return {name: StageTicker(ticker, name, ports[name], values[name])
            for name in stages}


def make_ticker(arm=None, **kwargs):
    """A ControllerTicker on `arm` (a new ArmKinematics if None)."""
    return ControllerTicker(arm or ArmKinematics(), **kwargs)
