"""Tests of drake_wbc.math.distribution against independent formulations.

J_wb is built here by hand as [R6, J_b] from its definition in eq. (fk),
not with drake_wbc.math.kinematics, so that these tests stand on their own.
"""

import itertools

import numpy as np
import pytest
from reference_kinematics import random_rotation

from drake_wbc.math.distribution import (
    DEFAULT_DAMPING,
    SingularityDamping,
    capability_null_velocity,
    distribute,
    weighted_distribution,
    weighted_pseudoinverse,
    weighting_matrix,
)

N_CASES = 300
BOUNDARY_SIGMAS = [
    (0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0),
    (0.0, 0.4), (0.7, 0.0), (1.0, 0.3), (0.6, 1.0),
]


def random_orthogonal(rng, n):
    """A random n x n orthogonal matrix (QR of a Gaussian matrix)."""
    Q, R = np.linalg.qr(rng.normal(size=(n, n)))
    return Q * np.sign(np.diag(R))


def whole_body(R, p, J_a=None):
    """[R6 J_a, J_b] of eq. (fk), with J_b of eq. (2), written out; J_a = None
    is the identity (Cartesian arm input)."""
    J_a = np.eye(6) if J_a is None else J_a
    J = np.zeros((6, 9))
    J[:3, :6] = R @ J_a[:3]
    J[3:, :6] = R @ J_a[3:]
    J[0, 6] = J[1, 7] = J[5, 8] = 1.0
    J[0, 8], J[1, 8] = -p[1], p[0]
    return J


def random_case(rng, upright=False):
    """A random J_wb = [R6, J_b] and end-effector twist V_ee.

    With upright=True the arm base's z axis is kept at least 30 deg from
    the horizontal plane of T_b: at sigma = 0 the distribution needs it not
    horizontal (proof in the pseudoinverse module docstring).
    """
    R = random_rotation(rng)
    while upright and abs(R[2, 2]) < 0.5:
        R = random_rotation(rng)
    p = rng.uniform(-1.5, 1.5, size=3)
    return whole_body(R, p), rng.normal(size=6)


def q_half(sigma_xy, sigma_phi):
    """Q^(1/2) of eq. (weight-factors), written out."""
    return np.diag(np.sqrt([
        sigma_xy, sigma_xy, 1, 1, 1, sigma_phi,
        1 - sigma_xy, 1 - sigma_xy, 1 - sigma_phi,
    ]))


def test_weighting_matrix_closed_form():
    Q = weighting_matrix(0.25, 0.75)
    np.testing.assert_array_equal(
        Q, np.diag([0.25, 0.25, 1, 1, 1, 0.75, 0.75, 0.75, 0.25])
    )


def test_reproduces_end_effector_twist_interior_sigmas():
    rng = np.random.default_rng(10)
    for _ in range(N_CASES):
        J, V_ee = random_case(rng)
        s_xy, s_phi = rng.uniform(0.0, 1.0, size=2)
        V_wb = distribute(J, V_ee, s_xy, s_phi)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)


@pytest.mark.parametrize("sigmas", BOUNDARY_SIGMAS)
def test_reproduces_end_effector_twist_boundary_sigmas(sigmas):
    rng = np.random.default_rng(11)
    for _ in range(N_CASES // 3):
        J, V_ee = random_case(rng, upright=True)
        V_wb = distribute(J, V_ee, *sigmas)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)


def test_sigma_one_moves_only_the_arm():
    rng = np.random.default_rng(12)
    for _ in range(N_CASES):
        J, V_ee = random_case(rng)
        V_wb = distribute(J, V_ee, 1.0, 1.0)
        np.testing.assert_allclose(V_wb[6:], 0.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)


def test_sigma_zero_leaves_no_planar_motion_to_the_arm():
    """With ^bR_a = I the arm's x, y and yaw components are the end
    effector's planar translation and yaw in T_b, so at sigma = 0 the base
    must do all of them. (With a rotated arm base V_a[0], V_a[1], V_a[5]
    are still zero, their weights being zero, but they are components in
    T_a: the arm's other components can then still move the end effector
    in the plane of T_b, and the closed form of V_b below fails.)"""
    rng = np.random.default_rng(13)
    for _ in range(N_CASES):
        p = rng.uniform(-1.5, 1.5, size=3)
        J, V_ee = whole_body(np.eye(3), p), rng.normal(size=6)
        V_wb = distribute(J, V_ee, 0.0, 0.0)
        np.testing.assert_allclose(V_wb[[0, 1, 5]], 0.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)
        # The base alone carries the yaw rate and, with it, the planar
        # translation (closed form from eq. (2)).
        wz = V_ee[5]
        np.testing.assert_allclose(
            V_wb[6:], [V_ee[0] + wz * p[1], V_ee[1] - wz * p[0], wz],
            rtol=0, atol=1e-9,
        )


