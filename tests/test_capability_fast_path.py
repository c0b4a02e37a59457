"""The per-tick path of the workspace stage against the generic
(AutoDiffXd-capable) path, on seeded random inputs with the edge cases
(the end effector on the arm base's axis and behind it, every band edge,
the deactivation on and off): no result may differ beyond rounding
(1e-12 relative)."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE
from pydrake.autodiffutils import AutoDiffXd, ExtractValue
from scipy.spatial.transform import Rotation

from drake_wbc.math import adaptive_weighting
from drake_wbc.math.capability import CapabilityBand
from drake_wbc.math.workspace import LocalWorkspace
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.capability_stage import (
    WorkspaceAdapter,
    WorkspaceAdapterParameters,
)

WORKSPACE_INPUTS = ("end_effector_position", "end_effector_velocity",
                    "capability", "capability_gradient")


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def stage_outputs(system, context):
    return [np.array(system.get_output_port(i).Eval(context))
            for i in range(system.num_output_ports())]



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
