"""No wind-up behind the base's limits: the repulsive field of eq.
(cdmp-base) is bounded in norm, and the StopGate keeps the base filter's
input, hence its state (eq. (filtering), zeta >= 1), within the base's
velocity limits, however many obstacle points crowd the footprint."""

from dataclasses import replace

import numpy as np
import pytest
from controller_rig import Rig
from pydrake.systems.framework import InputPortIndex
from pydrake.systems.primitives import Linearize
from shipped_names import BASE_VELOCITY_LIMITS, FOOTPRINT

from drake_wbc.controller import ControllerParameters
from drake_wbc.math.repulsion import RepulsiveFieldParameters, repulsive_force
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages import StopGate

V_MAX = np.array(BASE_VELOCITY_LIMITS)
TOL = 1e-9


def crowd(count=40, seed=3):
    """`count` points of a person pressing on the footprint's front right
    corner (0.4, -0.3), some of them inside it."""
    rng = np.random.default_rng(seed)
    return np.array([0.42, -0.28]) + rng.uniform(-0.08, 0.08, (count, 2))


def test_the_field_is_bounded_in_norm_with_its_direction_kept():
    points = crowd()
    unbounded = repulsive_force(points, RepulsiveFieldParameters(
        half_sizes=FOOTPRINT, max_force=1e12))
    assert np.linalg.norm(unbounded) > 1000.0  # the paper's field
    for bound in (80.0, 5.0):
        force = repulsive_force(points, RepulsiveFieldParameters(
            half_sizes=FOOTPRINT, max_force=bound))
        assert np.linalg.norm(force) == pytest.approx(bound, rel=1e-12)
        np.testing.assert_allclose(
            force / bound, unbounded / np.linalg.norm(unbounded),
            rtol=1e-12)
    weak = np.array([[0.8, 0.0]])  # 0.4 m from the footprint, |f| = 0.0313
    np.testing.assert_array_equal(
        repulsive_force(weak, RepulsiveFieldParameters(
            half_sizes=FOOTPRINT)),
        repulsive_force(weak, RepulsiveFieldParameters(
            half_sizes=FOOTPRINT, max_force=1e12)))


def test_max_force_is_validated():
    with pytest.raises(ValueError, match="max_force = 0"):
        RepulsiveFieldParameters(half_sizes=FOOTPRINT, max_force=0.0)


def gate_output(gate, value, stop=0.0):
    context = gate.CreateDefaultContext()
    gate.GetInputPort("value").FixValue(context, value)
    gate.GetInputPort("stop").FixValue(context, [stop])
    return gate.GetOutputPort("gated").Eval(context)


def test_the_gate_scales_as_a_whole_into_its_envelope():
    gate = StopGate(3, limits=[1.0, 1.0, 0.5])
    inside = np.array([0.3, -0.9, 0.4])
    np.testing.assert_array_equal(gate_output(gate, inside), inside)
    over = np.array([3.0, -1.0, 0.5])
    np.testing.assert_allclose(gate_output(gate, over), over / 3.0,
                               rtol=1e-15)
    yaw = np.array([0.1, 0.2, -2.0])
    np.testing.assert_allclose(gate_output(gate, yaw), yaw / 4.0,
                               rtol=1e-15)
    np.testing.assert_array_equal(gate_output(gate, over, stop=1.0), 0.0)
    np.testing.assert_array_equal(gate_output(StopGate(3), over), over)
    with pytest.raises(ValueError, match=r"limits\[1\] = -1.0"):
        StopGate(3, limits=[1.0, -1.0, 1.0])


