"""Tests of drake_wbc.math.cdmp: transfer functions against eqs. (lp-admit) and
(tf-admit), the paper's own form of eq. (stiff-dmp), closed-form steady
states, the repulsive field against U_rep, and AutoDiff gradients."""

import numpy as np
import pytest
from reference_kinematics import central_differences
from shipped_names import FOOTPRINT
from test_dmp import check_autodiff

from drake_wbc.math.cdmp import (
    AdmittanceCouplingParameters,
    ArmCdmpParameters,
    BaseCdmpParameters,
    StiffnessCouplingParameters,
    WholeBodyCdmpParameters,
    admittance_coupled_derivative,
    arm_cdmp_derivative,
    base_cdmp_derivative,
    paper_velocity,
    shifted_velocity,
    stiffness_coupled_derivative,
    whole_body_cdmp_derivative,
)
from drake_wbc.math.dmp import DmpParameters
from drake_wbc.math.repulsion import (
    RepulsiveFieldParameters,
    footprint_distance,
    repulsive_force,
    repulsive_force_float,
    repulsive_potential,
)

FREQUENCIES = 1j * np.logspace(-3, 3, 61)
W_N = np.sqrt(25.0 * 6.25)  # natural frequency of the default attractor


def state_space(derivative, n_x, n_u):
    """(A, B) of an affine x_dot = derivative(x, u), evaluated at unit
    vectors."""
    x0, u0 = np.zeros(n_x), np.zeros(n_u)
    offset = derivative(x0, u0)
    A = np.array([derivative(e, u0) - offset for e in np.eye(n_x)]).T
    B = np.array([derivative(x0, e) - offset for e in np.eye(n_u)]).T
    return A, B


def transfer(A, B, C, D, s):
    return C @ np.linalg.solve(s * np.eye(len(A)) - A, B) + D


