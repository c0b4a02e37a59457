"""The controller's task: its inputs over time, and the controller wired to
a station with them.

A task input is a `Schedule` of values over time; `TaskInputs` holds one
per task input port of the controller (drake_wbc.math.task_inputs, which
gives each one's size and range).
`add_controller` builds the controller, adds the task's sources and
connects both to a station: the simulated station
(drake_wbc.experiments.runner) or the LCM hardware interface
(drake_wbc.deployment.deploy), the same wiring for both, since both offer
the station's port names.
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_wbc.controller.diagram import STATION_INPUTS, build_controller
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import as_vector, checked_instance

INTERPOLATIONS = ("hold", "linear")


@dataclass
class Schedule:
    """A task input over time.

    Attributes:
        times: strictly increasing times in s.
        values: one value (a list of numbers of the input's size) per
            time.
        interpolation: `hold` (each value from its time until the next;
            the first value before the first time) or `linear`
            (piecewise linear between the times, constant outside).

    An empty schedule leaves the input to its default (see TaskInputs).
    """

    times: list[float] = field(default_factory=list)
    values: list[list[float]] = field(default_factory=list)
    interpolation: str = "hold"

    def __post_init__(self):
        if len(self.times) != len(self.values):
            raise ValueError(
                f"values has {len(self.values)} entries, which is not "
                f"allowed: must have one per time ({len(self.times)})")
        if self.times:
            times = as_vector("times", self.times)
            if np.any(np.diff(times) <= 0.0):
                raise ValueError(f"times = {self.times} is not allowed: "
                                 "must be strictly increasing")
            sizes = {len(v) for v in self.values}
            if len(sizes) != 1:
                raise ValueError(f"values = {self.values} is not allowed: "
                                 "every value must have the same size")
            for i, value in enumerate(self.values):
                as_vector(f"values[{i}]", value)
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(
                f"interpolation = {self.interpolation!r} is not allowed: "
                f"must be one of {', '.join(INTERPOLATIONS)}")

    def size(self):
        """The size of the values (0 for an empty schedule)."""
        return len(self.values[0]) if self.values else 0


@dataclass
class TaskInputs:
    """The controller's task inputs over time (math.task_inputs.TASK_INPUTS).

    Attributes:
        reference_velocity: V_ee^ref (6) in the world, [v; w]; zero when
            empty.
        desired_wrench: F_d (6), the controller's arm_cdmp.F_d when empty.
        phri_switch: S_hri (1), the parameter when empty.
        null_space_gain: k_n (1), the parameter when empty.
        compensation_switch: s_c (1), the parameter when empty.
    """

    reference_velocity: Schedule = field(default_factory=Schedule)
    desired_wrench: Schedule = field(default_factory=Schedule)
    phri_switch: Schedule = field(default_factory=Schedule)
    null_space_gain: Schedule = field(default_factory=Schedule)
    compensation_switch: Schedule = field(default_factory=Schedule)

    def __post_init__(self):
        for name, spec in TASK_INPUTS.items():
            schedule = checked_instance(name, getattr(self, name), Schedule,
                                        Schedule)
            setattr(self, name, schedule)
            if schedule.times and schedule.size() != spec.size:
                raise ValueError(
                    f"{name}.values = {schedule.values} is not allowed: "
                    f"each value must have {spec.size} entries")
            for i, value in enumerate(schedule.values):
                for j, entry in enumerate(value):
                    spec.check(f"{name}.values[{i}][{j}]", entry)


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


def add_controller(builder, params, task, station, arm=None):
    """Adds the controller built from `params` and the sources of `task`
    to `builder`, and connects the controller to `station` (a Diagram
    already in `builder` with the station's ports: the simulated station
    or the LCM hardware interface, the same wiring for both).

    Args:
        builder: a DiagramBuilder.
        params: ControllerParameters (a scenario's, for one of its runs:
            Scenario.controller_for(variant)).
        task: TaskInputs.
        station: the station's Diagram, already added to `builder`.
        arm: the station's robot, as build_controller takes it: a
            RobotDescription or the ArmKinematics of one (the shipped
            robot if None). The task's stages use the built controller's
            ArmKinematics (Controller.arm).

    Returns:
        (controller, sources): the drake_wbc.controller.diagram.Controller
        and a dict of the task's sources (TrajectorySources) by input name.
    """
    task = checked_instance("task", task, TaskInputs, TaskInputs)
    controller = build_controller(params, arm)
    builder.AddNamedSystem("controller", controller.diagram)
    for name in STATION_INPUTS:
        builder.Connect(station.GetOutputPort(name),
                        controller.diagram.GetInputPort(name))
    for name in ("base.velocity_command", "arm.position_command"):
        builder.Connect(controller.diagram.GetOutputPort(name),
                        station.GetInputPort(name))
    sources = {}
    for name, spec in TASK_INPUTS.items():
        schedule = getattr(task, name)
        if name == "reference_velocity" or schedule.times:
            sources[name] = builder.AddNamedSystem(
                f"task.{name}", schedule_source(schedule, spec.size))
            builder.Connect(sources[name].get_output_port(),
                            controller.diagram.GetInputPort(name))
    player = controller.stages["whole_body_cdmp"].player
    if player is not None and player.tracking_gain > 0.0:
        _add_movement_tracking(builder, controller, sources, station, player)
    return controller, sources


def _add_movement_tracking(builder, controller, sources, station, player):
    """Adds the learned movement's tracking (MovementTracking, with the
    controller's own ArmKinematics, controller.arm) to the task's
    reference velocity (cdmp.MovementReplay.tracking_gain)."""
    from pydrake.systems.primitives import Adder

    from drake_wbc.stages.whole_body_cdmp import MovementTracking

    tracking = builder.AddNamedSystem("task.movement_tracking",
                                      MovementTracking(player,
                                                       controller.arm))
    for name in ("base.state_estimated", "arm.position_measured"):
        builder.Connect(station.GetOutputPort(name),
                        tracking.GetInputPort(name))
    adder = builder.AddNamedSystem("task.reference_velocity_sum",
                                   Adder(2, TASK_INPUTS[
                                       "reference_velocity"].size))
    reference = controller.diagram.GetInputPort("reference_velocity")
    builder.Disconnect(sources["reference_velocity"].get_output_port(),
                       reference)
    builder.Connect(sources["reference_velocity"].get_output_port(),
                    adder.get_input_port(0))
    builder.Connect(tracking.get_output_port(), adder.get_input_port(1))
    builder.Connect(adder.get_output_port(), reference)
    sources["reference_velocity"] = adder