@pytest.mark.parametrize("value", [
    [0.2, -0.1, 0.05],     # within the limits: the identity
    [3.0, -1.0, 0.5],      # beyond on x: scaled as a whole
    [0.1, 0.2, -2.0],      # beyond on the yaw rate
], ids=["inside", "beyond-x", "beyond-yaw"])
def test_the_gate_converts_and_linearises_to_its_jacobian(value):
    """Drake's Linearize of the gate (through its AutoDiffXd copy) is the
    Jacobian of what it sends: the identity within the limits; beyond
    them, where the k-th entry binds, g(v) = s v with s = L_k / |v_k|,
    so dg/dv = s (I - v e_k^T / v_k) and ds/dv = -s e_k^T / v_k (the
    scale's own derivative once dropped, which gave D = s I: 0.33 on the
    binding entry, whose sent value L_k does not move, and 0 off the
    diagonal), held to central differences of the double gate too."""
    value = np.array(value)
    gate = StopGate(3, limits=V_MAX).ToAutoDiffXd()
    assert gate.limits == tuple(V_MAX)
    context = gate.CreateDefaultContext()
    gate.GetInputPort("value").FixValue(context, value)
    gate.GetInputPort("stop").FixValue(context, [0.0])
    np.testing.assert_allclose(
        [x.value() for x in gate.GetOutputPort("gated").Eval(context)],
        gate_output(StopGate(3, limits=V_MAX), value), rtol=1e-15)
    double = StopGate(3, limits=V_MAX)
    context = double.CreateDefaultContext()
    double.GetInputPort("value").FixValue(context, value)
    double.GetInputPort("stop").FixValue(context, [0.0])
    ratios = V_MAX / np.abs(value)
    k = int(np.argmin(ratios))
    s = min(1.0, ratios[k])
    expected = np.eye(3) if s == 1.0 else s * (
        np.eye(3) - np.outer(value, np.eye(3)[k]) / value[k])
    step = 1e-7
    central = np.column_stack([
        (gate_output(double, value + step * e)
         - gate_output(double, value - step * e)) / (2 * step)
        for e in np.eye(3)])
    np.testing.assert_allclose(central, expected, atol=1e-7)
    # (The scale within the limits is the constant 1, with no derivative:
    # Drake's Linearize cannot take an output that depends on neither the
    # state nor the input, so it is linearised beyond them only.)
    outputs = [("gated", expected)] + ([] if s == 1.0 else [
        ("scale", -s * np.eye(3)[[k]] / value[k])])
    for output, jacobian in outputs:
        linear = Linearize(double, context,
                           input_port_index=InputPortIndex(0),
                           output_port_index=double.GetOutputPort(
                               output).get_index())
        np.testing.assert_allclose(linear.D(), jacobian, atol=1e-12)


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


@pytest.mark.parametrize("max_force", [80.0, 1e12],
                         ids=["bounded-field", "paper-field"])
def test_a_crowd_at_the_footprint_cannot_wind_up_the_filter(arm, max_force):
    """Even with the paper's unbounded field, whose V_b' runs to tens of
    m/s, the filter's output (and so the command) stays within the base's
    limits; the bounded field also keeps V_b' itself moderate."""
    params = ControllerParameters()
    params.base_cdmp.repulsion.max_force = max_force
    rig = Rig(arm, params, q=HOME_ARM_POSITIONS)
    rig.set("reference_velocity", np.zeros(6))
    rig.set("lidar.obstacle_points", crowd())
    rig.advance(0.08)  # about the attractor's time constant, 1 / 12.5 s
    avoiding = rig.controller.stages["base_cdmp"]
    v_b = avoiding.GetOutputPort("avoiding_base_velocity").Eval(
        avoiding.GetMyContextFromRoot(rig.root_context))
    rig.advance(0.92)
    _, filtered = rig.log("filtered_base_velocity")
    _, command = rig.log("base.velocity_command")
    assert np.all(np.isfinite(filtered))
    assert np.all(np.abs(filtered) <= V_MAX + TOL)
    assert np.all(np.abs(command) <= V_MAX + TOL)
    # Pushed along the field, away from the corner (backwards and left).
    push = repulsive_force(crowd(), replace(params.base_cdmp.repulsion,
                                            half_sizes=FOOTPRINT))
    assert push[0] < 0.0 and push[1] > 0.0
    assert filtered[-1, :2] @ push / np.linalg.norm(push) > 0.05
    if max_force == 80.0:
        assert np.linalg.norm(v_b[:2]) < 4.0
    else:
        assert np.linalg.norm(v_b[:2]) > 10.0
