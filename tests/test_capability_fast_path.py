"""The per-tick paths of the capability and workspace stages against the
formulas as written and against the generic (AutoDiffXd-capable) path, on
seeded random inputs with the edge cases (joints at and beyond their
limits, singular Jacobians, damping active, the end effector on the arm
base's axis and behind it, every band edge, the deactivation on and off):
no result may differ beyond rounding (1e-12 relative)."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE, relative_difference
from pydrake.autodiffutils import AutoDiffXd, ExtractValue
from scipy.spatial.transform import Rotation

from drake_wbc.math import adaptive_weighting, capability, capability_gradients
from drake_wbc.math.workspace import LocalWorkspace
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.stages.capability_stage import (
    ArmCapability,
    ArmCapabilityParameters,
    CapabilityBand,
    WorkspaceAdapter,
    WorkspaceAdapterParameters,
)

WORKSPACE_INPUTS = ("end_effector_position", "end_effector_velocity",
                    "capability", "capability_gradient")


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


# --- capability: the math, against numpy formulations -----------------------

def products_of_others(values):
    return np.array([np.prod(np.delete(values, k))
                     for k in range(len(values))])


def manipulability_gradient_by_einsum(J, svd):
    """sum_k (prod_{l != k} s_l) u_k^T (dJ/dq_i) v_k, the derivative from
    jacobian_derivative, with the given SVD (at a singularity the sign of
    the result follows that of the singular vectors)."""
    U, s, Vt = svd
    return np.einsum("k,rk,irc,kc->i", products_of_others(s), U,
                     capability_gradients.jacobian_derivative(J), Vt)


def penalty_gradient_as_written(q, lower, upper, k_j):
    q = np.clip(q, lower, upper)
    span2 = (upper - lower) ** 2
    factors = (q - lower) * (upper - q) / span2
    slopes = (upper + lower - 2.0 * q) / span2
    return (k_j * np.exp(-k_j * np.prod(factors)) * slopes
            * products_of_others(factors))


def cartesian_gradient_as_written(J, joint_gradient, lambda_max, eps):
    """(J J^T + lambda^2 I)^-1 J dC_m/dq through numpy's SVD."""
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    lambda2 = (lambda_max**2 * (1.0 - (s[-1] / eps) ** 2)
               if s[-1] < eps else 0.0)
    return U @ (s / (s**2 + lambda2) * (Vt @ joint_gradient))


def rank_deficient(rng, n, rank):
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(n, n)))
    s = np.zeros(6)
    s[:rank] = rng.uniform(0.1, 2.0, rank)
    return (U * s) @ V[:6]


