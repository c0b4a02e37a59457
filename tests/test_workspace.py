"""drake_wbc.math.workspace and motion_mode (Sec. IV-C) against closed
forms, the capability module's transition and finite differences, for
floats and AutoDiffXd."""

import numpy as np
import pytest
from pydrake.autodiffutils import (
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from reference_kinematics import random_rotation

from drake_wbc.math import capability, motion_mode, workspace
from drake_wbc.math.motion_mode import MotionMode
from drake_wbc.math.workspace import LocalWorkspace

WS = LocalWorkspace()
UPPER, LOWER = 0.04, 0.035
H = 1e-6


def polar(d, azimuth, z=0.3):
    return np.array([d * np.cos(azimuth), d * np.sin(azimuth), z])


def test_defaults_are_the_papers():
    assert (WS.extent_lower, WS.extent_upper) == (0.75, 0.8)
    assert np.degrees(WS.deflection_lower) == pytest.approx(30.0)
    assert np.degrees(WS.deflection_upper) == pytest.approx(35.0)


def test_extent_and_deflection_closed_forms():
    rng = np.random.default_rng(1)
    for _ in range(100):
        d = rng.uniform(0.05, 1.2)
        azimuth = rng.uniform(-np.pi, np.pi)
        p = polar(d, azimuth, rng.uniform(-0.5, 1.0))
        assert workspace.extent(p) == pytest.approx(d, rel=1e-12)
        assert workspace.deflection(p) == pytest.approx(abs(azimuth),
                                                        abs=1e-12)


def test_in_arm_base_rotates_and_shifts():
    rng = np.random.default_rng(2)
    R = random_rotation(rng)
    origin = rng.normal(size=3)
    p_a = rng.normal(size=3)
    p_b = origin + R @ p_a
    np.testing.assert_allclose(workspace.in_arm_base(p_b, R, origin), p_a,
                               atol=1e-14)


@pytest.mark.parametrize("function, gradient", [
    (workspace.extent, workspace.extent_gradient),
    (workspace.deflection, workspace.deflection_gradient),
])
def test_gradients_match_finite_differences(function, gradient):
    rng = np.random.default_rng(3)
    for _ in range(50):
        p = polar(rng.uniform(0.1, 1.0), rng.uniform(-3.0, 3.0))
        numeric = np.zeros(6)
        for i in range(3):
            step = np.zeros(3)
            step[i] = H
            numeric[i] = (function(p + step) - function(p - step)) / (2 * H)
        np.testing.assert_allclose(gradient(p), numeric, atol=1e-8)


def test_on_the_axis_there_is_no_gradient_and_no_nan():
    p = InitializeAutoDiff(np.array([0.0, 0.0, 0.4])).ravel()
    for value in (workspace.extent(p), workspace.deflection(p)):
        assert value.value() == 0.0
        assert np.all(np.isfinite(value.derivatives()))
    for gradient in (workspace.extent_gradient(p),
                     workspace.deflection_gradient(p)):
        np.testing.assert_array_equal(ExtractValue(gradient).ravel(), 0.0)


def linear_capability(c0, g):
    """A C_m that is linear in the 6-D pose x, with gradient g."""
    return lambda x: c0 + g @ x


def penalized_by_pose(c0, g, p0, x):
    """C_m^d and C_m^phi at pose x (position part added to p0)."""
    C_m = linear_capability(c0, g)(x)
    P_d, P_phi = workspace.workspace_penalties(p0 + x[:3], WS)
    return np.array([C_m * P_d * P_phi, C_m * P_phi])


def central_differences(c0, g, p0):
    """(2, 6) [grad C_m^d; grad C_m^phi] by central differences of
    `penalized_by_pose` at the pose p0, step H."""
    numeric = np.zeros((2, 6))
    for i in range(6):
        step = np.zeros(6)
        step[i] = H
        numeric[:, i] = (penalized_by_pose(c0, g, p0, step)
                         - penalized_by_pose(c0, g, p0, -step)) / (2 * H)
    return numeric


def test_penalized_capability_gradients_match_finite_differences():
    """grad C_m^d and grad C_m^phi by central differences of the math
    functions, with C_m linear in the pose; points inside both bands."""
    rng = np.random.default_rng(4)
    largest = 0.0
    for _ in range(50):
        d = rng.uniform(0.755, 0.795)
        azimuth = rng.choice([-1, 1]) * np.radians(rng.uniform(30.5, 34.5))
        p0 = polar(d, azimuth)
        c0 = rng.uniform(0.03, 0.07)
        g = rng.normal(size=6) * 0.01
        result = workspace.penalized_capability(c0, g, p0, WS)
        numeric = central_differences(c0, g, p0)
        np.testing.assert_allclose(result.gradient_d, numeric[0], atol=1e-8)
        np.testing.assert_allclose(result.gradient_phi, numeric[1],
                                   atol=1e-8)
        P_d, P_phi = workspace.workspace_penalties(p0, WS)
        largest = max(largest,
                      np.abs(result.gradient_d - P_d * P_phi * g).max())
    assert largest > 0.1  # the workspace's terms are there


def test_penalized_capability_gradients_at_the_switches():
    """grad C_m^d and grad C_m^phi by central differences where the
    piecewise penalties switch: d and phi 1e-4 (in m and rad) either side
    of each edge of their bands, the end effector straight ahead and
    straight behind (y = 0, where phi has its kink and P_phi is flat) and
    each with phi on the other side; C_m linear in the pose."""
    rng = np.random.default_rng(5)
    d_edges = (WS.extent_lower, WS.extent_upper)
    phi_edges = (WS.deflection_lower, WS.deflection_upper)
    points = [polar(d + side * 1e-4, azimuth)
              for d in d_edges for side in (-1.0, 1.0)
              for azimuth in (0.0, np.pi, 0.3, -2.0)]
    points += [polar(d, sign * (phi + side * 1e-4))
               for d in (0.6, 0.77, 0.9) for phi in phi_edges
               for side in (-1.0, 1.0) for sign in (-1.0, 1.0)]
    for p0 in points:
        c0 = rng.uniform(0.03, 0.07)
        g = rng.normal(size=6) * 0.01
        result = workspace.penalized_capability(c0, g, p0, WS)
        numeric = central_differences(c0, g, p0)
        np.testing.assert_allclose(result.gradient_d, numeric[0], atol=1e-8,
                                   err_msg=p0)
        np.testing.assert_allclose(result.gradient_phi, numeric[1],
                                   atol=1e-8, err_msg=p0)


def state(p, V=None, C_m=0.06, g=None):
    V = np.zeros(6) if V is None else V
    g = np.zeros(6) if g is None else g
    return workspace.local_workspace_state(p, V, C_m, g, UPPER,
                                                    LOWER, WS)


def test_inside_the_workspace_far_from_constraints_the_arm_moves():
    rng = np.random.default_rng(5)
    for _ in range(50):
        p = polar(rng.uniform(0.1, 0.74), np.radians(rng.uniform(-29, 29)))
        s = state(p, V=rng.normal(size=6), g=rng.normal(size=6))
        assert (s.f_xy, s.f_phi, s.sigma_xy, s.sigma_phi) == (1, 1, 1, 1)


def test_beyond_the_boundaries_the_base_moves():
    outward = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    beyond_d = state(polar(0.85, 0.0), V=outward)
    assert (beyond_d.P_d, beyond_d.f_xy, beyond_d.sigma_xy) == (0, 0, 0)
    assert beyond_d.f_phi == 1.0  # the rotation stays with the arm
    sideways = polar(0.6, np.radians(40.0))
    away = np.concatenate([np.cross([0, 0, 1.0], sideways), np.zeros(3)])
    beyond_phi = state(sideways, V=0.1 * away)
    assert beyond_phi.phi_rate > 0
    assert (beyond_phi.P_phi, beyond_phi.f_phi, beyond_phi.sigma_phi) == \
        (0, 0, 0)
    assert beyond_phi.sigma_xy == 0  # C_m^d = C_m P_d P_phi = 0 too


def test_low_capability_hands_the_motion_to_the_base():
    s = state(polar(0.5, 0.0), C_m=0.03)
    assert (s.f_xy, s.f_phi, s.sigma_xy, s.sigma_phi) == (0, 0, 0, 0)


def test_factors_are_smooth_and_monotone_across_the_boundary():
    """f falls from 1 to 0 where C_m P_d (C_m P_phi) crosses the band of
    C_m: with C_m = 0.06 between d = 0.7696 and 0.7723 m (phi = 31.96 and
    32.23 deg); sampled there at 7 um (0.001 deg) it has no jump."""
    for position, coarse, fine, factor in (
        (lambda d: polar(d, 0.0), (0.74, 0.81), (0.769, 0.774), "f_xy"),
        (lambda a: polar(0.5, np.radians(a)), (29.0, 36.0), (31.8, 32.4),
         "f_phi"),
    ):
        grid = np.linspace(*coarse, 141)
        f = np.array([getattr(state(position(x)), factor) for x in grid])
        assert f[0] == 1.0 and f[-1] == 0.0
        assert np.all(np.diff(f) <= 1e-15)
        grid = np.linspace(*fine, 601)
        f = np.array([getattr(state(position(x)), factor) for x in grid])
        assert f[0] == 1.0 and f[-1] == 0.0
        assert np.all(np.diff(f) <= 1e-15)
        assert np.abs(np.diff(f)).max() < 0.01
        assert np.count_nonzero((f > 0) & (f < 1)) > 200


def test_factor_is_one_minus_transition_of_penalized_capability():
    rng = np.random.default_rng(6)
    for _ in range(50):
        d = rng.uniform(0.7, 0.85)
        azimuth = np.radians(rng.uniform(-40, 40))
        C_m = rng.uniform(0.03, 0.08)
        s = state(polar(d, azimuth), C_m=C_m)
        P_d = capability.transition(d, 0.8, 0.75)
        P_phi = capability.transition(abs(azimuth), WS.deflection_upper,
                                      WS.deflection_lower)
        assert s.f_xy == pytest.approx(
            1 - capability.transition(C_m * P_d * P_phi, UPPER, LOWER))
        assert s.f_phi == pytest.approx(
            1 - capability.transition(C_m * P_phi, UPPER, LOWER))


def test_deactivation_when_moving_back_in():
    p = polar(0.85, 0.0)
    inward = np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    s = state(p, V=inward)
    assert s.d_rate == pytest.approx(-0.1)
    assert s.f_xy == 0.0 and s.sigma_xy == 1.0
    sideways = polar(0.6, np.radians(-40.0))
    counterclockwise = np.cross([0, 0, 1.0], sideways)
    back = np.concatenate([0.1 * counterclockwise, np.zeros(3)])
    s = state(sideways, V=back)  # the azimuth grows from -40 deg to 0
    assert s.phi_rate < 0
    assert s.f_phi == 0.0 and s.sigma_phi == 1.0


def test_motion_along_the_boundary_does_not_deactivate():
    """Beyond both boundaries: a tangential motion (d_dot = 0 up to
    rounding) keeps sigma_xy = f_xy = 0, a radial one outwards (phi_dot =
    0) keeps sigma_phi = f_phi = 0, and no motion keeps both."""
    for azimuth in np.radians([40.0, -40.0, 50.0, 123.0, -171.0]):
        p = polar(0.85, azimuth)
        tangential = state(p, V=np.concatenate(
            [0.1 * np.cross([0, 0, 1.0], p), np.zeros(3)]))
        assert tangential.sigma_xy == 0.0
        assert tangential.sigma_phi == (1.0 if azimuth < 0 else 0.0)
        radial = state(p, V=np.concatenate([0.1 * p[:2], np.zeros(4)]))
        still = state(p)
        for s in (radial, still):
            assert (s.sigma_xy, s.sigma_phi) == (0.0, 0.0)


def test_deactivation_when_capability_rises():
    """In the band of C_m (inside the workspace) a twist along grad C_m^d
    gives the motion back to the arm; the opposite twist does not."""
    g = np.array([0.0, 0.0, 0.05, 0.0, 0.0, 0.0])
    p = polar(0.5, 0.0)
    up = np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])
    rising = state(p, V=up, C_m=0.037, g=g)
    falling = state(p, V=-up, C_m=0.037, g=g)
    assert 0 < rising.f_xy < 1
    assert rising.sigma_xy == 1.0 and rising.sigma_phi == 1.0
    assert falling.sigma_xy == falling.f_xy
    assert falling.sigma_phi == falling.f_phi