def test_null_space_term_does_not_move_the_end_effector():
    rng = np.random.default_rng(14)
    sigmas = [tuple(rng.uniform(0, 1, size=2)) for _ in range(N_CASES)]
    sigmas += BOUNDARY_SIGMAS
    for s_xy, s_phi in sigmas:
        J, V_ee = random_case(rng, upright=True)
        V_n = 10.0 * rng.normal(size=9)
        with_null = distribute(J, V_ee, s_xy, s_phi, null_velocity=V_n)
        without = distribute(J, V_ee, s_xy, s_phi)
        difference = with_null - without
        np.testing.assert_allclose(J @ difference, 0.0, rtol=0, atol=1e-9)
    # The null-space term is not trivially zero.
    assert np.linalg.norm(difference) > 1e-3


def test_capability_null_velocity_in_distribution():
    rng = np.random.default_rng(15)
    for _ in range(50):
        J, V_ee = random_case(rng)
        grad, k_n = rng.normal(size=6), rng.uniform(0.0, 5.0)
        V_n = capability_null_velocity(grad, k_n)
        np.testing.assert_array_equal(V_n, np.concatenate([k_n * grad,
                                                           np.zeros(3)]))
        V_wb = distribute(J, V_ee, 0.5, 0.5, null_velocity=V_n)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)


def distribute_as_written(J, V_ee, sigma_xy, sigma_phi, V_n, damping):
    """Eqs. (wbsln)/(wbccm) as written: J^+ from the eigenvalues of
    J Q J^T with the damping rule of the module docstring and an explicit
    inverse, then J^+ V_ee + (I - J^+ J) V_n."""
    Q = np.diag([sigma_xy, sigma_xy, 1, 1, 1, sigma_phi, 1 - sigma_xy,
                 1 - sigma_xy, 1 - sigma_phi])
    M = J @ Q @ J.T
    M = 0.5 * (M + M.T)
    if damping is not None:
        e = np.linalg.eigvalsh(M)
        s_min, s_max = max(e[0], 0.0), e[-1]
        eps = damping.threshold * s_max
        if s_min < eps:
            M += np.eye(6) * damping.max_squared * s_max * (
                1 - (s_min / eps) ** 2)
    J_pinv = Q @ J.T @ np.linalg.inv(M)
    return J_pinv @ V_ee + (np.eye(9) - J_pinv @ J) @ V_n


def jacobians_of_three_kinds(rng, count):
    """(kind, J): the controller's [R_ba, J_b] (kind 0), random ones (1)
    and random ones made nearly singular so that the damping acts (2)."""
    for i in range(count):
        kind = i % 3
        if kind == 0:
            J = whole_body(random_rotation(rng), rng.uniform(-1.0, 1.0, 3))
        else:
            J = rng.normal(size=(6, 9))
            if kind == 2:
                J[5] = J[4] + rng.choice([0.0, 1e-6, 1e-3, 3e-2]) * J[5]
        yield kind, J


def test_distribute_matches_the_formula_as_written():
    rng = np.random.default_rng(25)
    worst = {}
    for kind, J in jacobians_of_three_kinds(rng, 600):
        sigma_xy, sigma_phi = rng.choice([0.0, 1.0, *rng.uniform(size=3)], 2)
        V_ee, V_n = rng.normal(size=6), rng.normal(size=9)
        expected = distribute_as_written(J, V_ee, sigma_xy, sigma_phi, V_n,
                                         DEFAULT_DAMPING)
        actual = distribute(J, V_ee, sigma_xy, sigma_phi, V_n)
        error = np.max(np.abs(actual - expected)) / np.max(np.abs(expected))
        worst[kind] = max(worst.get(kind, 0.0), error)
    # Kind 2 (damped, condition numbers up to 1e4) loses digits in the
    # explicit inverse of the formula as written itself; kinds 0 and 1
    # differ by rounding, whose last digit depends on the LAPACK at hand
    # (up to 1.1e-12 seen).
    assert worst[0] < 5e-12 and worst[1] < 5e-12
    assert worst[2] < 1e-9


