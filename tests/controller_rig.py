"""The controller Diagram advanced alone against fixed measurements, every
vector output logged at each tick: the rig of the run-time safety tests."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, PortDataType
from pydrake.systems.primitives import VectorLogSink

from drake_wbc.controller import build_controller
from drake_wbc.robot.model import HOME_ARM_POSITIONS
from drake_wbc.stages.wrench import tool_weight_reading

H = 0.01
"""The control period, s."""


class Rig:
    """The controller Diagram with every vector output logged at each
    tick, its inputs fixed on its context and changeable between
    advances."""

    def __init__(self, arm, params=None, q=HOME_ARM_POSITIONS):
        self.controller = build_controller(params, arm)
        builder = DiagramBuilder()
        diagram = self.diagram = builder.AddSystem(self.controller.diagram)
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
        self.controller.initialize(self.root_context, arm_position=self.q)
        self.simulator = Simulator(self.root, self.root_context)
        self.ticks = 0

    def set(self, name, value):
        port = self.diagram.GetInputPort(name)
        if name == "lidar.obstacle_points":
            port.FixValue(self.context, AbstractValue.Make(
                np.asarray(value, dtype=float)))
        else:
            port.FixValue(self.context, np.asarray(value, dtype=float))

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
