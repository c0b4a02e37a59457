"""The framework's share of a control tick: the controller Diagram with
every stage replaced by a hollow one.

A hollow stage is a Python LeafSystem with the ports of the stage it
stands for (names, sizes, abstract or vector), the same direct
feedthrough, the same amount of discrete state updated at the same
period, and no work: the outputs that depend on the same inputs share
a cache entry that evaluates those inputs (as a stage's outputs share
its result), each output evaluates its entry and writes zeros, and the
update evaluates every connected input and keeps the state. Which
inputs are connected is read once, at construction (an Eval each, no
HasValue: in Drake, HasValue evaluates the upstream output too).
Wired as the controller is and ticked against the same measurements, it
costs what Drake's systems framework and the Python bindings cost for
this structure of one system per stage, whatever the stages compute:
the floor under the controller's tick.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import (
    DiagramBuilder,
    LeafSystem,
    OutputPortIndex,
    PortDataType,
    ValueProducer,
)

from drake_wbc.bench.control_tick import DiagramTicker


class HollowStage(LeafSystem):
    """A stage's ports, feedthrough and discrete state, without its work.

    Args:
        stage: the stage (a LeafSystem of the controller).
        context: the stage's context in the running controller (for its
            state's size and which of its inputs are connected).
        time_step: the period of its update, s.
    """

    def __init__(self, stage, context, time_step):
        super().__init__()
        self._inputs, connected = [], []
        for i in range(stage.num_input_ports()):
            port = stage.get_input_port(i)
            self._inputs.append(
                self.DeclareVectorInputPort(port.get_name(), port.size())
                if port.get_data_type() == PortDataType.kVectorValued
                else self.DeclareAbstractInputPort(port.get_name(),
                                                   port.Allocate()))
            if port.HasValue(context):
                connected.append(self._inputs[-1])
        self._connected = connected
        if context.num_discrete_state_groups() > 0:
            self.DeclareDiscreteState(
                context.get_discrete_state_vector().size())
            self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0,
                                                    self._update)
        # The outputs that depend on the same inputs share one cache entry
        # that evaluates them, as a stage's outputs share its result.
        shared = {}
        for j in range(stage.num_output_ports()):
            port = stage.get_output_port(j)
            through = tuple(i for i in range(len(self._inputs))
                            if stage.HasDirectFeedthrough(i, j))
            if through not in shared:
                shared[through] = self._declare_pull(through)
            prerequisites = {shared[through].ticket()}
            if port.get_data_type() == PortDataType.kVectorValued:
                self.DeclareVectorOutputPort(
                    port.get_name(), port.size(),
                    self._vector_output(shared[through], port.size()),
                    prerequisites_of_calc=prerequisites)
            else:
                self.DeclareAbstractOutputPort(
                    port.get_name(), port.Allocate().Clone,
                    lambda context, value, entry=shared[through]:
                        entry.Eval(context),
                    prerequisites_of_calc=prerequisites)

    def _declare_pull(self, through):
        """A cache entry that evaluates the connected inputs among
        `through` (indices), recomputed when they or the state change."""
        ports = [self._inputs[i] for i in through
                 if self._inputs[i] in self._connected]

        def calc(context, value):
            self._pull(context, ports)

        return self.DeclareCacheEntry(
            f"pull{list(through)}",
            ValueProducer(allocate=lambda: AbstractValue.Make(0),
                          calc=calc),
            {self.all_state_ticket(),
             *(self._inputs[i].ticket() for i in through)})

    @staticmethod
    def _pull(context, ports):
        for port in ports:
            port.Eval(context)

    @staticmethod
    def _vector_output(entry, size):
        zeros = np.zeros(size)

        def calc(context, output):
            entry.Eval(context)
            output.SetFromVector(zeros)

        return calc

    def _update(self, context, discrete_state):
        self._pull(context, self._connected)


class FloorTicker(DiagramTicker):
    """The hollow copy of a ControllerTicker's controller, in a Simulator
    of its own, against the same measurements, ticked as the controller
    is (a DiagramTicker: AdvanceTo((k + 1) h), the station's commands
    pulled after each).

    Its hollow stages (`stages`, by the controller's names) tick alone
    as the controller's do (control_tick.stage_tickers), so that each
    stage's own work is its tick less its hollow twin's.

    Args:
        ticker: a drake_wbc.bench.control_tick.ControllerTicker.
    """

    def __init__(self, ticker):
        controller = ticker.controller
        builder = DiagramBuilder()
        hollow = {}
        for name, stage in controller.stages.items():
            hollow[id(stage)] = builder.AddNamedSystem(name, HollowStage(
                stage, stage.GetMyContextFromRoot(ticker.context),
                ticker.time_step))
        wired = controller.diagram
        for (destination, i), (source, j) in (
                wired.connection_map().items()):
            builder.Connect(hollow[id(source)].get_output_port(j),
                            hollow[id(destination)].get_input_port(i))
        for i in range(wired.num_input_ports()):
            name = wired.get_input_port(i).get_name()
            guard = hollow[id(controller.stages["guard"])]
            builder.ExportInput(guard.GetInputPort(name), name)
        for i in range(wired.num_output_ports()):
            source, j = wired.get_output_port_locator(OutputPortIndex(i))
            builder.ExportOutput(hollow[id(source)].get_output_port(j),
                                 wired.get_output_port(i).get_name())
        super().__init__(
            builder.Build(), {name: hollow[id(stage)] for name, stage
                              in controller.stages.items()},
            ticker.time_step, ticker.values)