def integrate(derivative, x, t_end, dt=1e-3):
    """RK4 of x_dot = derivative(t, x) from 0 to t_end; returns x(t_end)."""
    t = 0.0
    for _ in range(int(round(t_end / dt))):
        k1 = derivative(t, x)
        k2 = derivative(t + dt / 2, x + dt / 2 * k1)
        k3 = derivative(t + dt / 2, x + dt / 2 * k2)
        k4 = derivative(t + dt, x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt
    return x


# ----------------------------------------------------------------------------
# Stiffness-coupled DMP, eqs. (stiff-dmp), (lp-admit)
# ----------------------------------------------------------------------------

@pytest.mark.parametrize(("tau", "k_d"), [(1.0, 0.0), (1.7, 0.3),
                                          (0.5, 2.0)])
def test_stiffness_transfer_function_is_lp_admit(tau, k_d):
    params = StiffnessCouplingParameters(
        k_p=0.02, k_d=k_d, dmp=DmpParameters(alpha_z=20.0, beta_z=4.0,
                                             tau=tau))

    def derivative(x, u):
        return np.concatenate(stiffness_coupled_derivative(
            x[:1], x[1:], np.zeros(1), u, params))

    A, B = state_space(derivative, 2, 1)
    C, D = np.array([[1.0, 0.0]]), np.zeros((1, 1))
    for s in FREQUENCIES:
        expected = 0.02 * ((tau**2 + k_d) * s + tau * 20.0) / (
            tau**2 * s**2 + tau * 20.0 * s + 20.0 * 4.0)
        np.testing.assert_allclose(transfer(A, B, C, D, s)[0, 0], expected,
                                   rtol=1e-9)


def test_stiffness_shifted_state_matches_the_paper_form():
    """The paper's (y, z) with k_d C_f_dot from an analytic F_dot, and the
    shifted (y, z~) with no F_dot, give the same motion."""
    params = StiffnessCouplingParameters(
        k_p=0.01, k_d=0.4, dmp=DmpParameters(tau=1.3))
    tau, a_z, b_z = 1.3, 25.0, 6.25
    g = np.array([0.2, -0.1])

    def F(t):
        return np.array([3 * np.sin(2 * t) + 1, np.cos(5 * t)])

    def F_dot(t):
        return np.array([6 * np.cos(2 * t), -5 * np.sin(5 * t)])

    def paper(t, x):
        y, z = x[:2], x[2:]
        z_dot = (a_z * (b_z * (g - y) - z) + 0.4 * 0.01 * F_dot(t)) / tau
        return np.concatenate([(z + tau * 0.01 * F(t)) / tau, z_dot])

    def shifted(t, x):
        return np.concatenate(stiffness_coupled_derivative(
            x[:2], x[2:], g, F(t), params))

    y0, z0 = np.array([0.0, 0.3]), np.array([0.1, 0.0])
    x_paper = integrate(paper, np.concatenate([y0, z0]), 2.0)
    z0_tilde = shifted_velocity(z0, 0.01 * F(0.0), 0.4, tau)
    x_ours = integrate(shifted, np.concatenate([y0, z0_tilde]), 2.0)
    np.testing.assert_allclose(x_ours[:2], x_paper[:2], atol=1e-10)
    np.testing.assert_allclose(
        paper_velocity(x_ours[2:], 0.01 * F(2.0), 0.4, tau), x_paper[2:],
        atol=1e-10)


# ----------------------------------------------------------------------------
# Admittance-coupled DMP, eqs. (admit-dmp), (tf-admit)
# ----------------------------------------------------------------------------

def random_spd(rng, n):
    M = rng.normal(size=(n, n))
    return M @ M.T + n * np.eye(n)


def admittance_system(params, d):
    def derivative(x, u):
        return np.concatenate(admittance_coupled_derivative(
            x[:d], x[d:2 * d], x[2 * d:], np.zeros(d), u, params))
    return state_space(derivative, 3 * d, d)


@pytest.mark.parametrize("tau", [1.0, 0.4])
def test_admittance_transfer_function_is_exactly_D_a_over_s(tau):
    """e = y - g - C is not driven by F_e, so from rest L(y) = D_a L(F_e)
    / s at every frequency (derivation in the docstring)."""
    rng = np.random.default_rng(10)
    D_a = 0.01 * random_spd(rng, 3)
    params = AdmittanceCouplingParameters(D_a, F_d=rng.normal(size=3),
                                          dmp=DmpParameters(tau=tau))
    A, B = admittance_system(params, 3)
    y_out = np.hstack([np.eye(3), np.zeros((3, 6))])
    error_out = np.hstack([np.eye(3), np.zeros((3, 3)), -np.eye(3)])
    for s in FREQUENCIES:
        H = transfer(A, B, y_out, np.zeros((3, 3)), s)
        np.testing.assert_allclose(H, D_a / s, rtol=1e-9,
                                   atol=1e-9 * np.abs(D_a / s).max())
        np.testing.assert_allclose(
            transfer(A, B, error_out, np.zeros((3, 3)), s), 0.0,
            atol=1e-12 * np.abs(D_a / s).max())
    # Low frequency: s H(s) -> D_a; the velocity y_dot = s y has D_a.
    s = 1e-7j
    np.testing.assert_allclose(s * transfer(A, B, y_out, 0, s), D_a,
                               rtol=1e-9)
    velocity_out, velocity_feedthrough = A[:3], B[:3]
    for s in FREQUENCIES:
        np.testing.assert_allclose(
            transfer(A, B, velocity_out, velocity_feedthrough, s), D_a,
            rtol=1e-9, atol=1e-12)


def test_admittance_initial_mismatch_decays_critically_damped():
    rng = np.random.default_rng(11)
    params = AdmittanceCouplingParameters(0.05, F_d=1.0)
    g, e0 = rng.normal(size=(2, 2))

    def derivative(t, x):
        F_e = np.array([np.sin(3 * t), 2 * np.cos(t)])
        return np.concatenate(admittance_coupled_derivative(
            x[:2], x[2:4], x[4:], g, F_e, params))

    for t_end in (0.1, 0.3, 1.0):
        x = integrate(derivative, np.concatenate([g + e0, np.zeros(4)]),
                      t_end)
        e = x[:2] - g - x[4:]
        np.testing.assert_allclose(
            e, e0 * (1 + W_N * t_end) * np.exp(-W_N * t_end), atol=1e-9)


# ----------------------------------------------------------------------------
# Whole-body CDMP, eqs. (cdmp-wb), (cdmp-wb-error)
# ----------------------------------------------------------------------------

def test_whole_body_velocity_interface():
    rng = np.random.default_rng(12)
    g, C, E, V_ee, F_ext, delta = rng.normal(size=(6, 6))
    y = g + C - E  # on the goal: the end effector at g + C
    params = WholeBodyCdmpParameters()
    for S_hri in (0.0, 1.0):
        y_dot, z_dot, C_dot, E_dot = whole_body_cdmp_derivative(
            y, np.zeros(6), C, E, g, V_ee, F_ext, delta, params, S_hri)
        np.testing.assert_allclose(C_dot, V_ee + 0.05 * S_hri * F_ext)
        np.testing.assert_allclose(y_dot, C_dot)
        np.testing.assert_allclose(z_dot, 0.0, atol=1e-12)
        np.testing.assert_array_equal(E_dot, delta)


def test_whole_body_commands_back_the_accumulated_deviation():
    """A deviation pulse of 0.05 m/s for 0.4 s: the real end effector
    y + E returns to g + C, y moves by -E."""
    params = WholeBodyCdmpParameters()
    g, zero = np.full(6, 0.1), np.zeros(6)
    delta = np.array([0.05, -0.05, 0.0, 0.0, 0.02, 0.0])

    def derivative(t, x):
        y, z, C, E = np.split(x, 4)
        return np.concatenate(whole_body_cdmp_derivative(
            y, z, C, E, g, zero, zero, delta if t < 0.4 else zero, params))

    x = integrate(derivative, np.concatenate([g, zero, zero, zero]), 2.0)
    y, _, C, E = np.split(x, 4)
    np.testing.assert_allclose(E, 0.4 * delta, atol=1e-4)  # steps at 1 ms
    np.testing.assert_allclose(y + E, g + C, atol=1e-6)


# ----------------------------------------------------------------------------
# Repulsive field and base CDMP, eq. (cdmp-base)
# ----------------------------------------------------------------------------

FIELD = RepulsiveFieldParameters(half_sizes=FOOTPRINT)


def reference_distance(p, half_sizes=(0.4, 0.3)):
    """Distance and direction from the rectangle by its nearest point."""
    nearest = np.clip(p, -np.array(half_sizes), half_sizes)
    d = np.linalg.norm(p - nearest)
    return d, (p - nearest) / max(d, 1e-300)


def random_points_near(rng, count, lo=0.06, hi=0.49):
    """Points outside the footprint at distances in (lo, hi)."""
    points = []
    while len(points) < count:
        p = rng.uniform(-1.0, 1.0, size=2)
        d, _ = reference_distance(p)
        if lo < d < hi:
            points.append(p)
    return np.array(points)


def test_repulsive_force_closed_form_and_direction():
    rng = np.random.default_rng(13)
    for p in random_points_near(rng, 100):
        d, n = reference_distance(p)
        f = repulsive_force(p[None], FIELD)
        magnitude = 0.01 * (1 / d - 1 / 0.5) / d**2  # |dU/dd|
        np.testing.assert_allclose(f, -magnitude * n, rtol=1e-12)
        assert f @ n < 0.0  # away from the obstacle point
        d_lib, n_lib = footprint_distance(p[None], FIELD)
        np.testing.assert_allclose(d_lib[0], d, rtol=1e-12)
        np.testing.assert_allclose(n_lib[0], n, rtol=1e-12)


def test_repulsive_force_is_gradient_of_U_rep():
    """f_avoid = dU_rep/dp (p the obstacle point in T_b) = -dU/d(base)."""
    rng = np.random.default_rng(14)
    points = random_points_near(rng, 20)
    for p in points:
        numeric = central_differences(
            lambda q: repulsive_potential(q[None], FIELD), p, h=1e-7)
        np.testing.assert_allclose(repulsive_force(p[None], FIELD), numeric,
                                   rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(
        repulsive_force(points, FIELD),
        sum(repulsive_force(p[None], FIELD) for p in points), rtol=1e-12)
    d = np.array([reference_distance(p)[0] for p in points])
    np.testing.assert_allclose(repulsive_potential(points, FIELD),
                               np.sum(0.005 * (1 / d - 2.0) ** 2))


@pytest.mark.parametrize("force", [repulsive_force, repulsive_force_float])
def test_repulsive_force_is_gradient_of_U_rep_at_the_switches(force):
    """f_avoid = dU_rep/dp by central differences where U_rep's pieces
    meet: 1e-4 m inside d_th and outside d_min, along a side and off a
    corner, and 1e-4 m either side of the lines x = a and y = b that part
    the sides' regions from the corners'."""
    a, b = FIELD.half_sizes
    points = []
    for d in (FIELD.d_th - 1e-4, FIELD.d_min + 1e-4):
        for angle in (0.0, 0.5 * np.pi, np.pi, 0.25 * np.pi, -0.75 * np.pi):
            direction = np.array([np.cos(angle), np.sin(angle)])
            corner = np.where(direction > 1e-12, [a, b],
                              np.where(direction < -1e-12, [-a, -b],
                                       [0.0, 0.0]))
            points.append(corner + d * direction)
    for side in (-1e-4, 1e-4):
        points += [np.array([a + side, b + 0.2]),
                   np.array([-a - 0.2, -b + side])]
    for p in points:
        numeric = central_differences(
            lambda q: repulsive_potential(q[None], FIELD), p, h=1e-7)
        np.testing.assert_allclose(force(p[None], FIELD), numeric,
                                   rtol=1e-6, atol=1e-9, err_msg=p)


def test_repulsive_force_zero_beyond_threshold_finite_inside():
    beyond = np.array([[0.91, 0.0], [0.0, -0.81], [0.8, 0.7], [3.0, 1.0]])
    np.testing.assert_array_equal(repulsive_force(beyond, FIELD), 0.0)
    assert repulsive_potential(beyond, FIELD) == 0.0
    np.testing.assert_array_equal(repulsive_force(np.zeros((0, 2)), FIELD),
                                  0.0)
    np.testing.assert_allclose(repulsive_force([[0.8999999, 0.0]], FIELD),
                               0.0, atol=1e-5)
    # Inside or on the footprint: the push at d_min along the nearest side.
    push = 0.01 * (1 / 0.05 - 2.0) / 0.05**2
    for p, n in [([0.39, 0.0], [1, 0]), ([0.0, -0.29], [0, -1]),
                 ([0.0, 0.0], [0, 1]), ([0.4, 0.3], [1, 0]),
                 ([0.42, 0.0], [1, 0])]:
        f = repulsive_force([p], FIELD)
        assert np.all(np.isfinite(f))
        np.testing.assert_allclose(f, -push * np.array(n), rtol=1e-12)


@pytest.mark.parametrize("force", [repulsive_force, repulsive_force_float])
def test_a_non_finite_point_makes_the_force_nan(force):
    """In the reference and in its float kernel (so that the checks
    downstream see a bad scan)."""
    for bad in (np.nan, np.inf):
        points = np.array([[0.5, 0.0], [bad, 0.1], [3.0, 3.0]])
        with np.errstate(invalid="ignore"):
            assert np.all(np.isnan(force(points, FIELD)))


def test_base_cdmp_avoids_and_passes_velocity():
    params = BaseCdmpParameters(repulsion=FIELD)
    g, C, V_b = np.array([1.0, 2.0, 0.3]), np.zeros(3), np.array([
        0.3, 0.1, 0.2])
    y_dot, z_dot, C_dot = base_cdmp_derivative(g, np.zeros(3), C, g, V_b,
                                               np.zeros((0, 2)), params)
    np.testing.assert_allclose(y_dot, V_b)
    np.testing.assert_allclose(C_dot, V_b)
    np.testing.assert_array_equal(z_dot, 0.0)
    _, z_dot, _ = base_cdmp_derivative(g, np.zeros(3), C, g, V_b,
                                       [[0.6, 0.0]], params)
    np.testing.assert_allclose(z_dot, [-0.75, 0.0, 0.0], rtol=1e-12)
    # Held near a wall ahead, the base settles back from its goal by
    # f_avoid / (alpha_z beta_z).
    wall = np.column_stack([np.full(11, 0.7), np.linspace(-0.5, 0.5, 11)])

    def derivative(t, x):
        y, z = x[:3], x[3:6]
        return np.concatenate(base_cdmp_derivative(
            y, z, x[6:], np.zeros(3), np.zeros(3), wall - y[:2], params))

    x = integrate(derivative, np.zeros(9), 3.0)
    f = repulsive_force(wall - x[:2], FIELD)
    np.testing.assert_allclose(x[:2], f / (25.0 * 6.25), atol=1e-9)
    assert x[0] < 0.0 and x[2] == 0.0


# ----------------------------------------------------------------------------
# Arm CDMP, eq. (cdmp-arm)
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("k_d", [0.0, 0.5])
def test_arm_pure_stiffness_steady_state(k_d):
    rng = np.random.default_rng(15)
    params = ArmCdmpParameters(S_m=np.ones(6), k_d=k_d, k_p=0.002,
                               dmp=DmpParameters(tau=1.2))
    g, C_a, F = rng.normal(size=(3, 6))
    zero = np.zeros(6)

    def derivative(t, x):
        return np.concatenate(arm_cdmp_derivative(
            x[:6], x[6:12], x[12:], g, zero, F, params))

    x = integrate(derivative, np.concatenate([g, zero, C_a]), 3.0)
    np.testing.assert_allclose(x[:6], g + C_a + 0.002 * F / 6.25,
                               atol=1e-10)
    np.testing.assert_allclose(x[12:], C_a, atol=1e-14)


@pytest.mark.parametrize("S_m", [np.zeros(6), (0, 1, 1, 1, 1, 1)])
def test_arm_force_loop_reaches_desired_force(S_m):
    """Against a stiff wall F_ext = -K_env (y - y_wall), the contact force
    on the tool settles at F_d = -10 N along x."""
    params = ArmCdmpParameters(S_m=S_m)
    K_env = np.diag([1e4, 5e3, 2e3, 1e3, 1e3, 1e3])
    y_wall = np.full(6, 0.2)
    g, zero = np.full(6, 0.19), np.zeros(6)

    def force(y):
        return -K_env @ (y - y_wall)

    def derivative(t, x):
        return np.concatenate(arm_cdmp_derivative(
            x[:6], x[6:12], x[12:], g, zero, force(x[:6]), params))

    x = integrate(derivative, np.concatenate([g, zero, zero]), 3.0)
    F = force(x[:6])
    np.testing.assert_allclose(F[0], -10.0, rtol=1e-9)
    force_axes = np.asarray(S_m) == 0
    np.testing.assert_allclose(F[force_axes], params.F_d[force_axes],
                               atol=1e-8)


def test_arm_force_term_off_in_phri():
    rng = np.random.default_rng(16)
    y, z, C_a, g, V_a, F = rng.normal(size=(6, 6))
    params = ArmCdmpParameters()
    np.testing.assert_array_equal(
        arm_cdmp_derivative(y, z, C_a, g, V_a, F, params, S_hri=1.0)[2],
        V_a)
    # S_hri = 0 by default: the force control acts.
    C_a_dot = arm_cdmp_derivative(y, z, C_a, g, V_a, F, params)[2]
    np.testing.assert_allclose(C_a_dot[0], V_a[0] + 0.01 * (F[0] + 10.0))
    np.testing.assert_allclose(C_a_dot[1:], V_a[1:])


# ----------------------------------------------------------------------------
# AutoDiff and bad parameters
# ----------------------------------------------------------------------------

def test_coupled_derivatives_autodiff_gradients():
    rng = np.random.default_rng(17)
    v = 0.3 * rng.normal(size=(10, 6))
    dmp = DmpParameters(tau=1.4)
    stiff = StiffnessCouplingParameters(k_d=0.2, dmp=dmp)
    check_autodiff(
        lambda y, z, g, F: stiffness_coupled_derivative(y, z, g, F, stiff),
        list(v[:4]))
    admit = AdmittanceCouplingParameters(0.01 * random_spd(rng, 6),
                                         F_d=v[9], dmp=dmp)
    check_autodiff(
        lambda y, z, C, g, F, V: admittance_coupled_derivative(
            y, z, C, g, F, admit, V), list(v[:6]))
    whole = WholeBodyCdmpParameters(dmp=dmp)
    check_autodiff(
        lambda y, z, C, E, g, V, F, dV, S: whole_body_cdmp_derivative(
            y, z, C, E, g, V, F, dV, whole, S_hri=S[0]),
        list(v[:8]) + [np.array([1.0])])
    arm = ArmCdmpParameters(k_d=0.3, S_m=(0, 1, 0, 1, 1, 1), dmp=dmp)
    check_autodiff(
        lambda y, z, C, g, V, F, S: arm_cdmp_derivative(
            y, z, C, g, V, F, arm, S_hri=S[0]),
        [*v[:6], np.array([0.0])])
    base = BaseCdmpParameters(repulsion=FIELD, dmp=dmp)
    points = np.array([[0.6, 0.1], [-0.3, 0.45], [0.55, -0.5], [0.1, 0.05],
                       [2.0, 0.0], [-0.5, -0.42]])
    check_autodiff(
        lambda y, z, C, g, V, P: base_cdmp_derivative(y, z, C, g, V, P,
                                                      base),
        [*v[:5, :3], points], rtol=1e-6, atol=1e-6)
    check_autodiff(lambda P: [repulsive_potential(P, FIELD)], [points],
                   atol=1e-6)


@pytest.mark.parametrize(("cls", "name", "kwargs"), [
    (ArmCdmpParameters, "S_m", {"S_m": (0.5, 1, 1, 1, 1, 1)}),
    (ArmCdmpParameters, "S_m", {"S_m": np.ones((6, 6))}),
    (ArmCdmpParameters, "k_p", {"k_p": -0.1}),
    (ArmCdmpParameters, "k_f", {"k_f": -0.01}),
    (ArmCdmpParameters, "k_d", {"k_d": -1.0}),
    (ArmCdmpParameters, "F_d", {"F_d": (1.0, 2.0)}),
    (ArmCdmpParameters, "dmp", {"dmp": 1.0}),
    (WholeBodyCdmpParameters, "k_hri", {"k_hri": -0.05}),
    (StiffnessCouplingParameters, "k_p", {"k_p": -1.0}),
    (AdmittanceCouplingParameters, "D_a", {"D_a": 0.0}),
    (AdmittanceCouplingParameters, "D_a", {"D_a": [[1.0, 2.0], [2.0, 1.0]]}),
    (AdmittanceCouplingParameters, "F_d", {"D_a": np.eye(2),
                                           "F_d": [1.0, 2.0, 3.0]}),
    (RepulsiveFieldParameters, "d_th", {"d_th": 0.0}),
    (RepulsiveFieldParameters, "d_th", {"d_th": -0.5}),
    (RepulsiveFieldParameters, "k_obs", {"k_obs": -0.01}),
    (RepulsiveFieldParameters, "d_min", {"d_min": 0.6}),
    (RepulsiveFieldParameters, "half_sizes", {"half_sizes": (0.4, -0.3)}),
    (BaseCdmpParameters, "repulsion", {"repulsion": None}),
])
def test_bad_parameters_name_the_argument(cls, name, kwargs):
    with pytest.raises(ValueError, match=name):
        cls(**kwargs)
