"""StopSwitch: a signal zeroed during a safe stop, as Drake's C++
systems (its math: drake_wbc.math.gating). The gate that also keeps a
signal within an envelope is StopGate (drake_wbc.stages.safety)."""

from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import MakeVectorVariable
from pydrake.systems.framework import Diagram_
from pydrake.systems.primitives import Multiplexer_, SymbolicVectorSystem_

from drake_wbc.math.gating import stop_switched
from drake_wbc.math.validation import whole_number
from drake_wbc.stages.support import build_composite, define_composite_stage

MODEL_NAME = "stop_switched"
"""The name of the stage's SymbolicVectorSystem inside it."""


def stop_switch_expressions(size):
    """(inputs, outputs): the symbolic [value (size); stop] and
    math.gating.stop_switched of them, the expressions of the stage."""
    inputs = MakeVectorVariable(size + 1, "u")
    return inputs, stop_switched(inputs[:size], inputs[size])


@define_composite_stage("StopSwitch_", scalars=(float, AutoDiffXd))
def StopSwitch_(T):
    class Impl(Diagram_[T]):
        """Passes a vector on, or zeros during a safe stop.

        ::

                     ┌────────────┐
            value ──►│            │
            stop ───►│ StopSwitch ├──► gated
                     └────────────┘

        - value: (size) the signal.
        - stop (1): >= 0.5 during a stop (InputGuard's `stop`).
        - gated: (size) zeros while stop, otherwise the very values;
          direct feedthrough of both inputs (the `gated` of a StopGate
          without limits).

        It holds an integrating stage while stopped: the controller
        zeroes the inputs of the DMPs' couplings with it
        (drake_wbc.controller.diagram), so that they do not integrate
        during a stop. In AutoDiffXd the gated output's derivatives are
        those of the value (or zero while stopped), none from the stop;
        on the threshold itself (a stop of exactly 0.5, which InputGuard
        never sends: it sends 0 or 1) Drake's symbolic derivative of the
        switch is NaN, and the AutoDiffXd evaluation raises.

        Built of Drake's C++ systems, so that no Python runs in its tick:
        a Multiplexer of [value; stop] into a SymbolicVectorSystem
        (named MODEL_NAME) of drake_wbc.math.gating.stop_switched
        evaluated on symbolic variables (stop_switch_expressions).
        tests/test_stop_switch.py holds it
        to stop_switched on random inputs, in double and AutoDiffXd, and
        to the StopGate without limits. Its scalar-converted copies are
        Drake's (stages.support.define_composite_stage).

        Args:
            size: the signal's size (>= 1).
        """

        def __init__(self, size=3):
            Diagram_[T].__init__(self)
            self.size = size = whole_number("size", size, minimum=1)
            inputs, outputs = stop_switch_expressions(size)

            def build(builder):
                join = builder.AddNamedSystem(
                    "value_and_stop", Multiplexer_[T]([size, 1]))
                switch = builder.AddNamedSystem(
                    MODEL_NAME, SymbolicVectorSystem_[T](
                        input=inputs, output=outputs))
                builder.Connect(join.get_output_port(),
                                switch.get_input_port())
                builder.ExportInput(join.get_input_port(0), "value")
                builder.ExportInput(join.get_input_port(1), "stop")
                builder.ExportOutput(switch.get_output_port(), "gated")

            build_composite(self, T, build)

    return Impl


StopSwitch = StopSwitch_[None]
"""StopSwitch_ for double; `ToAutoDiffXd()` gives Drake's AutoDiffXd
copy of it."""
