"""The coordination stages (ArmCapability, WorkspaceAdapter,
MotionDistributor, RobustCompensator) through their ports, against the math
layer called independently, closed forms and finite differences."""

import numpy as np
import pytest
from pydrake.autodiffutils import (
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Sine,
    VectorLogSink,
)

from drake_wbc.math import (
    capability,
    compensation,
    distribution,
    workspace,
)
from drake_wbc.math.capability import ArmCapabilityParameters, CapabilityBand
from drake_wbc.math.compensation import RobustCompensatorParameters
from drake_wbc.math.distribution import MotionDistributorParameters
from drake_wbc.math.kinematics import base_jacobian, whole_body_jacobian
from drake_wbc.math.workspace import (
    LocalWorkspace,
    WorkspaceAdapterParameters,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages import (
    ArmCapability,
    BaseVelocityFilter,
    MotionDistributor,
    RobustCompensator,
    WorkspaceAdapter,
)

ARM = ArmKinematics()
R_BA = ARM.R_ba
_home = ARM.evaluate(HOME_ARM_POSITIONS)
ARM_BASE = _home.p_ee_in_base - R_BA @ _home.X_AE.translation()
BAND = CapabilityBand()
H = 1e-6


def evaluate(system, inputs, context=None):
    """Fixes `inputs` (name -> value) and returns every output by name."""
    context = context or system.CreateDefaultContext()
    for name, value in inputs.items():
        system.GetInputPort(name).FixValue(context, np.atleast_1d(value))
    return {
        system.get_output_port(i).get_name():
            system.get_output_port(i).Eval(context)
        for i in range(system.num_output_ports())
    }


def flatten(inputs):
    return np.concatenate([np.atleast_1d(v) for v in inputs.values()])


def unflatten(inputs, x):
    result, start = {}, 0
    for name, value in inputs.items():
        size = np.atleast_1d(value).size
        result[name] = x[start:start + size]
        start += size
    return result


def autodiff_jacobians(system, inputs):
    """Outputs' values and their Jacobians w.r.t. all inputs (stacked in
    the order of `inputs`), from the system's ToAutoDiffXd()."""
    converted = system.ToAutoDiffXd()
    context = converted.CreateDefaultContext()
    x = InitializeAutoDiff(flatten(inputs)).ravel()
    for name, value in unflatten(inputs, x).items():
        converted.GetInputPort(name).FixValue(context, value)
    result = {}
    for i in range(converted.num_output_ports()):
        port = converted.get_output_port(i)
        y = port.Eval(context)
        result[port.get_name()] = (ExtractValue(y).ravel(),
                                   ExtractGradient(y))
    return result


def finite_difference_jacobians(system, inputs, step=H):
    """Central differences of the double system's outputs."""
    x0 = flatten(inputs)
    columns = {}
    for i in range(x0.size):
        dx = np.zeros_like(x0)
        dx[i] = step
        plus = evaluate(system, unflatten(inputs, x0 + dx))
        minus = evaluate(system, unflatten(inputs, x0 - dx))
        for name in plus:
            columns.setdefault(name, []).append(
                (plus[name] - minus[name]) / (2 * step))
    return {name: np.stack(c, axis=1) for name, c in columns.items()}


def assert_autodiff_matches(system, inputs, rtol=1e-6, atol=1e-7):
    exact = autodiff_jacobians(system, inputs)
    numeric = finite_difference_jacobians(system, inputs)
    values = evaluate(system, inputs)
    for name, (value, gradient) in exact.items():
        np.testing.assert_allclose(value, values[name], rtol=1e-12,
                                   atol=1e-14)
        scale = max(np.abs(numeric[name]).max(), 1.0)
        np.testing.assert_allclose(gradient, numeric[name], rtol=rtol,
                                   atol=atol * scale)
    return numeric


def random_arm_position(rng):
    return rng.uniform(0.8 * ARM.lower, 0.8 * ARM.upper)


# ArmCapability -----------------------------------------------------------

def test_arm_capability_matches_kinematics_and_capability():
    system = ArmCapability()
    rng = np.random.default_rng(10)
    for _ in range(10):
        q = random_arm_position(rng)
        out = evaluate(system, {"arm_position": q})
        values = ARM.evaluate(q)
        C_m = capability.capability(values.J_a, q, ARM.lower, ARM.upper)
        np.testing.assert_allclose(out["end_effector_position"],
                                   values.p_ee_in_base, atol=1e-14)
        assert out["capability"][0] == pytest.approx(C_m, rel=1e-12)
        np.testing.assert_allclose(
            out["capability_gradient"],
            capability.capability_gradient(values.J_a, q, ARM.lower,
                                           ARM.upper), rtol=1e-10,
            atol=1e-14)
        assert out["alpha"][0] == pytest.approx(
            capability.transition(C_m, 0.04, 0.035), abs=1e-14)


def test_arm_capability_alpha_at_the_band_edges():
    C_m = capability.capability(_home.J_a, HOME_ARM_POSITIONS, ARM.lower,
                                ARM.upper)
    for band, alpha in (
        (CapabilityBand(C_m, C_m + 0.01), 1.0),
        (CapabilityBand(C_m - 0.01, C_m), 0.0),
        (CapabilityBand(C_m - 0.01, C_m + 0.01), 0.5),
        (CapabilityBand(C_m - 0.02, C_m + 0.02), 0.5),
        (CapabilityBand(C_m - 0.01, C_m + 0.03), 0.5 * (1 + np.cos(0.25
                                                                  * np.pi))),
    ):
        system = ArmCapability(ArmCapabilityParameters(), ARM, band=band)
        out = evaluate(system, {"arm_position": HOME_ARM_POSITIONS})
        assert out["alpha"][0] == pytest.approx(alpha, abs=1e-12)
    default = evaluate(ArmCapability(ArmCapabilityParameters(), ARM),
                       {"arm_position": HOME_ARM_POSITIONS})
    assert default["alpha"][0] == 0.0  # C_m = 0.065 at home, above 0.04


class CountingArm(ArmKinematics):
    calls = 0

    def evaluate(self, q_a):
        CountingArm.calls += 1
        return super().evaluate(q_a)


def test_arm_capability_evaluates_the_kinematics_once_per_context():
    system = ArmCapability(arm=CountingArm())
    context = system.CreateDefaultContext()
    CountingArm.calls = 0
    evaluate(system, {"arm_position": HOME_ARM_POSITIONS}, context)
    evaluate(system, {}, context)
    assert CountingArm.calls == 1
    evaluate(system, {"arm_position": 0.5 * HOME_ARM_POSITIONS}, context)
    assert CountingArm.calls == 2


def test_arm_capability_autodiff_matches_finite_differences():
    rng = np.random.default_rng(11)
    inputs = {"arm_position": random_arm_position(rng)}
    assert_autodiff_matches(ArmCapability(arm=ARM), inputs, rtol=1e-5)


# WorkspaceAdapter --------------------------------------------------------

def phri_inputs(p_a, V_a=None, C_m=0.06, g=None):
    """Inputs for an end-effector position and twist given in T_a."""
    V_a = np.zeros(6) if V_a is None else V_a
    return {
        "end_effector_position": ARM_BASE + R_BA @ p_a,
        "end_effector_velocity": np.concatenate([R_BA @ V_a[:3],
                                                 R_BA @ V_a[3:]]),
        "capability": C_m,
        "capability_gradient": np.zeros(6) if g is None else g,
    }


PHRI = WorkspaceAdapterParameters(mode="intuitive-phri",
                                  deactivation_speed=0.0, max_rate=100.0)
"""The paper's rule, applied at the instant: no hysteresis, and a step of
max_rate h = 1 a tick is no rate limit (tests/test_weighting_smoothing.py
holds the stage's defaults)."""


def sigmas(system, inputs):
    out = evaluate(system, inputs)
    return out["sigma_xy"][0], out["sigma_phi"][0]


@pytest.mark.parametrize("params, expected", [
    (WorkspaceAdapterParameters(mode="locomotion"), (0.0, 0.0)),
    (WorkspaceAdapterParameters(mode="manipulation"), (1.0, 1.0)),
    (WorkspaceAdapterParameters(), (0.5, 0.5)),
    (WorkspaceAdapterParameters(mode="loco-manipulation", sigma_xy=0.2,
                                sigma_phi=0.9), (0.2, 0.9)),
])
def test_fixed_modes_need_no_input(params, expected):
    system = WorkspaceAdapter(params, ARM)
    assert sigmas(system, {}) == expected
    assert not system.HasAnyDirectFeedthrough()


def test_phri_matches_the_math_layer():
    system = WorkspaceAdapter(PHRI, ARM)
    assert system.HasAnyDirectFeedthrough()
    rng = np.random.default_rng(12)
    for _ in range(100):
        p_a = np.array([*(rng.uniform(0.7, 0.85) * np.array(
            [np.cos(a := rng.uniform(-0.8, 0.8)), np.sin(a)])), 0.3])
        inputs = phri_inputs(p_a, rng.normal(size=6) * 0.1,
                             rng.uniform(0.03, 0.07), rng.normal(size=6)
                             * 0.01)
        state = workspace.local_workspace_state(
            inputs["end_effector_position"], inputs["end_effector_velocity"],
            inputs["capability"], inputs["capability_gradient"], 0.04,
            0.035, LocalWorkspace(), R_BA, ARM_BASE)
        assert sigmas(system, inputs) == (state.sigma_xy, state.sigma_phi)


def test_phri_limits_through_the_ports():
    system = WorkspaceAdapter(PHRI, ARM)
    home = phri_inputs(_home.X_AE.translation())
    assert sigmas(system, home) == (1.0, 1.0)  # home is inside
    outward = np.array([0.1, 0, 0, 0, 0, 0])
    assert sigmas(system, phri_inputs(np.array([0.82, 0, 0.3]),
                                      outward)) == (0.0, 1.0)
    assert sigmas(system, phri_inputs(np.array([0.82, 0, 0.3]),
                                      -outward)) == (1.0, 1.0)
    side = 0.6 * np.array([np.cos(0.7), np.sin(0.7), 0.0])
    turning_away = np.array([-side[1], side[0], 0, 0, 0, 0])
    assert sigmas(system, phri_inputs(side, turning_away)) == (0.0, 0.0)
    assert sigmas(system, phri_inputs(side, -turning_away)) == (0.0, 1.0)
    in_band = sigmas(system, phri_inputs(np.array([0.771, 0, 0.3]),
                                         outward))
    assert 0.0 < in_band[0] < 1.0 and in_band[1] == 1.0


def test_phri_autodiff_matches_finite_differences():
    p_a = 0.757 * np.array([np.cos(0.5585), np.sin(0.5585), 0.0])
    p_a[2] = 0.3
    radial = np.array([np.cos(0.5585), np.sin(0.5585)])
    V = np.array([*(0.1 * radial + 0.05 * np.array([-radial[1], radial[0]])),
                  0, 0, 0, 0])
    inputs = phri_inputs(p_a, V, 0.0596,
                         np.array([0.001, -0.002, 0, 0, 0, 0]))
    values = sigmas(WorkspaceAdapter(PHRI, ARM), inputs)
    assert all(0 < s < 1 for s in values)
    numeric = assert_autodiff_matches(WorkspaceAdapter(PHRI, ARM), inputs,
                                      rtol=1e-5)
    assert np.abs(numeric["sigma_xy"]).max() > 1.0


# MotionDistributor -------------------------------------------------------

def distributor_inputs(rng, C_m=None):
    return {
        "end_effector_velocity": rng.normal(size=6),
        "sigma_xy": rng.uniform(),
        "sigma_phi": rng.uniform(),
        "end_effector_position": rng.uniform(-1.0, 1.0, size=3),
        "capability": rng.uniform(0.03, 0.045) if C_m is None else C_m,
        "capability_gradient": rng.normal(size=6),
    }


def split(out):
    return np.concatenate([out["arm_velocity"], out["base_velocity"]])


def test_distributor_matches_eq_wbccm():
    rng = np.random.default_rng(13)
    system = MotionDistributor(MotionDistributorParameters(
        null_space_gain=0.1), ARM)
    for _ in range(100):
        inputs = distributor_inputs(rng)
        J = whole_body_jacobian(None, inputs["end_effector_position"], R_BA)
        k = 0.1 * capability.transition(inputs["capability"], 0.04, 0.035)
        expected = distribution.distribute(
            J, inputs["end_effector_velocity"], inputs["sigma_xy"],
            inputs["sigma_phi"], distribution.capability_null_velocity(
                inputs["capability_gradient"], k))
        out = split(evaluate(system, inputs))
        np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(J @ out, inputs["end_effector_velocity"],
                                   atol=1e-12)


def test_null_space_term_never_moves_the_end_effector():
    rng = np.random.default_rng(14)
    system = MotionDistributor(arm=ARM)
    moved = 0.0
    for _ in range(50):
        inputs = distributor_inputs(rng, C_m=0.03)
        context = system.CreateDefaultContext()
        without = split(evaluate(system, inputs, context))
        system.GetInputPort("null_space_gain").FixValue(context, [0.1])
        with_gain = split(evaluate(system, {}, context))
        J = whole_body_jacobian(None, inputs["end_effector_position"], R_BA)
        np.testing.assert_allclose(J @ (with_gain - without), 0.0,
                                   atol=1e-12)
        moved = max(moved, np.abs(with_gain - without).max())
    assert moved > 1e-2


def test_null_space_gain_port_overrides_the_parameter():
    rng = np.random.default_rng(15)
    inputs = distributor_inputs(rng, C_m=0.03)
    by_parameter = MotionDistributor(MotionDistributorParameters(
        null_space_gain=0.1), ARM)
    by_port = MotionDistributor(arm=ARM)
    off = split(evaluate(by_port, inputs))
    on = split(evaluate(by_parameter, inputs))
    assert np.abs(on - off).max() > 1e-3
    np.testing.assert_allclose(
        split(evaluate(by_port, {**inputs, "null_space_gain": 0.1})), on,
        rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(
        split(evaluate(by_parameter, {**inputs, "null_space_gain": 0.0})),
        off, rtol=1e-14, atol=1e-15)
    with pytest.raises(ValueError, match="null_space_gain"):
        evaluate(by_port, {**inputs, "null_space_gain": -0.1})


@pytest.mark.parametrize("smooth", [True, False])
def test_null_space_gain_switches_off_above_the_upper_threshold(smooth):
    system = MotionDistributor(MotionDistributorParameters(
        null_space_gain=0.1, smooth_switch_off=smooth), ARM)
    for C_m, factor in ((0.03, 1.0), (0.035, 1.0), (0.0375, 0.5),
                        (0.04, 1.0 if not smooth else 0.0), (0.0401, 0.0),
                        (0.06, 0.0)):
        if not smooth and 0.035 < C_m < 0.04:
            factor = 1.0
        context = system.CreateDefaultContext()
        system.GetInputPort("capability").FixValue(context, [C_m])
        assert system.null_space_gain(context) == pytest.approx(0.1 * factor)


def test_the_switch_off_follows_the_band_it_is_given():
    """The band argument (build_controller's capability_band) places the
    switch-off of k_n, in the stage and in its AutoDiffXd copy."""
    system = MotionDistributor(MotionDistributorParameters(
        null_space_gain=0.1), ARM, band=CapabilityBand(0.05, 0.07))
    for C_m, factor in ((0.04, 1.0), (0.05, 1.0), (0.06, 0.5), (0.07, 0.0)):
        for stage in (system, system.ToAutoDiffXd()):
            context = stage.CreateDefaultContext()
            stage.GetInputPort("capability").FixValue(context, [C_m])
            gain = stage.null_space_gain(context)
            gain = gain.value() if hasattr(gain, "value") else gain
            assert gain == pytest.approx(0.1 * factor, abs=1e-15)


def test_distributor_autodiff_matches_finite_differences():
    rng = np.random.default_rng(16)
    inputs = distributor_inputs(rng, C_m=0.037)
    inputs["null_space_gain"] = 0.1
    assert_autodiff_matches(MotionDistributor(arm=ARM), inputs)


def test_autodiff_distribution_with_damping_matches_the_math_layer():
    """distribution.weighted_distribution in AutoDiffXd on a general J
    near singularity (damping active): its value is
    distribution.distribute's, its derivative central differences of
    it."""
    rng = np.random.default_rng(17)
    J0 = rng.normal(size=(6, 9))
    J0[5] = J0[4] + 1e-4 * rng.normal(size=9)  # nearly rank 5
    V_ee, V_n = rng.normal(size=6), rng.normal(size=9)
    M = J0 @ distribution.weighting_matrix(0.3, 0.6) @ J0.T
    eigenvalues = np.linalg.eigvalsh(M)
    assert eigenvalues[0] < 1e-4 * eigenvalues[-1]  # damping is active

    def pack(x):
        return x[:54].reshape(6, 9), x[54:60], x[60], x[61], x[62:]

    x0 = np.concatenate([J0.ravel(), V_ee, [0.3, 0.6], V_n])
    x = InitializeAutoDiff(x0).ravel()
    J, V, sigma_xy, sigma_phi, null = pack(x)
    result = distribution.weighted_distribution(
        J, V, distribution.weight_factors(sigma_xy, sigma_phi), null)
    np.testing.assert_allclose(ExtractValue(result).ravel(),
                               distribution.distribute(*pack(x0)),
                               rtol=1e-9, atol=1e-12)
    numeric = np.stack([
        (distribution.distribute(*pack(x0 + H * e))
         - distribution.distribute(*pack(x0 - H * e))) / (2 * H)
        for e in np.eye(x0.size)], axis=1)
    np.testing.assert_allclose(ExtractGradient(result), numeric, rtol=1e-5,
                               atol=1e-6 * np.abs(numeric).max())


# RobustCompensator -------------------------------------------------------

def compensator_inputs(rng, alpha=None):
    return {
        "arm_velocity": rng.normal(size=6),
        "base_velocity": rng.normal(size=3),
        "filtered_base_velocity": rng.normal(size=3),
        "end_effector_position": rng.uniform(-1.0, 1.0, size=3),
        "capability_gradient": rng.normal(size=6),
        "alpha": rng.uniform() if alpha is None else alpha,
    }


def test_compensator_matches_eqs_wb_error_to_deviation():
    rng = np.random.default_rng(18)
    system = RobustCompensator(arm=ARM)
    for _ in range(100):
        inputs = compensator_inputs(rng)
        dV_a, dV_ee = compensation.robust_compensation(
            inputs["filtered_base_velocity"] - inputs["base_velocity"],
            base_jacobian(inputs["end_effector_position"]), R_BA,
            inputs["capability_gradient"], inputs["alpha"])
        out = evaluate(system, inputs)
        np.testing.assert_allclose(out["arm_reference_velocity"],
                                   inputs["arm_velocity"] + dV_a,
                                   rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(out["end_effector_deviation"], dV_ee,
                                   rtol=1e-14, atol=1e-15)


def compensation_residual(inputs, out):
    """R_ba dV_a + J_b dV_b: what the end effector does of the base's
    deviation plus the arm's compensation."""
    dV_a = out["arm_reference_velocity"] - inputs["arm_velocity"]
    dV_b = inputs["filtered_base_velocity"] - inputs["base_velocity"]
    R6 = np.kron(np.eye(2), R_BA)
    return R6 @ dV_a + base_jacobian(inputs["end_effector_position"]) @ dV_b


def test_alpha_zero_compensates_exactly():
    rng = np.random.default_rng(19)
    system = RobustCompensator(arm=ARM)
    for _ in range(50):
        inputs = compensator_inputs(rng, alpha=0.0)
        out = evaluate(system, inputs)
        np.testing.assert_allclose(compensation_residual(inputs, out), 0.0,
                                   atol=1e-14)
        np.testing.assert_array_equal(out["end_effector_deviation"], 0.0)


def test_alpha_one_leaves_out_the_gradient_direction():
    rng = np.random.default_rng(20)
    system = RobustCompensator(arm=ARM)
    for _ in range(50):
        inputs = compensator_inputs(rng, alpha=1.0)
        g = inputs["capability_gradient"]
        out = evaluate(system, inputs)
        dV_a = out["arm_reference_velocity"] - inputs["arm_velocity"]
        assert g @ dV_a == pytest.approx(0.0, abs=1e-13)
        # What is left out is the deviation, along g.
        residual = compensation_residual(inputs, out)
        np.testing.assert_allclose(
            residual, np.kron(np.eye(2), R_BA) @ out[
                "end_effector_deviation"], atol=1e-13)
        deviation = out["end_effector_deviation"]
        np.testing.assert_allclose(deviation - (deviation @ g) / (g @ g) * g,
                                   0.0, atol=1e-13)


def test_switch_off_compensates_exactly():
    rng = np.random.default_rng(21)
    by_parameter = RobustCompensator(RobustCompensatorParameters(
        compensation_switch=0.0), ARM)
    by_port = RobustCompensator(arm=ARM)
    for _ in range(20):
        inputs = compensator_inputs(rng, alpha=1.0)
        for out in (evaluate(by_parameter, inputs),
                    evaluate(by_port, {**inputs, "compensation_switch": 0})):
            np.testing.assert_allclose(compensation_residual(inputs, out),
                                       0.0, atol=1e-14)
        robust = evaluate(by_parameter, {**inputs, "compensation_switch": 1})
        assert np.abs(robust["end_effector_deviation"]).max() > 1e-3
    with pytest.raises(ValueError, match="compensation_switch"):
        evaluate(by_port, {**inputs, "compensation_switch": 2.0})
    with pytest.raises(ValueError, match="alpha"):
        evaluate(by_port, {**inputs, "alpha": 1.5})


def test_compensator_autodiff_matches_finite_differences():
    rng = np.random.default_rng(22)
    inputs = compensator_inputs(rng, alpha=0.4)
    inputs["compensation_switch"] = 0.7
    assert_autodiff_matches(RobustCompensator(arm=ARM), inputs)
    # A zero gradient (P_Cm = 0) in AutoDiffXd: the full compensation.
    inputs = {**inputs, "capability_gradient": np.zeros(6)}
    exact = autodiff_jacobians(RobustCompensator(arm=ARM), inputs)
    np.testing.assert_array_equal(exact["end_effector_deviation"][0], 0.0)
    np.testing.assert_array_equal(exact["end_effector_deviation"][1], 0.0)


BAD_PORT_VALUES = [
    (MotionDistributor, "arm_velocity", "sigma_xy", np.nan),
    (MotionDistributor, "arm_velocity", "sigma_phi", 1.5),
    (MotionDistributor, "arm_velocity", "null_space_gain", -0.1),
    (RobustCompensator, "arm_reference_velocity", "alpha", np.nan),
    (RobustCompensator, "arm_reference_velocity", "alpha", 1.5),
    (RobustCompensator, "arm_reference_velocity", "compensation_switch",
     -0.5),
]


@pytest.mark.parametrize("autodiff", [False, True])
@pytest.mark.parametrize("stage, output, name, value", BAD_PORT_VALUES)
def test_values_the_ports_cannot_constrain_are_checked(stage, output, name,
                                                       value, autodiff):
    """A weighting factor, alpha or s_c outside [0, 1], or a negative
    k_n, on its port is an error naming the port, in double and in
    AutoDiffXd."""
    system = stage(arm=ARM)
    if autodiff:
        system = system.ToAutoDiffXd()
    rng = np.random.default_rng(24)
    inputs = (distributor_inputs(rng) if stage is MotionDistributor
              else compensator_inputs(rng))
    context = system.CreateDefaultContext()
    for port_name, port_value in {**inputs, name: value}.items():
        system.GetInputPort(port_name).FixValue(context,
                                                np.atleast_1d(port_value))
    with pytest.raises(ValueError, match=name):
        system.GetOutputPort(output).Eval(context)


# The complementary split -------------------------------------------------

def test_ideal_base_needs_no_compensation():
    """V_b^flt = V_b (a base without dynamics): V_a^ref = V_a and
    J_wb [V_a^ref; V_b^flt] = V_ee, for any alpha."""
    rng = np.random.default_rng(23)
    distributor = MotionDistributor(MotionDistributorParameters(
        null_space_gain=0.1), ARM)
    compensator = RobustCompensator(arm=ARM)
    for _ in range(20):
        inputs = distributor_inputs(rng)
        V_wb = evaluate(distributor, inputs)
        out = evaluate(compensator, {
            "arm_velocity": V_wb["arm_velocity"],
            "base_velocity": V_wb["base_velocity"],
            "filtered_base_velocity": V_wb["base_velocity"],
            "end_effector_position": inputs["end_effector_position"],
            "capability_gradient": inputs["capability_gradient"],
            "alpha": rng.uniform(),
        })
        np.testing.assert_array_equal(out["arm_reference_velocity"],
                                      V_wb["arm_velocity"])
        J = whole_body_jacobian(None, inputs["end_effector_position"], R_BA)
        np.testing.assert_allclose(
            J @ np.concatenate([out["arm_reference_velocity"],
                                V_wb["base_velocity"]]),
            inputs["end_effector_velocity"], atol=1e-12)


def test_filtered_base_plus_compensation_reproduces_the_command():
    """MotionDistributor -> BaseVelocityFilter -> RobustCompensator with
    s_c = 0 (alpha = 0 used): J_wb [V_a^ref; V_b^flt] = V_ee at every
    logged instant, while the base is far from its share."""
    builder = DiagramBuilder()
    distributor = builder.AddSystem(MotionDistributor(
        MotionDistributorParameters(null_space_gain=0.1), ARM))
    base_filter = builder.AddSystem(BaseVelocityFilter())
    compensator = builder.AddSystem(RobustCompensator(
        RobustCompensatorParameters(compensation_switch=0.0), ARM))
    command = builder.AddSystem(Sine(
        amplitudes=np.array([0.1, 0.08, 0.02, 0.1, 0.05, 0.3]),
        frequencies=np.array([1.0, 2.3, 0.7, 1.5, 0.4, 3.1]),
        phases=np.array([0.0, 0.5, 1.0, 0.2, 0.0, 1.3])))
    p_ee = _home.p_ee_in_base
    constants = {
        "sigma_xy": [0.5], "sigma_phi": [0.5], "end_effector_position": p_ee,
        "capability": [0.037], "capability_gradient":
            np.array([0.02, -0.01, 0.03, 0.001, 0.002, -0.001]),
    }
    for name, value in constants.items():
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value)))
        builder.Connect(source.get_output_port(),
                        distributor.GetInputPort(name))
        if name in ("end_effector_position", "capability_gradient"):
            builder.Connect(source.get_output_port(),
                            compensator.GetInputPort(name))
    alpha = builder.AddSystem(ConstantVectorSource([
        capability.transition(0.037, 0.04, 0.035)]))
    builder.Connect(alpha.get_output_port(), compensator.GetInputPort("alpha"))
    builder.Connect(command.get_output_port(0),
                    distributor.GetInputPort("end_effector_velocity"))
    for name in ("arm_velocity", "base_velocity"):
        builder.Connect(distributor.GetOutputPort(name),
                        compensator.GetInputPort(name))
    builder.Connect(distributor.GetOutputPort("base_velocity"),
                    base_filter.get_input_port())
    builder.Connect(base_filter.get_output_port(),
                    compensator.GetInputPort("filtered_base_velocity"))
    logs = {}
    for name, port in (
        ("V_ee", command.get_output_port(0)),
        ("V_a_ref", compensator.GetOutputPort("arm_reference_velocity")),
        ("V_b_flt", base_filter.get_output_port()),
        ("V_b", distributor.GetOutputPort("base_velocity")),
    ):
        logs[name] = builder.AddSystem(VectorLogSink(port.size(), 0.005))
        builder.Connect(port, logs[name].get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(3.0)
    data = {name: log.FindLog(simulator.get_context()).data()
            for name, log in logs.items()}
    assert data["V_ee"].shape[1] > 500
    J = whole_body_jacobian(None, p_ee, R_BA)
    reproduced = J @ np.vstack([data["V_a_ref"], data["V_b_flt"]])
    np.testing.assert_allclose(reproduced, data["V_ee"], atol=1e-9)
    assert np.abs(data["V_b_flt"] - data["V_b"]).max() > 0.01


# Parameters and scalar conversion ----------------------------------------

@pytest.mark.parametrize("make, name", [
    (lambda: WorkspaceAdapterParameters(sigma_xy=1.5), "sigma_xy"),
    (lambda: WorkspaceAdapterParameters(sigma_phi=-0.1), "sigma_phi"),
    (lambda: WorkspaceAdapterParameters(sigma_xy=0.0), "sigma_xy"),
    (lambda: WorkspaceAdapterParameters(mode="walking"), "mode"),
    (lambda: WorkspaceAdapterParameters(workspace=1.0), "workspace"),
    (lambda: CapabilityBand(lower=0.04, upper=0.035), "lower"),
    (lambda: CapabilityBand(lower=0.04, upper=0.04), "lower"),
    (lambda: CapabilityBand(lower=-0.01), "lower"),
    (lambda: LocalWorkspace(extent_lower=0.8, extent_upper=0.75),
     "extent_lower"),
    (lambda: LocalWorkspace(deflection_lower=0.7, deflection_upper=0.6),
     "deflection_lower"),
    (lambda: MotionDistributorParameters(null_space_gain=-0.1),
     "null_space_gain"),
    (lambda: MotionDistributorParameters(smooth_switch_off=1),
     "smooth_switch_off"),
    (lambda: MotionDistributorParameters(damping=0.1), "damping"),
    (lambda: MotionDistributor(band=(0.03, 0.04)),
     r"band = \(0.03, 0.04\) is not allowed: must be a CapabilityBand"),
    (lambda: ArmCapability(band=0.04), "band = 0.04"),
    (lambda: WorkspaceAdapter(band="paper"), "band = 'paper'"),
    (lambda: RobustCompensatorParameters(compensation_switch=2.0),
     "compensation_switch"),
    (lambda: ArmCapabilityParameters(joint_limit_gain=0.0),
     "joint_limit_gain"),
    (lambda: ArmCapability(params=CapabilityBand()), "params"),
    (lambda: MotionDistributor(arm="elfin5"), "arm"),
])
def test_bad_parameters_are_rejected(make, name):
    with pytest.raises(ValueError, match=name):
        make()


def test_defaults_are_the_papers():
    assert (BAND.lower, BAND.upper) == (0.035, 0.04)
    assert MotionDistributorParameters().null_space_gain == 0.0
    assert RobustCompensatorParameters().compensation_switch == 1.0
    params = WorkspaceAdapterParameters()
    assert (params.sigma_xy, params.sigma_phi) == (0.5, 0.5)
    assert PHRI.workspace is None  # the robot's: the paper's on ours
    assert ARM.model.description.tuning.local_workspace == LocalWorkspace()


@pytest.mark.parametrize("system, inputs, outputs", [
    (ArmCapability(arm=ARM), ["arm_position"],
     ["end_effector_position", "capability", "capability_gradient",
      "alpha"]),
    (WorkspaceAdapter(PHRI, ARM),
     ["end_effector_position", "end_effector_velocity", "capability",
      "capability_gradient"], ["sigma_xy", "sigma_phi"]),
    (MotionDistributor(arm=ARM),
     ["end_effector_velocity", "sigma_xy", "sigma_phi",
      "end_effector_position", "capability", "capability_gradient",
      "null_space_gain"], ["arm_velocity", "base_velocity"]),
    (RobustCompensator(arm=ARM),
     ["arm_velocity", "base_velocity", "filtered_base_velocity",
      "end_effector_position", "capability_gradient", "alpha",
      "compensation_switch", "base_state"],
     ["arm_reference_velocity", "end_effector_deviation"]),
    (RobustCompensator(RobustCompensatorParameters(
        base_source="predicted", base_lag=0.3), arm=ARM),
     ["arm_velocity", "base_velocity", "filtered_base_velocity",
      "end_effector_position", "capability_gradient", "alpha",
      "compensation_switch", "base_state"],
     ["arm_reference_velocity", "end_effector_deviation"]),
])
def test_scalar_conversion_keeps_ports_and_parameters(system, inputs,
                                                      outputs):
    converted = system.ToAutoDiffXd()
    for s in (system, converted):
        assert [s.get_input_port(i).get_name()
                for i in range(s.num_input_ports())] == inputs
        assert [s.get_output_port(i).get_name()
                for i in range(s.num_output_ports())] == outputs
    assert converted.params == system.params
    assert converted.arm is system.arm
    if hasattr(system, "band"):
        assert converted.band == system.band
