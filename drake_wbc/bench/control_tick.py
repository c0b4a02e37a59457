"""One control tick of the controller Diagram, whole and stage by stage.

The controller runs alone in a Simulator (no plant) against fixed
measurements: the robot at rest at the home pose, the tool's weight on
the wrist sensor (no external wrench), obstacle points scattered around
the base, and a constant reference twist. A tick is one AdvanceTo by the
control period h. Before every tick the station inputs are fixed again,
alternating between two sets that differ in every entry, as new
measurements arrive each period on the robot: this invalidates the
caches that depend on them, so that the stateless stages (ArmCapability,
the wrench estimator, ...) compute each tick as they do in the closed
loop instead of once. Each batch of ticks starts from the controller's
initial state: against fixed measurements the loop is open, and over
many batches the commanded arm would drift towards its limits and a
singularity, where a closed loop does not stay.

Per stage, each stage gets a context of its own with the state and the
input values it has in the running diagram; a tick of it is: fix its
inputs again, evaluate every output, and the periodic discrete update
when it has state. The cost of fixing the inputs alone is reported next
to it (the `inputs` column), so that the net cost of the stage is plain.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import PortDataType

from drake_wbc.controller import ControllerParameters, build_controller
from drake_wbc.controller.diagram import STATION_INPUTS
from drake_wbc.math.validation import positive, whole_number
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages.wrench import tool_weight_reading

REFERENCE_VELOCITY = np.array([0.1, 0.05, 0.0, 0.0, 0.0, 0.05])
"""The reference twist V_ee^ref (T_w) of the ticks."""

BASE_STATE = np.array([0.0, 0.0, 0.3, 0.0, 0.0, 0.0])
"""The measured base state: at the origin, yawed 0.3 rad, at rest."""


def obstacle_points(count, seed=0):
    """`count` obstacle points (count, 2) in T_b, seeded: a quarter of
    them within 0.5 m of the footprint (inside the repulsive field's
    d_th), the rest between 1 and 5 m away, like LIDAR returns on walls."""
    count = whole_number("count", count, minimum=0)
    rng = np.random.default_rng(seed)
    near = count // 4
    radius = np.concatenate([rng.uniform(0.55, 0.9, near),
                             rng.uniform(1.0, 5.0, count - near)])
    angle = rng.uniform(-np.pi, np.pi, count)
    return np.column_stack([radius * np.cos(angle),
                            radius * np.sin(angle)])


def _measurements(arm, num_points, turn):
    """The station inputs of ControllerTicker's measurement set `turn`
    (0 or 1): the second one differs in every entry."""
    q = HOME_ARM_POSITIONS + 1e-3 * turn
    c, s = np.cos(1e-3 * turn), np.sin(1e-3 * turn)
    return {
        "base.state_estimated": BASE_STATE + 1e-4 * turn,
        "arm.position_measured": q,
        "wrist.wrench_measured": tool_weight_reading(arm, q),
        "lidar.obstacle_points": AbstractValue.Make(
            obstacle_points(num_points) @ np.array([[c, s], [-s, c]])),
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


class ControllerTicker:
    """The controller Diagram in a Simulator of its own, with fixed inputs.

    Args:
        arm: a shared ArmKinematics.
        time_step: control period h in s (0.01 s: 100 Hz, the paper's).
        num_points: number of obstacle points on lidar.obstacle_points.
    """

    def __init__(self, arm, time_step=0.01, num_points=300):
        self.time_step = positive("time_step", time_step)
        params = ControllerParameters(time_step=self.time_step)
        self.controller = build_controller(params, arm)
        diagram = self.controller.diagram
        self.simulator = Simulator(diagram)
        self.context = self.simulator.get_mutable_context()
        self.values = [_measurements(arm, num_points, turn)
                       for turn in (0, 1)]
        self.fixed = [
            Fixed(diagram.GetInputPort(name), self.context,
                   [values[name] for values in self.values])
            for name in STATION_INPUTS]
        diagram.GetInputPort("reference_velocity").FixValue(
            self.context, REFERENCE_VELOCITY)
        self.controller.initialize(self.context)
        self.simulator.Initialize()
        self._start = self.context.Clone()

    def refresh(self):
        """Writes the station inputs again (new measurements)."""
        for fixed in self.fixed:
            fixed.write()

    def advance(self, refresh=True):
        """One tick from the current state (measurements written again
        first if `refresh`)."""
        if refresh:
            self.refresh()
        self.simulator.AdvanceTo(self.context.get_time() + self.time_step)

    def ticks(self, count, refresh=True):
        """A timing.interleave contender: `count` ticks of the controller
        from its initial state (measurements fixed again before each if
        `refresh`)."""
        count = whole_number("count", count, minimum=1)

        def run():
            self.context.SetStateAndParametersFrom(self._start)
            for fixed in self.fixed:
                fixed.restart()
            for _ in range(count):
                self.advance(refresh)
            return count

        return run


class StageTicker:
    """One stage of a running ControllerTicker, in a context of its own.

    Its inputs alternate, as the ticker's measurements do, between the
    values they had in the running diagram after two successive ticks.

    Args:
        ticker: a ControllerTicker.
        name: the stage's name (a key of Controller.stages).
    """

    def __init__(self, ticker, name):
        stage = ticker.controller.stages[name]
        inner = stage.GetMyContextFromRoot(ticker.context)
        self.stage, self.name = stage, name
        ports = [stage.get_input_port(i)
                 for i in range(stage.num_input_ports())]
        ports = [port for port in ports if port.HasValue(inner)]
        values = [[] for _ in ports]  # unconnected optional inputs left
        for _ in range(2):
            ticker.advance()
            for port, seen in zip(ports, values, strict=True):
                seen.append(
                    np.array(port.Eval(inner))
                    if port.get_data_type() == PortDataType.kVectorValued
                    else port.EvalAbstract(inner).Clone())
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


def stage_tickers(ticker):
    """A StageTicker for every stage of `ticker`'s controller, after one
    tick so that every input has its running value."""
    ticker.advance()
    return {name: StageTicker(ticker, name)
            for name in ticker.controller.stages}


def make_ticker(arm=None, **kwargs):
    """A ControllerTicker on `arm` (a new ArmKinematics if None)."""
    return ControllerTicker(arm or ArmKinematics(), **kwargs)