def test_manipulability_gradient_matches_the_einsum_form():
    rng = np.random.default_rng(20)
    for n in (6, 7, 9):
        for trial in range(20):
            J = (rng.normal(size=(6, n)) if trial % 4
                 else rank_deficient(rng, n, 5 - trial % 8 // 4))
            svd = capability_gradients._svd(J)
            assert relative_difference(
                capability_gradients.manipulability_joint_gradient(J),
                manipulability_gradient_by_einsum(J, svd)) < RELATIVE


def test_stretched_arm_has_no_manipulability_gradient():
    # Several zero singular values: the exact gradient, 0, to rounding.
    rng = np.random.default_rng(21)
    J = rank_deficient(rng, 6, 3)
    assert np.abs(capability_gradients.manipulability_joint_gradient(
        J)).max() < 1e-12


def test_products_of_others_as_lists_and_arrays():
    rng = np.random.default_rng(22)
    for size in (1, 2, 5, 6, 9):
        v = rng.normal(size=size)
        if size > 1:
            v[rng.integers(size)] = 0.0
        expected = products_of_others(v)
        assert relative_difference(capability._products_of_others(v.tolist()),
                                   expected) < RELATIVE
        assert relative_difference(capability._products_of_others(v),
                                   expected) < RELATIVE


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


def test_penalty_and_its_gradient_match_the_formula(arm):
    rng = np.random.default_rng(23)
    for q in limit_cases(arm, rng, 60):
        k_j = rng.uniform(5e3, 3e4)
        expected = penalty_gradient_as_written(q, arm.lower, arm.upper, k_j)
        got = capability_gradients.joint_limit_penalty_gradient(q, arm.lower,
                                                                arm.upper, k_j)
        assert isinstance(got, np.ndarray) and got.shape == (6,)
        if np.any(expected):
            assert relative_difference(got, expected) < RELATIVE
        else:
            assert np.count_nonzero(got) == 0
        factors = ((np.clip(q, arm.lower, arm.upper) - arm.lower)
                   * (arm.upper - np.clip(q, arm.lower, arm.upper))
                   / (arm.upper - arm.lower) ** 2)
        penalty = capability.joint_limit_penalty(q, arm.lower, arm.upper,
                                                 k_j)
        assert isinstance(penalty, float)
        assert penalty == pytest.approx(
            -np.expm1(-k_j * np.prod(factors)), rel=RELATIVE, abs=1e-300)


def test_cartesian_gradient_matches_the_formula(arm):
    rng = np.random.default_rng(24)
    damped = 0
    for q in limit_cases(arm, rng, 60):
        J = arm.evaluate(q).J_a
        k_j, lam, eps = rng.uniform(5e3, 3e4), 0.02, rng.uniform(0.01, 0.2)
        joint_gradient = capability_gradients.capability_joint_gradient(
            J, q, arm.lower, arm.upper, k_j)
        expected = cartesian_gradient_as_written(J, joint_gradient, lam, eps)
        got = capability_gradients.capability_gradient(J, q, arm.lower,
                                                       arm.upper, k_j, lam,
                                                       eps)
        assert relative_difference(got, expected) < RELATIVE
        fused_C, fused_g = capability_gradients.capability_terms_unchecked(
            J, q.tolist(), arm.lower.tolist(), arm.upper.tolist(), k_j, lam,
            eps)
        assert fused_C == pytest.approx(capability.capability(
            J, q, arm.lower, arm.upper, k_j), rel=RELATIVE, abs=1e-300)
        np.testing.assert_array_equal(fused_g, got)
        damped += np.linalg.svd(J, compute_uv=False)[-1] < eps
    assert damped >= 10


# --- the ArmCapability stage ------------------------------------------------

@pytest.fixture(scope="module")
def capability_stage(arm):
    params = ArmCapabilityParameters(band=CapabilityBand(0.03, 0.045),
                                     joint_limit_gain=2e4,
                                     gradient_damping=0.03,
                                     gradient_damping_threshold=0.05)
    return ArmCapability(params, arm)


def stage_outputs(system, context):
    return [np.array(system.get_output_port(i).Eval(context))
            for i in range(system.num_output_ports())]


def in_band(arm, params, joint):
    """A configuration with C_m in the band: from home towards the upper
    limit of `joint`, by bisection."""
    home = np.array(HOME_ARM_POSITIONS, dtype=float)

    def C_m(t):
        q = home.copy()
        q[joint] += t * (arm.upper[joint] - home[joint])
        return capability.capability(arm.evaluate(q).J_a, q, arm.lower,
                                     arm.upper, params.joint_limit_gain), q

    target = 0.5 * (params.band.lower + params.band.upper)
    low, high = 0.0, 1.0  # C_m(0) above the band, C_m(1) = 0
    for _ in range(40):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if C_m(middle)[0] > target else (low,
                                                                   middle)
    return C_m(low)[1]


def test_capability_stage_matches_the_public_functions(arm,
                                                       capability_stage):
    system = capability_stage
    p = system.params
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(25)
    alphas = set()
    for q in (limit_cases(arm, rng, 30) + [np.array(HOME_ARM_POSITIONS)]
              + [in_band(arm, p, joint) for joint in (0, 3)]):
        system.get_input_port().FixValue(context, q)
        position, C_m, gradient, alpha = stage_outputs(system, context)
        values = arm.evaluate(q)
        np.testing.assert_array_equal(position, values.p_ee_in_base)
        expected_C = capability.capability(values.J_a, q, arm.lower,
                                           arm.upper, p.joint_limit_gain)
        assert C_m[0] == pytest.approx(expected_C, rel=RELATIVE, abs=1e-300)
        assert relative_difference(
            gradient, capability_gradients.capability_gradient(
                values.J_a, q, arm.lower, arm.upper, p.joint_limit_gain,
                p.gradient_damping, p.gradient_damping_threshold)) < RELATIVE
        expected_alpha = capability.transition(C_m[0], p.band.upper,
                                               p.band.lower)
        assert alpha[0] == pytest.approx(expected_alpha, abs=1e-15)
        alphas.add(0.0 if alpha[0] == 0.0 else 1.0 if alpha[0] == 1.0
                   else 0.5)
    assert alphas == {0.0, 0.5, 1.0}


def test_capability_stage_autodiff_values_equal_the_float_ones(
        arm, capability_stage):
    system = capability_stage
    converted = system.ToAutoDiffXd()
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


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_capability_stage_rejects_non_finite_positions(capability_stage,
                                                       bad):
    context = capability_stage.CreateDefaultContext()
    q = np.array(HOME_ARM_POSITIONS, dtype=float)
    q[3] = bad
    capability_stage.get_input_port().FixValue(context, q)
    with pytest.raises(ValueError, match="q_a"):
        capability_stage.GetOutputPort("capability").Eval(context)


# --- workspace: the plain-float path against local_workspace_state ----------

def workspace_case(rng, kind):
    """One random input of the intuitive pHRI mode, of a given kind (the
    end effector on the axis, straight ahead, straight behind, on the
    extent band, on the deflection band, or anywhere; the twist zero,
    vertical, or any), and the constants."""
    upper = rng.uniform(0.03, 0.07)
    lower = upper - rng.uniform(0.002, 0.02)
    ws = LocalWorkspace(extent_lower=rng.uniform(0.5, 0.75),
                        extent_upper=rng.uniform(0.76, 0.9),
                        deflection_lower=np.radians(rng.uniform(5, 30)),
                        deflection_upper=np.radians(rng.uniform(31, 60)))
    R = (np.eye(3) if kind % 2 == 0
         else Rotation.from_rotvec(rng.normal(size=3)).as_matrix())
    origin = rng.normal(size=3) * 0.3
    radius, azimuth = rng.uniform(0.0, 1.0), rng.uniform(-np.pi, np.pi)
    shape = kind % 6
    if shape == 1:
        radius = 0.0
    elif shape == 2:
        azimuth = 0.0
    elif shape == 3:
        azimuth = np.pi
    elif shape == 4:
        radius = rng.uniform(ws.extent_lower, ws.extent_upper)
    elif shape == 5:
        azimuth = rng.choice([-1, 1]) * rng.uniform(ws.deflection_lower,
                                                    ws.deflection_upper)
    p_a = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth),
                    rng.normal() * 0.3])
    V = rng.normal(size=6)
    twist = kind // 6 % 3
    if twist == 1:
        V[:] = 0.0
    elif twist == 2:
        V[:] = 0.0
        V[:3] = R[:, 2] * rng.normal()  # along the arm base's z axis
    # C_m: anywhere, or such that C_m P_d P_phi lands in the band.
    C_m = rng.uniform(0.0, 0.1)
    gradient = rng.normal(size=6) * 0.1
    return (R @ p_a + origin, V, C_m, gradient), (upper, lower, ws, R,
                                                  origin)


