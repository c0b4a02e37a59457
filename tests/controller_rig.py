"""The controller Diagram advanced alone against fixed measurements and
an arm that follows its commands, every vector output logged at each
tick: the rig of the run-time safety tests."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem, PortDataType
from pydrake.systems.primitives import VectorLogSink

from drake_wbc.controller import build_controller
from drake_wbc.robot.model import HOME_ARM_POSITIONS
from drake_wbc.stages.wrench import tool_weight_reading

H = 0.01
"""The control period, s."""


class FollowingArm(LeafSystem):
    """An arm whose position servo follows the controller's command at
    once (`measured` is `command`, no lag), or a reading given in its
    place (`reading` while `follow` is 0)."""

    def __init__(self, size):
        super().__init__()
        self.command = self.DeclareVectorInputPort("command", size)
        self.reading = self.DeclareVectorInputPort("reading", size)
        self.follow = self.DeclareVectorInputPort("follow", 1)
        self.DeclareVectorOutputPort("measured", size, self._measured)

    def _measured(self, context, output):
        following = self.follow.Eval(context)[0] >= 0.5
        output.SetFromVector((self.command if following
                              else self.reading).Eval(context))


class Rig:
    """The controller Diagram with every vector output logged at each
    tick, its inputs fixed on its context and changeable between
    advances; its arm.position_measured is a FollowingArm's, following
    the arm.position_command until a reading is set."""

    def __init__(self, arm, params=None, q=HOME_ARM_POSITIONS):
        self.controller = build_controller(params, arm)
        builder = DiagramBuilder()
        diagram = self.diagram = builder.AddSystem(self.controller.diagram)
        self.arm = builder.AddSystem(FollowingArm(arm.num_joints))
        builder.Connect(diagram.GetOutputPort("arm.position_command"),
                        self.arm.GetInputPort("command"))
        builder.Connect(self.arm.GetOutputPort("measured"),
                        diagram.GetInputPort("arm.position_measured"))
        self.logs = {}
        for i in range(diagram.num_output_ports()):
            port = diagram.get_output_port(i)
            if port.get_data_type() == PortDataType.kVectorValued:
                sink = builder.AddSystem(VectorLogSink(port.size(), H))
                builder.Connect(port, sink.get_input_port())
                self.logs[port.get_name()] = sink
        self.root = builder.Build()
        self.root_context = self.root.CreateDefaultContext()
        self.context = diagram.GetMyMutableContextFromRoot(self.root_context)
        self.arm_context = self.arm.GetMyMutableContextFromRoot(
            self.root_context)
        self.q = np.asarray(q, dtype=float)
        self.valid = {
            "base.state_estimated": [0.0, 0.0, 0.3, 0.0, 0.0, 0.0],
            "arm.position_measured": self.q,
            "wrist.wrench_measured": tool_weight_reading(arm, self.q),
            "reference_velocity": [0.1, 0.05, 0.0, 0.0, 0.0, 0.05],
            "desired_wrench": [-10.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            "phri_switch": [0.0],
            "null_space_gain": [0.05],
            "compensation_switch": [1.0],
            "lidar.obstacle_points": np.array([[0.7, 0.1], [2.0, 0.0]]),
        }
        for name, value in self.valid.items():
            self.set(name, value)
        self.follow()
        self.controller.initialize(self.root_context, arm_position=self.q)
        self.simulator = Simulator(self.root, self.root_context)
        self.ticks = 0

    def set(self, name, value):
        """Sets input `name` to `value`; the arm's measured position to a
        reading in place of the following arm's."""
        if name == "arm.position_measured":
            self.arm.GetInputPort("reading").FixValue(
                self.arm_context, np.asarray(value, dtype=float))
            self.arm.GetInputPort("follow").FixValue(self.arm_context, [0.0])
            return
        port = self.diagram.GetInputPort(name)
        if name == "lidar.obstacle_points":
            port.FixValue(self.context, AbstractValue.Make(
                np.asarray(value, dtype=float)))
        else:
            port.FixValue(self.context, np.asarray(value, dtype=float))

    def follow(self):
        """The arm's measured position follows its command again."""
        self.arm.GetInputPort("follow").FixValue(self.arm_context, [1.0])

    def restore(self, name):
        """Input `name` valid again: its valid value, or, for the arm's
        measured position, the following arm's."""
        if name == "arm.position_measured":
            self.follow()
        else:
            self.set(name, self.valid[name])

    def advance(self, duration):
        """Advances by `duration` to a tick k h exactly (the tick's update
        runs at the start of the next advance, after any input change)."""
        self.ticks += round(duration / H)
        self.simulator.AdvanceTo(self.ticks * H)

    def time(self):
        return self.ticks * H

    def log(self, name):
        """(time (N,), data (N, k)) of an output."""
        log = self.logs[name].FindLog(self.root_context)
        return log.sample_times(), log.data().T
