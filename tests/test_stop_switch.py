"""StopSwitch, Drake's C++ systems of drake_wbc.math.gating: held to
stop_switched and to the StopGate without limits it stands in for, in
double and AutoDiffXd, and linearised."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue
from pydrake.symbolic import Variable
from pydrake.systems.framework import InputPortIndex, OutputPortIndex
from pydrake.systems.primitives import Linearize

from drake_wbc.math.gating import stop_switched
from drake_wbc.stages import StopGate, StopSwitch


def _evaluate(system, context, value, stop):
    system.GetInputPort("value").FixValue(context, value)
    system.GetInputPort("stop").FixValue(context, [stop])
    return np.asarray(system.GetOutputPort("gated").Eval(context))


@pytest.mark.parametrize("size", [3, 6])
def test_the_switch_is_stop_switched_and_the_gate_without_limits(size):
    """On random values and stops (either side of 0.5, and on it), in
    double and AutoDiffXd: gated equals math.gating.stop_switched and
    the StopGate's output exactly."""
    switch, gate = StopSwitch(size), StopGate(size)
    pairs = [(switch, gate, 0.5),
             (switch.ToAutoDiffXd(), gate.ToAutoDiffXd(), 0.51)]
    rng = np.random.default_rng(7)
    for ours, theirs, on_threshold in pairs:
        contexts = [s.CreateDefaultContext() for s in (ours, theirs)]
        for _ in range(40):
            value = rng.normal(size=size)
            stop = rng.choice([0.0, 1.0, on_threshold, 0.49, rng.random()])
            gated, expected = (
                _evaluate(s, c, value, stop)
                for s, c in zip((ours, theirs), contexts, strict=True))
            np.testing.assert_array_equal(
                ExtractValue(gated).ravel(), stop_switched(value, stop))
            np.testing.assert_array_equal(ExtractValue(gated),
                                          ExtractValue(expected))


def test_autodiff_derivatives_pass_through_or_stop():
    switch = StopSwitch(3).ToAutoDiffXd()
    context = switch.CreateDefaultContext()
    value = np.array([AutoDiffXd(v, g) for v, g in
                      zip([0.1, -0.2, 0.3], np.eye(3), strict=True)])
    for stop, expected in ((0.0, np.eye(3)), (1.0, np.zeros((3, 3)))):
        switch.GetInputPort("value").FixValue(context, value)
        switch.GetInputPort("stop").FixValue(
            context, [AutoDiffXd(stop, np.ones(3))])
        gated = switch.GetOutputPort("gated").Eval(context)
        np.testing.assert_array_equal(ExtractGradient(gated), expected)


def test_autodiff_has_no_derivative_on_the_threshold():
    """A stop of exactly 0.5 in AutoDiffXd (which InputGuard never sends:
    0 or 1) has no derivative: Drake's symbolic derivative of the switch
    is NaN there, and the evaluation says so."""
    switch = StopSwitch(3).ToAutoDiffXd()
    context = switch.CreateDefaultContext()
    with pytest.raises(RuntimeError, match="NaN"):
        _evaluate(switch, context, np.ones(3), 0.5).__next__()


def test_the_switch_linearises_to_the_identity_or_zero():
    switch = StopSwitch(3)
    context = switch.CreateDefaultContext()
    for stop, expected in ((0.0, np.eye(3)), (1.0, np.zeros((3, 3)))):
        switch.GetInputPort("value").FixValue(context, [0.2, -0.1, 0.05])
        switch.GetInputPort("stop").FixValue(context, [stop])
        linear = Linearize(switch, context,
                           input_port_index=InputPortIndex(0),
                           output_port_index=OutputPortIndex(0))
        np.testing.assert_array_equal(linear.D(), expected)


def test_stop_switched_builds_if_then_else_on_symbols():
    value, stop = [Variable("v0"), Variable("v1")], Variable("stop")
    expressions = stop_switched(value, stop)
    for entry, v in zip(expressions, value, strict=True):
        env = {v: 2.5, stop: 0.0}
        assert entry.Evaluate(env) == 2.5
        env[stop] = 0.5
        assert entry.Evaluate(env) == 0.0


@pytest.mark.parametrize("stage", [StopSwitch, StopGate])
def test_the_size_is_checked(stage):
    """A size that is not a whole number >= 1 is refused by both stages
    alike; a whole float gives ports of that size."""
    for size in (0, -1, 2.7, True):
        with pytest.raises(ValueError, match="size"):
            stage(size)
    system = stage(3.0)
    assert system.size == 3
    assert system.GetInputPort("value").size() == 3