def test_the_pseudoinverse_is_the_distribution_of_the_unit_twists():
    """J^+ V_ee = distribute(V_ee) without null-space term, and J^+ is
    the formula as written applied to I, damped or not."""
    rng = np.random.default_rng(26)
    for _, J in jacobians_of_three_kinds(rng, 60):
        sigma = rng.uniform(size=2)
        V_ee = rng.normal(size=6)
        J_pinv = weighted_pseudoinverse(J, weighting_matrix(*sigma))
        np.testing.assert_allclose(distribute(J, V_ee, *sigma),
                                   J_pinv @ V_ee, rtol=0,
                                   atol=1e-12 * np.abs(J_pinv @ V_ee).max())
        expected = distribute_as_written(J, np.eye(6), *sigma,
                                         np.zeros((9, 6)), DEFAULT_DAMPING)
        np.testing.assert_allclose(J_pinv, expected, rtol=0,
                                   atol=1e-9 * np.abs(expected).max())


def test_weighted_least_norm_matches_kkt_solution():
    """For sigma in (0, 1), W = Q^-1 exists: the solution of eq. (wln),
    min 1/2 V^T W V s.t. J V = V_ee, solves the KKT system
    [[W, J^T], [J, 0]] [V; mu] = [0; V_ee]."""
    rng = np.random.default_rng(16)
    for _ in range(N_CASES):
        J, V_ee = random_case(rng)
        s_xy, s_phi = rng.uniform(0.05, 0.95, size=2)
        W = np.diag(1.0 / np.diag(q_half(s_xy, s_phi) ** 2))
        kkt = np.zeros((15, 15))
        kkt[:9, :9], kkt[:9, 9:], kkt[9:, :9] = W, J.T, J
        V_kkt = np.linalg.solve(kkt, np.concatenate([np.zeros(9), V_ee]))[:9]
        V_wb = distribute(J, V_ee, s_xy, s_phi)
        np.testing.assert_allclose(V_wb, V_kkt, rtol=0, atol=1e-9)
        # And it beats other solutions of J V = V_ee in the W-norm.
        other = V_wb + (np.eye(9) - np.linalg.pinv(J) @ J) @ rng.normal(
            size=9
        )
        assert V_wb @ W @ V_wb <= other @ W @ other + 1e-12


@pytest.mark.parametrize("sigmas", BOUNDARY_SIGMAS)
def test_weighted_least_norm_with_singular_weights(sigmas):
    """At sigma = 0 or 1 some weights are zero (W infinite there): the
    solution is V = Q^(1/2) z with z the least-norm solution of
    J Q^(1/2) z = V_ee, i.e. Q^(1/2) pinv(J Q^(1/2)) V_ee."""
    rng = np.random.default_rng(17)
    H = q_half(*sigmas)
    for _ in range(100):
        J, V_ee = random_case(rng, upright=True)
        expected = H @ np.linalg.pinv(J @ H) @ V_ee
        np.testing.assert_allclose(
            distribute(J, V_ee, *sigmas), expected, rtol=0, atol=1e-9
        )


def test_general_weights_give_a_right_inverse():
    rng = np.random.default_rng(18)
    for _ in range(50):
        J = rng.normal(size=(6, 9))
        A = rng.normal(size=(9, 9))
        Q = A @ A.T
        J_pinv = weighted_pseudoinverse(J, Q)
        assert J_pinv.shape == (9, 6)
        np.testing.assert_allclose(J @ J_pinv, np.eye(6), atol=1e-9)
        # Closed form of eq. (wbsln) with an explicit inverse, for the test
        # only.
        np.testing.assert_allclose(
            J_pinv, Q @ J.T @ np.linalg.inv(J @ Q @ J.T), atol=1e-9
        )