def test_rates_use_the_arm_frame():
    """With T_a rotated by 90 deg about z and shifted, d and phi and their
    rates are those of the position and twist seen from T_a."""
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    origin = np.array([0.2, 0.1, 0.3])
    p_a = polar(0.6, np.radians(20.0))
    V_a = np.array([0.05, 0.02, 0.0, 0.0, 0.0, 0.1])
    p_b = origin + R @ p_a
    V_b = np.concatenate([R @ V_a[:3], R @ V_a[3:]])
    s = workspace.local_workspace_state(p_b, V_b, 0.06, np.zeros(6),
                                                 UPPER, LOWER, WS, R, origin)
    assert s.d == pytest.approx(0.6)
    assert s.phi == pytest.approx(np.radians(20.0))
    assert s.d_rate == pytest.approx(
        workspace.extent_gradient(p_a)[:3] @ V_a[:3])
    assert s.phi_rate == pytest.approx(
        (workspace.deflection(p_a + H * V_a[:3])
         - workspace.deflection(p_a - H * V_a[:3])) / (2 * H))


def test_autodiff_state_matches_floats_and_finite_differences():
    """sigma_xy, sigma_phi w.r.t. every input, in the bands, with a twist
    that keeps the deactivation off on both sides of the differences."""
    p = polar(0.757, np.radians(32.0))
    radial = p[:2] / np.linalg.norm(p[:2])
    tangential = np.array([-radial[1], radial[0]])  # the azimuth grows
    V = np.concatenate([0.1 * radial + 0.05 * tangential, np.zeros(4)])
    g = np.array([0.001, -0.002, 0.0, 0.0, 0.0, 0.0])
    x0 = np.concatenate([p, V, [0.0596], g])

    def sigmas(x):
        s = workspace.local_workspace_state(x[:3], x[3:9], x[9],
                                                     x[10:16], UPPER, LOWER,
                                                     WS)
        return np.array([s.sigma_xy, s.sigma_phi])

    x = InitializeAutoDiff(x0).ravel()
    result = sigmas(x)
    np.testing.assert_allclose(ExtractValue(result).ravel(), sigmas(x0),
                               rtol=1e-14)
    values = sigmas(x0)
    assert np.all((values > 0) & (values < 1))
    numeric = np.stack([(sigmas(x0 + H * e) - sigmas(x0 - H * e)) / (2 * H)
                        for e in np.eye(x0.size)], axis=1)
    np.testing.assert_allclose(ExtractGradient(result), numeric, rtol=1e-5,
                               atol=1e-6)
    assert np.abs(numeric).max() > 1.0


