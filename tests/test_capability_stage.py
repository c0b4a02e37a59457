"""The ArmCapability and WorkspaceAdapter stages: their outputs are the math
layer's (drake_wbc.math.capability and workspace) at the configurations
that matter (joints at and beyond their limits, the wrist singularity,
C_m in the band and on either side of it; the end effector on the arm
base's axis, behind it, in the bands), the same for AutoDiffXd, and a
joint angle that is not finite gives NaN."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue
from singular_sides import is_one_of, one_sided_gradients

from drake_wbc.math import capability, workspace
from drake_wbc.math.capability import ArmCapabilityParameters, CapabilityBand
from drake_wbc.math.workspace import (
    LocalWorkspace,
    WorkspaceAdapterParameters,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages.capability_stage import ArmCapability, WorkspaceAdapter

WORKSPACE_INPUTS = ("end_effector_position", "end_effector_velocity",
                    "capability", "capability_gradient")


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def stage_outputs(system, context):
    return [np.array(system.get_output_port(i).Eval(context))
            for i in range(system.num_output_ports())]


# --- ArmCapability ------------------------------------------------------------

@pytest.fixture(scope="module")
def capability_stage(arm):
    params = ArmCapabilityParameters(joint_limit_gain=2e4,
                                     gradient_damping=0.03,
                                     gradient_damping_threshold=0.05)
    return ArmCapability(params, arm, band=CapabilityBand(0.03, 0.045))


def limit_cases(arm, rng, count):
    """Configurations inside the range, at a limit, beyond one, with two
    joints at limits, at the wrist and elbow singularities."""
    lower, upper = arm.lower, arm.upper
    cases = []
    for i in range(count):
        q = rng.uniform(lower + 0.05, upper - 0.05)
        j, k = rng.choice(6, size=2, replace=False)
        kind = i % 6
        if kind == 1:
            q[j] = lower[j] if rng.uniform() < 0.5 else upper[j]
        elif kind == 2:
            q[j] = lower[j] - 0.02 if rng.uniform() < 0.5 else upper[j] + 0.02
        elif kind == 3:
            q[j], q[k] = lower[j], upper[k]
        elif kind == 4:
            q[4] = 0.0  # wrist singularity: damping active
        elif kind == 5:
            q[2], q[4] = 0.0, rng.uniform(-0.05, 0.05)
        cases.append(q)
    return cases


def in_band(arm, params, band, joint):
    """A configuration with C_m in the band: from home towards the upper
    limit of `joint`, by bisection."""
    home = np.array(HOME_ARM_POSITIONS, dtype=float)

    def C_m(t):
        q = home.copy()
        q[joint] += t * (arm.upper[joint] - home[joint])
        return capability.capability(arm.evaluate(q).J_a, q, arm.lower,
                                     arm.upper, params.joint_limit_gain), q

    target = 0.5 * (band.lower + band.upper)
    low, high = 0.0, 1.0  # C_m(0) above the band, C_m(1) = 0
    for _ in range(40):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if C_m(middle)[0] > target else (low,
                                                                   middle)
    return C_m(low)[1]


def test_capability_stage_gives_the_math_layers_values(arm,
                                                       capability_stage):
    system = capability_stage
    p = system.params
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(25)
    alphas = set()
    for q in (limit_cases(arm, rng, 30) + [np.array(HOME_ARM_POSITIONS)]
              + [in_band(arm, p, system.band, joint) for joint in (0, 3)]):
        system.get_input_port().FixValue(context, q)
        position, C_m, gradient, alpha = stage_outputs(system, context)
        values = arm.evaluate(q)
        np.testing.assert_array_equal(position, values.p_ee_in_base)
        expected_C = capability.capability(values.J_a, q, arm.lower,
                                           arm.upper, p.joint_limit_gain)
        # (At a singular pose C_m is 0 to rounding, 1e-19 or so, whose
        # digits depend on the SVD's LAPACK.)
        assert C_m[0] == pytest.approx(expected_C, rel=1e-12, abs=1e-16)
        expected_g = capability.capability_gradient(
            values.J_a, q, arm.lower, arm.upper, p.joint_limit_gain,
            p.gradient_damping, p.gradient_damping_threshold)
        if np.linalg.svd(values.J_a, compute_uv=False)[-1] < 1e-12:
            # An exact singularity: either side (singular_sides).
            assert is_one_of(gradient, one_sided_gradients(
                values.J_a, q, arm.lower, arm.upper, p.joint_limit_gain,
                p.gradient_damping, p.gradient_damping_threshold))
        else:
            np.testing.assert_allclose(gradient, expected_g, rtol=0,
                                       atol=1e-12 * np.abs(expected_g).max())
        expected_alpha = capability.transition(C_m[0], system.band.upper,
                                               system.band.lower)
        assert alpha[0] == pytest.approx(expected_alpha, abs=1e-15)
        alphas.add(0.0 if alpha[0] == 0.0 else 1.0 if alpha[0] == 1.0
                   else 0.5)
    assert alphas == {0.0, 0.5, 1.0}


def test_capability_stage_for_autodiff_gives_the_same_values(
        arm, capability_stage):
    system = capability_stage
    converted = system.ToAutoDiffXd()
    assert converted.params is system.params and converted.arm is system.arm
    context = system.CreateDefaultContext()
    ad_context = converted.CreateDefaultContext()
    rng = np.random.default_rng(26)
    for q in limit_cases(arm, rng, 6):
        system.get_input_port().FixValue(context, q)
        converted.get_input_port().FixValue(
            ad_context, np.array([AutoDiffXd(x) for x in q]))
        for port, (a, b) in enumerate(zip(
                stage_outputs(system, context),
                stage_outputs(converted, ad_context), strict=True)):
            np.testing.assert_array_equal(
                a, ExtractValue(b).ravel(),
                err_msg=system.get_output_port(port).get_name())


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_capability_stage_gives_nan_for_non_finite_positions(
        capability_stage, bad):
    """A tick raises for no value: a joint angle that is not finite makes
    every output NaN, for double and AutoDiffXd (values and derivatives),
    and the next finite one gives the finite outputs again."""
    q = np.array(HOME_ARM_POSITIONS, dtype=float)
    q[3] = bad
    system = capability_stage
    context = system.CreateDefaultContext()
    system.get_input_port().FixValue(context, q)
    for output in stage_outputs(system, context):
        assert np.isnan(output).all()
    converted = system.ToAutoDiffXd()
    ad_context = converted.CreateDefaultContext()
    converted.get_input_port().FixValue(ad_context, np.array(
        [AutoDiffXd(x, np.eye(6)[i]) for i, x in enumerate(q)]))
    for output in stage_outputs(converted, ad_context):
        assert np.isnan(ExtractValue(output)).all()
        assert np.isnan(ExtractGradient(output)).all()
    system.get_input_port().FixValue(context, np.array(HOME_ARM_POSITIONS))
    for output in stage_outputs(system, context):
        assert np.isfinite(output).all()


# --- WorkspaceAdapter ---------------------------------------------------------

@pytest.fixture(scope="module")
def adapter(arm):
    params = WorkspaceAdapterParameters(
        mode="intuitive-phri",
        workspace=LocalWorkspace(extent_lower=0.6, extent_upper=0.8,
                                 deflection_lower=0.3, deflection_upper=0.7),
        deactivation_speed=0.0, max_rate=100.0)  # the paper's rule
    return WorkspaceAdapter(params, arm, band=CapabilityBand(0.02, 0.06))


def fix_workspace_inputs(system, context, values):
    for name, value in zip(WORKSPACE_INPUTS, values, strict=True):
        system.GetInputPort(name).FixValue(context, value)


def test_adapter_gives_the_local_workspace_state(adapter):
    """The double system and the AutoDiffXd one give sigma_xy, sigma_phi
    of workspace.local_workspace_state, on the ramps, at 0 and at 1."""
    converted = adapter.ToAutoDiffXd()
    context = adapter.CreateDefaultContext()
    ad_context = converted.CreateDefaultContext()
    R, origin = adapter.R_ba, adapter.arm_base_position
    params, band = adapter.params, adapter.band
    rng = np.random.default_rng(28)
    seen = set()
    for case in range(120):
        radius = rng.uniform(0.4, 1.0) if case % 5 else 0.0
        azimuth = rng.uniform(-1.2, 1.2) if case % 7 else np.pi
        p_a = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth),
                        0.2])
        values = [R @ p_a + origin, rng.normal(size=6),
                  [rng.uniform(0.0, 0.1)], rng.normal(size=6) * 0.1]
        fix_workspace_inputs(adapter, context, values)
        state = workspace.local_workspace_state(
            values[0], values[1], values[2][0], values[3],
            band.upper, band.lower, params.workspace, R,
            origin)
        expected = [state.sigma_xy, state.sigma_phi]
        double = np.concatenate(stage_outputs(adapter, context))
        np.testing.assert_allclose(double, expected, rtol=0, atol=1e-12)
        if case % 4 == 0:
            fix_workspace_inputs(converted, ad_context, [
                np.array([AutoDiffXd(x) for x in np.ravel(v)])
                for v in values])
            np.testing.assert_allclose(ExtractValue(np.concatenate(
                stage_outputs(converted, ad_context))).ravel(), expected,
                rtol=0, atol=1e-12)
        seen.update("ramp" if 0.0 < v < 1.0 else v for v in double)
    assert seen == {0.0, 1.0, "ramp"}


@pytest.mark.parametrize("mode, expected", [
    ("locomotion", (0.0, 0.0)), ("manipulation", (1.0, 1.0)),
    ("loco-manipulation", (0.2, 0.7))])
def test_adapter_in_a_fixed_mode_reads_no_input(mode, expected):
    params = WorkspaceAdapterParameters(mode=mode, sigma_xy=0.2,
                                        sigma_phi=0.7)
    system = WorkspaceAdapter(params)
    for stage in (system, system.ToAutoDiffXd()):
        factors = np.concatenate(stage_outputs(stage,
                                               stage.CreateDefaultContext()))
        np.testing.assert_array_equal(ExtractValue(factors).ravel()
                                      if factors.dtype == object
                                      else factors, expected)
        assert not stage.HasAnyDirectFeedthrough()
    params.sigma_xy = 0.4  # read when the stage was built
    np.testing.assert_array_equal(np.concatenate(stage_outputs(
        system, system.CreateDefaultContext())), expected)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
@pytest.mark.parametrize("index", range(4))
def test_adapter_gives_nan_for_non_finite_inputs(adapter, index, bad):
    """A tick does not raise for a value (the safety layer sees the NaN
    input and stops): the factors are NaN, in double and AutoDiffXd."""
    values = [np.array([0.9, 0.1, 0.3]), np.full(6, 0.1), np.array([0.05]),
              np.full(6, 0.01)]
    values[index] = values[index].copy()
    values[index][-1] = bad
    for stage in (adapter, adapter.ToAutoDiffXd()):
        context = stage.CreateDefaultContext()
        fix_workspace_inputs(stage, context, values)
        factors = np.concatenate(stage_outputs(stage, context))
        if factors.dtype == object:
            factors = ExtractValue(factors).ravel()
        assert np.isnan(factors).all()