def test_sideways_arm_at_sigma_zero_is_the_one_singular_case():
    """An arm base whose z axis is horizontal in T_b (a_z = 0): at
    sigma_xy = 0 the arm may not translate in its own x-y plane, which now
    contains the vertical, and the base cannot move vertically; at
    sigma_phi = 0 the arm may not turn about its own z axis, which is now
    horizontal, and the base turns only about the vertical. Either way
    J Q J^T is singular, as the pseudoinverse module docstring states.
    With both sigmas in (0, 1] the same mounting is fine."""
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    assert R[2, 2] == 0.0
    J = whole_body(R, [0.6, 0.2, 0.8])
    for sigmas in [(0.0, 0.5), (0.5, 0.0), (0.0, 0.0), (0.0, 1.0)]:
        Q = weighting_matrix(*sigmas)
        assert np.linalg.eigvalsh(J @ Q @ J.T)[0] < 1e-12
        with pytest.raises(ValueError, match="J_wb"):
            weighted_pseudoinverse(J, Q, damping=None)
    V_ee = np.array([0.1, -0.2, 0.3, 0.05, 0.0, -0.1])
    for sigmas in [(0.2, 0.5), (1.0, 1.0), (1.0, 0.3), (0.01, 0.01)]:
        V_wb = distribute(J, V_ee, *sigmas)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)


def singular_arm_case(rng, smallest_singular_value):
    """J_wb = [R6 J_a, J_b] with a geometric arm block J_a of singular
    values (1, 0.8, 0.6, 0.5, 0.4, smallest)."""
    singular_values = [1.0, 0.8, 0.6, 0.5, 0.4, smallest_singular_value]
    J_a = (
        random_orthogonal(rng, 6)
        @ np.diag(singular_values)
        @ random_orthogonal(rng, 6)
    )
    R = random_rotation(rng)
    return whole_body(R, rng.uniform(-1, 1, size=3), J_a), rng.normal(size=6)


def test_damped_branch_at_an_exact_singularity():
    """sigma = 1 gives all the motion to an arm whose geometric Jacobian
    has lost rank, so J Q J^T is singular and the damped inverse is used.
    In the SVD of J Q^(1/2) the damped solution scales the least-squares
    one along each direction of singular value s_i by s_i^2 / (s_i^2 +
    lambda^2) and drops the lost direction, as least squares does. Hence
    it is finite and within lambda_max^2 / s_5^2 (relative) of the
    minimum-norm least-squares solution pinv(J_a part) V_ee, here
    lambda_max^2 = 1e-4 * 1^2 and s_5 = 0.4."""
    rng = np.random.default_rng(19)
    bound = SingularityDamping().max_squared / 0.4**2
    for _ in range(50):
        J, V_ee = singular_arm_case(rng, 0.0)
        V_wb = distribute(J, V_ee, 1.0, 1.0)
        assert np.all(np.isfinite(V_wb))
        least_squares = np.concatenate(
            [np.linalg.pinv(J[:, :6]) @ V_ee, np.zeros(3)]
        )
        error = np.linalg.norm(V_wb - least_squares)
        assert error <= bound * np.linalg.norm(least_squares) * (1 + 1e-9)
        # Damping is active: the solution is not exactly least squares.
        assert error > 1e-3 * bound * np.linalg.norm(least_squares)
    with pytest.raises(ValueError, match="J_wb"):
        distribute(J, V_ee, 1.0, 1.0, damping=None)


def test_damped_branch_bounds_the_motion_near_a_singularity():
    """With a smallest singular value of 1e-5 the undamped solution moves
    the arm with a gain of 1e5 along the weak direction; the damped one is
    bounded by 1 / (2 lambda) per unit of V_ee (max of s / (s^2 +
    lambda^2) over s), here lambda^2 = 1e-4 (1 - (1e-10 / 1e-4)^2) and
    1 / (2 lambda) is about 50."""
    rng = np.random.default_rng(20)
    for _ in range(50):
        J, V_ee = singular_arm_case(rng, 1e-5)
        damped = distribute(J, V_ee, 1.0, 1.0)
        undamped = distribute(J, V_ee, 1.0, 1.0, damping=None)
        assert np.linalg.norm(damped) <= 50.0 * np.linalg.norm(V_ee)
        assert np.linalg.norm(undamped) > 100.0 * np.linalg.norm(damped)


def test_no_damping_above_the_threshold():
    """Smallest singular value 0.02: J Q J^T has condition number 2500 <
    1e4, so the exact formula is used and J V_wb = V_ee."""
    rng = np.random.default_rng(21)
    for _ in range(50):
        J, V_ee = singular_arm_case(rng, 0.02)
        V_wb = distribute(J, V_ee, 1.0, 1.0)
        np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            V_wb, distribute(J, V_ee, 1.0, 1.0, damping=None), atol=1e-12
        )