def test_fixed_modes():
    assert motion_mode.fixed_weighting_factors("locomotion") == (0.0, 0.0)
    assert motion_mode.fixed_weighting_factors(MotionMode.MANIPULATION) == \
        (1.0, 1.0)
    assert motion_mode.fixed_weighting_factors("loco-manipulation", 0.3,
                                               0.8) == (0.3, 0.8)
    with pytest.raises(ValueError, match="adaptive"):
        motion_mode.fixed_weighting_factors("intuitive-phri")


STATE_INPUTS = (np.array([0.7, 0.1, 0.3]), np.full(6, 0.1), 0.05,
                np.full(6, 0.01))


@pytest.mark.parametrize("call, name", [
    (lambda: MotionMode.parse("walking"), "mode"),
    (lambda: motion_mode.fixed_weighting_factors("loco-manipulation", 0.0,
                                                 0.5), "sigma_xy"),
    (lambda: motion_mode.fixed_weighting_factors("loco-manipulation", 0.5,
                                                 1.2), "sigma_phi"),
    (lambda: LocalWorkspace(extent_lower=0.8, extent_upper=0.75),
     "extent_lower"),
    (lambda: LocalWorkspace(extent_lower=0.8, extent_upper=0.8),
     "extent_lower"),
    (lambda: LocalWorkspace(extent_lower=-0.1), "extent_lower"),
    (lambda: LocalWorkspace(deflection_lower=0.7, deflection_upper=0.6),
     "deflection_lower"),
    (lambda: LocalWorkspace(deflection_upper=4.0), "deflection_upper"),
    (lambda: workspace.extent(np.zeros(2)), "p_in_arm_base"),
    (lambda: workspace.workspace_penalties(np.zeros(3), "big"),
     "workspace"),
    (lambda: workspace.local_workspace_state(*STATE_INPUTS, 0.03, 0.04),
     "capability_lower"),
    (lambda: workspace.local_workspace_state(*STATE_INPUTS, 0.04, np.nan),
     "capability_lower"),
    (lambda: workspace.local_workspace_state(*STATE_INPUTS, 0.04, 0.03,
                                             "big"), "workspace"),
    (lambda: workspace.local_workspace_state(*STATE_INPUTS, 0.04, 0.03,
                                             None, 2 * np.eye(3)), "R_ba"),
    (lambda: workspace.local_workspace_state(*STATE_INPUTS, 0.04, 0.03,
                                             None, None, np.zeros(2)),
     "arm_base_in_base"),
    (lambda: workspace.local_workspace_state(
        np.array([0.7, np.nan, 0.3]), *STATE_INPUTS[1:], 0.04, 0.03),
     "p_ee_in_base"),
    (lambda: workspace.local_workspace_state(
        STATE_INPUTS[0], [0.1, np.inf, 0, 0, 0, 0], *STATE_INPUTS[2:], 0.04,
        0.03), "V_ee"),
    (lambda: workspace.local_workspace_state(
        *STATE_INPUTS[:2], np.nan, STATE_INPUTS[3], 0.04, 0.03), "C_m"),
    (lambda: workspace.local_workspace_state(
        *STATE_INPUTS[:3], [0.0] * 5, 0.04, 0.03), "grad_C_m"),
])
def test_bad_arguments_are_rejected(call, name):
    with pytest.raises(ValueError, match=name):
        call()