def test_adaptive_factors_match_local_workspace_state():
    rng = np.random.default_rng(27)
    seen = set()
    for case in range(1800):
        (p, V, C_m, gradient), (upper, lower, ws, R, origin) = \
            workspace_case(rng, case)
        state = adaptive_weighting.local_workspace_state(
            p, V, C_m, gradient, upper, lower, ws, R, origin)
        if case % 3 == 0:  # put C_m^d into the band of the factors
            P = state.P_d * state.P_phi
            if P > 0.0:
                C_m = rng.uniform(lower, upper) / P
                state = adaptive_weighting.local_workspace_state(
                    p, V, C_m, gradient, upper, lower, ws, R, origin)
        constants = adaptive_weighting.adaptive_workspace(upper, lower, ws, R,
                                                          origin)
        fast = adaptive_weighting.adaptive_weighting_factors(
            p, V.tolist(), C_m, gradient.tolist(), constants)
        expected = (state.sigma_xy, state.sigma_phi)
        assert all(isinstance(value, float) for value in fast)
        assert np.max(np.abs(np.subtract(fast, expected))) <= RELATIVE, case
        for value, factor in zip(fast, (state.f_xy, state.f_phi),
                                 strict=True):
            seen.add("deactivated" if value == 1.0 != factor
                     else "edge" if value in (0.0, 1.0) else "ramp")
    assert seen == {"deactivated", "edge", "ramp"}