def test_damping_is_continuous_at_the_threshold():
    """s_min / s_max = 1e-4 sits just below one threshold and just above
    the other: lambda^2 = 1e-4 (1 - 1 / 1.01^2), about 2 % of s_min, so the
    two pseudo-inverses differ by about 2 % (in the weak direction)."""
    rng = np.random.default_rng(22)
    J, _ = singular_arm_case(rng, 1e-2)
    Q = weighting_matrix(1.0, 1.0)
    above = weighted_pseudoinverse(J, Q, SingularityDamping(0.99e-4))
    below = weighted_pseudoinverse(J, Q, SingularityDamping(1.01e-4))
    difference = np.linalg.norm(below - above, 2)
    assert 1e-3 * np.linalg.norm(above, 2) < difference
    assert difference < 3e-2 * np.linalg.norm(above, 2)


def test_damped_matrix_keeps_its_smallest_eigenvalue_near_eps():
    """With lambda_max^2 = eps (the defaults) the weak-direction gain of
    (J Q J^T + lambda^2 I)^-1 stays within [1 / (1.25 eps), 1 / eps] for
    every s_min in [0, eps]: through J^+ = Q J^T (...)^-1 with Q = diag(I,
    0), the gain of J^+ along that direction is s / (s^2 + lambda^2),
    s = sqrt(s_min), and is checked here against that closed form."""
    rng = np.random.default_rng(24)
    Q = weighting_matrix(1.0, 1.0)
    for smallest in [0.0, 1e-4, 3e-3, 5e-3, 7e-3, 9.9e-3]:
        J, _ = singular_arm_case(rng, smallest)
        U, S, _ = np.linalg.svd(J[:, :6])
        s_min, eps = smallest**2, 1e-4 * S[0] ** 2
        lambda_sq = 1e-4 * S[0] ** 2 * (1 - (s_min / eps) ** 2)
        assert eps <= s_min + lambda_sq <= 1.25 * eps
        gain = np.linalg.norm(weighted_pseudoinverse(J, Q) @ U[:, 5])
        np.testing.assert_allclose(
            gain, smallest / (s_min + lambda_sq), rtol=1e-6, atol=1e-12
        )


def test_zero_jacobian_gives_zero():
    V_wb = distribute(np.zeros((6, 9)), np.ones(6), 0.5, 0.5)
    np.testing.assert_array_equal(V_wb, np.zeros(9))


@pytest.mark.parametrize(
    ("name", "value"),
    [("sigma_xy", -0.1), ("sigma_xy", 1.1), ("sigma_phi", -0.1),
     ("sigma_phi", 1.1), ("sigma_xy", np.nan), ("sigma_phi", np.inf)],
)
def test_sigma_outside_unit_interval_is_rejected(name, value):
    sigmas = {"sigma_xy": 0.5, "sigma_phi": 0.5, name: value}
    with pytest.raises(ValueError, match=name):
        weighting_matrix(**sigmas)
    with pytest.raises(ValueError, match=name):
        distribute(np.ones((6, 9)), np.zeros(6), **sigmas)


def test_bad_arrays_are_rejected():
    J = whole_body(np.eye(3), [0.5, 0.1, 1.0])
    with pytest.raises(ValueError, match="V_ee"):
        distribute(J, [0, 0, 0, np.nan, 0, 0], 0.5, 0.5)
    with pytest.raises(ValueError, match="V_ee"):
        distribute(J, np.zeros(9), 0.5, 0.5)
    with pytest.raises(ValueError, match="J_wb"):
        distribute(J[:, :6], np.zeros(6), 0.5, 0.5)
    with pytest.raises(ValueError, match="J_wb"):
        distribute(np.full((6, 9), np.nan), np.zeros(6), 0.5, 0.5)
    with pytest.raises(ValueError, match="null_velocity"):
        distribute(J, np.zeros(6), 0.5, 0.5, null_velocity=np.zeros(6))
    with pytest.raises(ValueError, match="null_velocity"):
        distribute(J, np.zeros(6), 0.5, 0.5, null_velocity=[np.nan] * 9)
    with pytest.raises(ValueError, match="damping"):
        distribute(J, np.zeros(6), 0.5, 0.5, damping=1e-3)