def test_adaptive_factors_reject_non_finite_inputs_by_name():
    constants = adaptive_weighting.adaptive_workspace(0.04, 0.035)
    good = (np.array([0.7, 0.1, 0.3]), [0.1] * 6, 0.05, [0.01] * 6)
    names = ("p_ee_in_base", "V_ee", "C_m", "grad_C_m")
    for index, name in enumerate(names):
        for bad in (np.nan, np.inf, -np.inf):
            args = list(good)
            if index == 0:
                args[0] = good[0].copy()
                args[0][1] = bad
            elif index == 2:
                args[2] = bad
            else:
                args[index] = list(good[index])
                args[index][2] = bad
            with pytest.raises(ValueError, match=name):
                adaptive_weighting.adaptive_weighting_factors(*args, constants)


@pytest.mark.parametrize("call, name", [
    (lambda: adaptive_weighting.adaptive_workspace(0.03, 0.04),
     "capability_lower"),
    (lambda: adaptive_weighting.adaptive_workspace(0.04, np.nan),
     "capability_lower"),
    (lambda: adaptive_weighting.adaptive_workspace(0.04, 0.03, "big"),
     "workspace"),
    (lambda: adaptive_weighting.adaptive_workspace(0.04, 0.03, None,
                                                   2 * np.eye(3)),
     "R_ba"),
    (lambda: adaptive_weighting.adaptive_workspace(0.04, 0.03, None, None,
                                                   np.zeros(2)),
     "arm_base_in_base"),
])
def test_adaptive_workspace_checks_its_parameters(call, name):
    with pytest.raises(ValueError, match=name):
        call()


# --- the WorkspaceAdapter stage ---------------------------------------------

@pytest.fixture(scope="module")
def adapter(arm):
    params = WorkspaceAdapterParameters(
        mode="intuitive-phri", band=CapabilityBand(0.02, 0.06),
        workspace=LocalWorkspace(extent_lower=0.6, extent_upper=0.8,
                                 deflection_lower=0.3, deflection_upper=0.7))
    return WorkspaceAdapter(params, arm)


def fix_workspace_inputs(system, context, values):
    for name, value in zip(WORKSPACE_INPUTS, values, strict=True):
        system.GetInputPort(name).FixValue(context, value)


def test_adapter_float_path_matches_the_autodiff_one(adapter):
    """The double system takes adaptive_weighting_factors, the AutoDiffXd
    one local_workspace_state: the same values."""
    converted = adapter.ToAutoDiffXd()
    context = adapter.CreateDefaultContext()
    ad_context = converted.CreateDefaultContext()
    R, origin = adapter.R_ba, adapter.arm_base_position
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
        fix_workspace_inputs(converted, ad_context, [
            np.array([AutoDiffXd(x) for x in np.ravel(v)]) for v in values])
        fast = np.concatenate(stage_outputs(adapter, context))
        generic = ExtractValue(np.concatenate(
            stage_outputs(converted, ad_context))).ravel()
        assert np.max(np.abs(fast - generic)) <= RELATIVE
        state = adaptive_weighting.local_workspace_state(
            values[0], values[1], values[2][0], values[3],
            adapter.params.band.upper, adapter.params.band.lower,
            adapter.params.workspace, R, origin)
        np.testing.assert_allclose(fast, [state.sigma_xy, state.sigma_phi],
                                   rtol=0, atol=RELATIVE)
        seen.update("ramp" if 0.0 < v < 1.0 else v for v in fast)
    assert seen == {0.0, 1.0, "ramp"}


@pytest.mark.parametrize("index", range(4))
def test_adapter_rejects_non_finite_inputs(adapter, index):
    context = adapter.CreateDefaultContext()
    values = [np.array([0.9, 0.1, 0.3]), np.full(6, 0.1), np.array([0.05]),
              np.full(6, 0.01)]
    values[index] = values[index].copy()
    values[index][-1] = np.nan
    fix_workspace_inputs(adapter, context, values)
    name = ("p_ee_in_base", "V_ee", "C_m", "grad_C_m")[index]
    with pytest.raises(ValueError, match=name):
        adapter.GetOutputPort("sigma_xy").Eval(context)