def test_bad_weights_are_rejected():
    J = whole_body(np.eye(3), [0.5, 0.1, 1.0])
    Q = np.eye(9)
    Q[0, 1] = 0.5
    with pytest.raises(ValueError, match="Q.*symmetric"):
        weighted_pseudoinverse(J, Q)
    with pytest.raises(ValueError, match="Q.*semidefinite"):
        weighted_pseudoinverse(J, -np.eye(9))
    with pytest.raises(ValueError, match="Q"):
        weighted_pseudoinverse(J, np.eye(6))
    with pytest.raises(ValueError, match="Q"):
        weighted_pseudoinverse(J, np.full((9, 9), np.nan))


def test_bad_damping_parameters_are_rejected():
    with pytest.raises(ValueError, match="threshold"):
        SingularityDamping(threshold=0.0)
    with pytest.raises(ValueError, match="max_squared"):
        SingularityDamping(max_squared=-1e-4)


@pytest.mark.parametrize("k_n", [-1e-3, -1.0, np.nan])
def test_negative_gain_is_rejected(k_n):
    with pytest.raises(ValueError, match="k_n"):
        capability_null_velocity(np.ones(6), k_n)


def test_bad_gradient_is_rejected():
    for bad in [np.ones(5), [0, 0, np.nan, 0, 0, 0]]:
        with pytest.raises(ValueError, match="grad_x_C_m"):
            capability_null_velocity(bad, 1.0)


def test_sigma_grid_boundaries_agree_with_nearby_interior():
    """The boundary solutions are limits of the interior ones."""
    rng = np.random.default_rng(23)
    J, V_ee = random_case(rng, upright=True)
    for s_xy, s_phi in itertools.product([0.0, 1.0], repeat=2):
        near = [1e-7 if s == 0.0 else 1.0 - 1e-7 for s in (s_xy, s_phi)]
        np.testing.assert_allclose(
            distribute(J, V_ee, s_xy, s_phi),
            distribute(J, V_ee, *near),
            rtol=0, atol=1e-5,
        )


def test_a_strided_twist_compiles_nothing_new():
    """The float kernel gives a strided view (a reversed twist), a
    read-only array or a list to its sealed closed form as the
    C-contiguous array it was compiled for, and a 0-d array as a float:
    the same result, no new signature."""
    from drake_wbc.math import distribution, kernels

    kernel = next(k for k in kernels.registered_kernels()
                  if k.reference is distribution.whole_body_distribution)
    kernels.warm(kernel)
    signatures = len(distribution._closed_form.signatures)
    args = list(kernel.sample(np.random.default_rng(3)))
    args[2] = None  # the usual mounting: the closed form
    expected = kernel.fast(*args)
    for index in (0, 1, 5):  # V_ee, p_ee_in_base, capability_gradient
        strided = list(args)
        strided[index] = np.array(args[index][::-1])[::-1]
        assert not strided[index].flags.c_contiguous
        np.testing.assert_array_equal(kernel.fast(*strided), expected)
        read_only = list(args)
        read_only[index] = np.array(args[index])
        read_only[index].flags.writeable = False
        np.testing.assert_array_equal(kernel.fast(*read_only), expected)
        listed = list(args)
        listed[index] = list(args[index])
        np.testing.assert_array_equal(kernel.fast(*listed), expected)
    for index in (3, 4, 6):  # sigma_xy, sigma_phi, k_n as 0-d arrays
        scalar = list(args)
        scalar[index] = np.array(args[index])
        np.testing.assert_array_equal(kernel.fast(*scalar), expected)
    assert len(distribution._closed_form.signatures) == signatures == 1


def test_without_damping_a_zero_jacobian_is_rejected_not_zero():
    """J Q J^T = 0 is not positive definite: with damping=None the checked
    functions raise, as they do for a singular one (the reference gives
    NaN: no exact inverse), rather than give zeros."""
    J = np.zeros((6, 9))
    with pytest.raises(ValueError, match="J_wb .*damping=None"):
        weighted_pseudoinverse(J, weighting_matrix(0.5, 0.5), damping=None)
    with pytest.raises(ValueError, match="J_wb .*damping=None"):
        distribute(J, np.ones(6), 0.5, 0.5, damping=None)
    assert np.isnan(weighted_distribution(
        J, np.ones(6), np.ones(9), damping=None)).all()
    # Damped, no weighted input moves the end effector: zeros.
    np.testing.assert_array_equal(
        weighted_pseudoinverse(J, weighting_matrix(0.5, 0.5)),
        np.zeros((9, 6)))
