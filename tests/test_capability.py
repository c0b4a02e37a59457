"""Tests of drake_wbc.math.capability: the values (manipulability,
joint-limit penalty, C_m, transition) against closed forms and independent
formulations, the gradients against finite differences, the reference
bodies for AutoDiffXd, and the argument checks.

Real arm Jacobians come from the independent serial-chain kinematics of
reference_kinematics: the Elfin5 table and random chains, to show nothing
is Elfin-specific.
"""

import numpy as np
import pytest
from pydrake.autodiffutils import (
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from reference_kinematics import (
    ELFIN5,
    ELFIN5_LOWER,
    ELFIN5_UPPER,
    central_differences,
    chains_under_test,
    jacobian,
    jacobian_by_differences,
    one_sided_difference,
    penalty_by_loop,
    random_nonsingular_q,
)
from singular_sides import is_one_of, one_sided_gradients

from drake_wbc.math import capability as cap

K_J = cap.DEFAULT_JOINT_LIMIT_GAIN
CHAINS = chains_under_test()
CHAIN_IDS = [name for name, *_ in CHAINS]


def test_kinematics_of_the_tests_agree_with_each_other():
    rng = np.random.default_rng(0)
    for _, chain, lower, upper in CHAINS:
        q = rng.uniform(lower, upper)
        np.testing.assert_allclose(jacobian(chain, q),
                                   jacobian_by_differences(chain, q),
                                   atol=1e-8)


# ----------------------------------------------------------------------------
# Manipulability
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("shape", [(6, 6), (6, 7), (3, 5), (1, 4)])
def test_manipulability_is_sqrt_det_and_product_of_singular_values(shape):
    rng = np.random.default_rng(1)
    for _ in range(20):
        J = rng.normal(size=shape)
        m = cap.manipulability(J)
        assert isinstance(m, float)
        np.testing.assert_allclose(m, np.sqrt(np.linalg.det(J @ J.T)),
                                   rtol=1e-10)
        np.testing.assert_allclose(
            m, np.prod(np.linalg.svd(J, compute_uv=False)), rtol=1e-12)


def test_manipulability_scales_with_rows_and_is_one_for_orthonormal_rows():
    rng = np.random.default_rng(2)
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    assert cap.manipulability(Q) == pytest.approx(1.0, rel=1e-12)
    scale = rng.uniform(0.5, 2.0, 6)
    J = rng.normal(size=(6, 6))
    np.testing.assert_allclose(cap.manipulability(scale[:, None] * J),
                               np.prod(scale) * cap.manipulability(J),
                               rtol=1e-10)


def test_manipulability_is_zero_at_singular_configurations():
    # The Elfin5 at q = 0 is stretched straight up.
    assert cap.manipulability(jacobian(ELFIN5, np.zeros(6))) < 1e-12
    J = np.random.default_rng(3).normal(size=(6, 6))
    J[:, 4] = 2.0 * J[:, 1]
    assert cap.manipulability(J) < 1e-12
    q = random_nonsingular_q(np.random.default_rng(3), ELFIN5,
                             ELFIN5_LOWER, ELFIN5_UPPER)
    assert cap.manipulability(jacobian(ELFIN5, q)) > 1e-4


# ----------------------------------------------------------------------------
# Joint-limit penalty
# ----------------------------------------------------------------------------

def test_penalty_matches_the_formula_inside_the_limits():
    rng = np.random.default_rng(4)
    for _ in range(50):
        q = rng.uniform(ELFIN5_LOWER, ELFIN5_UPPER)
        k_j = rng.uniform(1.0, 1e5)
        np.testing.assert_allclose(
            cap.joint_limit_penalty(q, ELFIN5_LOWER, ELFIN5_UPPER, k_j),
            penalty_by_loop(q, ELFIN5_LOWER, ELFIN5_UPPER, k_j),
            rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("joint", range(6))
def test_penalty_is_zero_at_and_beyond_each_limit(joint):
    rng = np.random.default_rng(5)
    q = rng.uniform(ELFIN5_LOWER, ELFIN5_UPPER)
    for limit, overshoot in ((ELFIN5_LOWER, -1e-3), (ELFIN5_UPPER, 1e-3)):
        q[joint] = limit[joint]
        assert cap.joint_limit_penalty(q, ELFIN5_LOWER, ELFIN5_UPPER,
                                       K_J) == 0.0
        q[joint] = limit[joint] + overshoot
        assert cap.joint_limit_penalty(q, ELFIN5_LOWER, ELFIN5_UPPER,
                                       K_J) == 0.0


def test_penalty_is_largest_with_every_joint_mid_range():
    rng = np.random.default_rng(6)
    lower = rng.uniform(-3.0, 0.0, 6)
    upper = lower + rng.uniform(0.5, 4.0, 6)
    mid = 0.5 * (lower + upper)
    best = cap.joint_limit_penalty(mid, lower, upper, K_J)
    for _ in range(1000):
        q = rng.uniform(lower, upper)
        assert cap.joint_limit_penalty(q, lower, upper, K_J) < best


@pytest.mark.parametrize("n", [1, 3, 6, 7])
def test_penalty_at_mid_range_closed_form_and_monotone_in_gain(n):
    lower, upper = -np.arange(1.0, n + 1), np.arange(2.0, n + 2)
    mid = 0.5 * (lower + upper)
    gains = 4.0**n * np.array([0.01, 0.1, 1.0, 3.0, 10.0, 30.0])
    penalties = [cap.joint_limit_penalty(mid, lower, upper, k) for k in gains]
    np.testing.assert_allclose(1.0 - np.array(penalties),
                               np.exp(-gains * 4.0**-n), rtol=1e-9,
                               atol=1e-15)
    assert np.all(np.diff(penalties) > 0.0)
    assert penalties[-1] > 1.0 - 1e-12


def test_default_gain_values_stated_in_its_docstring():
    mid = 0.5 * (ELFIN5_LOWER + ELFIN5_UPPER)
    near = mid.copy()
    near[2] = ELFIN5_LOWER[2] + 0.05 * (ELFIN5_UPPER[2] - ELFIN5_LOWER[2])
    p_mid = cap.joint_limit_penalty(mid, ELFIN5_LOWER, ELFIN5_UPPER)
    p_near = cap.joint_limit_penalty(near, ELFIN5_LOWER, ELFIN5_UPPER)
    assert p_mid == pytest.approx(1.0 - np.exp(-K_J / 4096.0), rel=1e-12)
    assert p_near == pytest.approx(1.0 - np.exp(-0.19 * K_J / 4096.0),
                                   rel=1e-12)
    assert p_mid == pytest.approx(0.974, abs=5e-4)
    assert p_near == pytest.approx(0.501, abs=5e-4)


def test_capability_is_manipulability_times_penalty():
    rng = np.random.default_rng(8)
    for _, chain, lower, upper in CHAINS:
        q = rng.uniform(lower, upper)
        J = jacobian(chain, q)
        expected = (np.sqrt(np.linalg.det(J @ J.T))
                    * penalty_by_loop(q, lower, upper, K_J))
        np.testing.assert_allclose(cap.capability(J, q, lower, upper, K_J),
                                   expected, rtol=1e-9)


# ----------------------------------------------------------------------------
# Transition
# ----------------------------------------------------------------------------

UPPER, LOWER = 0.05, 0.01


def test_transition_values():
    assert cap.transition(0.2, UPPER, LOWER) == 0.0
    assert cap.transition(UPPER, UPPER, LOWER) == 0.0
    assert cap.transition(LOWER, UPPER, LOWER) == 1.0
    assert cap.transition(-3.0, UPPER, LOWER) == 1.0
    mid = cap.transition(0.5 * (UPPER + LOWER), UPPER, LOWER)
    assert isinstance(mid, float)
    assert mid == pytest.approx(0.5, abs=1e-15)
    values = np.array([[0.0, 0.02], [0.04, 0.06]])
    alpha = cap.transition(values, UPPER, LOWER)
    assert alpha.shape == values.shape
    for index in np.ndindex(values.shape):
        x = (values[index] - LOWER) / (UPPER - LOWER)
        expected = 0.5 * (1.0 + np.cos(np.pi * min(max(x, 0.0), 1.0)))
        assert alpha[index] == pytest.approx(expected, abs=1e-15)


def test_transition_is_monotone_non_increasing():
    values = np.linspace(-0.1, 0.2, 20001)
    alpha = cap.transition(values, UPPER, LOWER)
    assert np.all(np.diff(alpha) <= 0.0)
    assert np.all((alpha >= 0.0) & (alpha <= 1.0))
    assert np.all(cap.transition_derivative(values, UPPER, LOWER) <= 0.0)


@pytest.mark.parametrize("edge", [LOWER, UPPER])
def test_transition_is_continuously_differentiable_at_the_band_edges(edge):
    def alpha(v):
        return cap.transition(v, UPPER, LOWER)

    # Inside the band alpha departs from its edge value as c h^2 with
    # c = pi^2 / (4 (upper - lower)^2); outside it is flat. So the one-sided
    # difference quotients on both sides, and the derivative, are O(h).
    c = 1.01 * np.pi**2 / (4.0 * (UPPER - LOWER) ** 2)
    at_edge = alpha(edge)
    for h in (1e-4, 1e-6, 1e-8):
        for side in (-1.0, 1.0):
            step = alpha(edge + side * h) - at_edge
            assert abs(step) <= c * h**2 + 1e-16
            assert abs(step / h) <= c * h + 1e-16 / h
            assert abs(cap.transition_derivative(edge + side * h, UPPER,
                                                 LOWER)) <= 2.0 * c * h
    assert cap.transition_derivative(edge, UPPER, LOWER) == 0.0


def test_transition_derivative_matches_finite_differences():
    values = np.random.default_rng(9).uniform(-0.02, 0.08, 200)
    h = 1e-7
    numeric = (cap.transition(values + h, UPPER, LOWER)
               - cap.transition(values - h, UPPER, LOWER)) / (2.0 * h)
    np.testing.assert_allclose(
        cap.transition_derivative(values, UPPER, LOWER), numeric,
        atol=1e-6 * np.pi / (UPPER - LOWER))


# ----------------------------------------------------------------------------
# Joint-space gradients
# ----------------------------------------------------------------------------

@pytest.mark.parametrize(("name", "chain", "lower", "upper"), CHAINS,
                         ids=CHAIN_IDS)
def test_jacobian_derivative_matches_finite_differences(name, chain, lower,
                                                        upper):
    rng = np.random.default_rng(10)
    for _ in range(5):
        q = rng.uniform(lower, upper)
        numeric = np.array([
            (jacobian(chain, q + 1e-6 * e) - jacobian(chain, q - 1e-6 * e))
            / 2e-6 for e in np.eye(len(q))
        ])
        np.testing.assert_allclose(cap.jacobian_derivative(
                                       jacobian(chain, q)),
                                   numeric, atol=1e-8)


@pytest.mark.parametrize(("name", "chain", "lower", "upper"), CHAINS,
                         ids=CHAIN_IDS)
def test_manipulability_gradient_matches_finite_differences(name, chain,
                                                            lower, upper):
    rng = np.random.default_rng(11)
    for _ in range(10):
        q = random_nonsingular_q(rng, chain, lower, upper)
        numeric = central_differences(
            lambda x, chain=chain: cap.manipulability(jacobian(chain, x)), q)
        analytic = cap.manipulability_joint_gradient(jacobian(chain, q))
        np.testing.assert_allclose(
            analytic, numeric, rtol=1e-6,
            atol=1e-6 * np.max(np.abs(numeric)))


def test_manipulability_gradient_at_and_near_singularities():
    # Stretched straight up: several zero singular values, m vanishes to
    # higher order, its gradient is 0.
    home = cap.manipulability_joint_gradient(jacobian(ELFIN5, np.zeros(6)))
    assert np.all(np.abs(home) < 1e-12)
    # Wrist singularity (q_5 = 0): one zero singular value, m ~ |g . d| along
    # any direction d, and the gradient is the limit of the gradients on
    # either side, up to sign.
    q = np.array([0.3, -0.7, 1.1, 0.4, 0.0, -0.5])
    g = cap.manipulability_joint_gradient(jacobian(ELFIN5, q))
    assert np.all(np.isfinite(g)) and np.linalg.norm(g) > 1e-2
    rng = np.random.default_rng(12)
    h = 1e-5
    for _ in range(5):
        d = rng.normal(size=6)
        m = [cap.manipulability(jacobian(ELFIN5, q + t * d))
             for t in (-h, 0.0, h)]
        np.testing.assert_allclose((m[0] + m[2] - 2.0 * m[1]) / (2.0 * h),
                                   abs(g @ d), rtol=1e-6)
    for side in (-1.0, 1.0):
        near = q.copy()
        near[4] = side * 1e-8
        g_near = cap.manipulability_joint_gradient(jacobian(ELFIN5, near))
        assert min(np.linalg.norm(g_near - g),
                   np.linalg.norm(g_near + g)) < 1e-6 * np.linalg.norm(g)


@pytest.mark.parametrize("body", [cap.capability_terms,
                                  cap.capability_terms_float])
def test_an_exact_singularity_gives_one_of_the_two_sides(body):
    """With one zero singular value the gradient has no side: each body
    returns the limit of the gradients on one side or the other (J_a +-
    delta u v^T), whichever its SVD's signs give (numpy 2.4's LAPACK and
    the compiled kernel's agreed on the random samples of
    tests/test_kernels.py, numpy 2.5's did not). C_m itself is 0 to
    rounding."""
    rng = np.random.default_rng(31)
    lower, upper = np.full(6, -3.0), np.full(6, 3.0)
    for _ in range(20):
        U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        V, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        s = np.concatenate([np.sort(rng.uniform(0.1, 1.5, 5))[::-1], [0.0]])
        J = (U * s) @ V.T
        q = rng.uniform(-2.5, 2.5, 6)
        damping, eps = 0.02, 0.1
        C_m, g = body(J, q, lower, upper, K_J, damping, eps)
        assert abs(C_m) < 1e-12
        sides = one_sided_gradients(J, q, lower, upper, K_J, damping, eps)
        assert np.linalg.norm(sides[0] - sides[1]) > 0.1 * np.linalg.norm(
            sides[0])
        assert is_one_of(g, sides)


def test_penalty_gradient_matches_finite_differences_inside():
    rng = np.random.default_rng(13)
    for _ in range(20):
        q = rng.uniform(ELFIN5_LOWER, ELFIN5_UPPER)
        numeric = central_differences(
            lambda x: penalty_by_loop(x, ELFIN5_LOWER, ELFIN5_UPPER, K_J), q)
        np.testing.assert_allclose(
            cap.joint_limit_penalty_gradient(q, ELFIN5_LOWER, ELFIN5_UPPER,
                                                  K_J),
            numeric, rtol=1e-6, atol=1e-9 * np.max(np.abs(numeric)))


@pytest.mark.parametrize("joint", range(6))
def test_gradients_with_a_joint_exactly_at_a_limit(joint):
    rng = np.random.default_rng(14 + joint)
    q = 0.6 * rng.uniform(ELFIN5_LOWER, ELFIN5_UPPER)
    q[4] = 1.0  # away from the wrist singularity
    for limit, inward in ((ELFIN5_LOWER, 1.0), (ELFIN5_UPPER, -1.0)):
        q[joint] = limit[joint]

        def penalty(x):
            return cap.joint_limit_penalty(x, ELFIN5_LOWER, ELFIN5_UPPER, K_J)

        def capability(x):
            return cap.capability(jacobian(ELFIN5, x), x, ELFIN5_LOWER,
                                  ELFIN5_UPPER, K_J)

        e = np.eye(6)[joint]
        for function, gradient in (
            (penalty, cap.joint_limit_penalty_gradient(
                q, ELFIN5_LOWER, ELFIN5_UPPER, K_J)),
            (capability, cap.capability_joint_gradient(
                jacobian(ELFIN5, q), q, ELFIN5_LOWER, ELFIN5_UPPER, K_J)),
        ):
            # The joint at its limit: derivative from inside, pointing in.
            slope = one_sided_difference(function, q, inward * e)
            assert inward * gradient[joint] > 0.0
            np.testing.assert_allclose(inward * gradient[joint], slope,
                                       rtol=1e-5)
            # The other joints: P stays 0 when they move.
            others = np.delete(np.arange(6), joint)
            np.testing.assert_allclose(gradient[others], 0.0, atol=1e-15)
            np.testing.assert_allclose(
                central_differences(function, q)[others], 0.0, atol=1e-15)


def test_penalty_gradient_beyond_a_limit_is_the_one_at_the_limit():
    q = 0.5 * (ELFIN5_LOWER + ELFIN5_UPPER)
    q[1] = ELFIN5_UPPER[1]
    at_limit = cap.joint_limit_penalty_gradient(q, ELFIN5_LOWER,
                                                     ELFIN5_UPPER, K_J)
    q[1] += 1e-3
    beyond = cap.joint_limit_penalty_gradient(q, ELFIN5_LOWER,
                                                   ELFIN5_UPPER, K_J)
    np.testing.assert_array_equal(beyond, at_limit)


@pytest.mark.parametrize(("name", "chain", "lower", "upper"), CHAINS,
                         ids=CHAIN_IDS)
def test_capability_joint_gradient_matches_finite_differences(name, chain,
                                                              lower, upper):
    rng = np.random.default_rng(15)

    def capability(x):
        return cap.capability(jacobian(chain, x), x, lower, upper, K_J)

    for _ in range(10):
        q = random_nonsingular_q(rng, chain, lower, upper)
        numeric = central_differences(capability, q)
        np.testing.assert_allclose(
            cap.capability_joint_gradient(jacobian(chain, q), q, lower,
                                               upper, K_J),
            numeric, rtol=1e-6, atol=1e-6 * np.max(np.abs(numeric)))


# ----------------------------------------------------------------------------
# Cartesian gradient
# ----------------------------------------------------------------------------

def test_capability_gradient_gives_the_rate_of_change_along_any_twist():
    rng = np.random.default_rng(16)
    for _, chain, lower, upper in CHAINS[:3]:  # square Jacobians
        for _ in range(10):
            q = random_nonsingular_q(rng, chain, lower, upper)
            J = jacobian(chain, q)
            g = cap.capability_gradient(J, q, lower, upper, K_J)
            V = rng.normal(size=6)
            qdot = np.linalg.solve(J, V)
            h = 1e-6
            rate = (cap.capability(jacobian(chain, q + h * qdot), q + h * qdot,
                                   lower, upper, K_J)
                    - cap.capability(jacobian(chain, q - h * qdot),
                                     q - h * qdot, lower, upper, K_J)
                    ) / (2.0 * h)
            scale = np.linalg.norm(g) * np.linalg.norm(V)
            assert g @ V == pytest.approx(rate, rel=1e-6, abs=1e-8 * scale)
            np.testing.assert_allclose(
                g, np.linalg.solve(
                    J.T, cap.capability_joint_gradient(J, q, lower, upper,
                                                            K_J)),
                rtol=1e-9, atol=1e-12 * np.linalg.norm(g))


def _near_constraints(rng, chain, lower, upper):
    """Configurations of `chain` near its constraints: near a joint limit
    (1e-3 rad inside it, each joint and each side in turn) and, for the
    Elfin5, near its wrist (q_5 -> 0) and elbow (q_3 -> 0) singularities,
    with s_min of J_a between 1.05 and 2 times the gradient's damping
    threshold (the undamped side, where grad_x C_m is exact)."""
    eps = cap.DEFAULT_DAMPING_THRESHOLD

    def drawn(joint, value, s_max):
        while True:
            q = random_nonsingular_q(rng, chain, 0.8 * lower, 0.8 * upper,
                                     s_min=0.1)
            q[joint] = value()
            s_min = np.linalg.svd(jacobian(chain, q), compute_uv=False)[-1]
            if 1.05 * eps < s_min < s_max:
                return q

    found = [drawn(joint, lambda j=joint, edge=edge, i=inward: edge[j]
                   + i * 1e-3, np.inf)
             for joint in range(len(lower))
             for edge, inward in ((lower, 1.0), (upper, -1.0))]
    if chain is ELFIN5:
        found += [drawn(joint, lambda: rng.choice([-1.0, 1.0])
                        * rng.uniform(0.05, 0.2), 2.0 * eps)
                  for joint in (4, 2)]
    return found


@pytest.mark.parametrize("body", [cap.capability_terms,
                                  cap.capability_terms_float],
                         ids=["reference", "kernel"])
@pytest.mark.parametrize(("name", "chain", "lower", "upper"),
                         [CHAINS[0], CHAINS[-1]], ids=[CHAIN_IDS[0],
                                                       CHAIN_IDS[-1]])
def test_capability_gradient_near_singularities_and_limits(body, name, chain,
                                                           lower, upper):
    """grad_x C_m (the null-space term of eq. (wbccm) and the direction of
    eq. (wb_error)) against central differences of C_m along arm twists V
    (qdot = J_a^+ V), where C_m changes fastest: 1e-3 rad from each joint
    limit, and near the Elfin5's singularities just outside the damping;
    the reference body and its kernel, on six and seven joints."""
    rng = np.random.default_rng(19)

    def capability(q):
        return cap.capability(jacobian(chain, q), q, lower, upper, K_J)

    for q in _near_constraints(rng, chain, lower, upper):
        J = np.ascontiguousarray(jacobian(chain, q))
        C_m, g = body(J, q, lower, upper, K_J, cap.DEFAULT_MAX_DAMPING,
                      cap.DEFAULT_DAMPING_THRESHOLD)
        assert C_m == pytest.approx(capability(q), rel=1e-12)
        for _ in range(3):
            V = rng.normal(size=6)
            qdot = np.linalg.pinv(J) @ V
            h = 1e-7
            rate = (capability(q + h * qdot) - capability(q - h * qdot)) / (
                2.0 * h)
            assert g @ V == pytest.approx(
                rate, rel=1e-5, abs=1e-6 * np.linalg.norm(g)
                * np.linalg.norm(V))


def test_capability_gradient_of_a_redundant_chain_is_least_squares():
    _, chain, lower, upper = CHAINS[-1]
    rng = np.random.default_rng(17)
    q = random_nonsingular_q(rng, chain, lower, upper)
    J = jacobian(chain, q)
    assert J.shape == (6, 7)
    dC = cap.capability_joint_gradient(J, q, lower, upper, K_J)
    expected = np.linalg.lstsq(J.T, dC, rcond=None)[0]
    np.testing.assert_allclose(
        cap.capability_gradient(J, q, lower, upper, K_J), expected,
        rtol=1e-9, atol=1e-12 * np.linalg.norm(expected))


def test_capability_gradient_damping_near_a_singularity():
    eps = cap.DEFAULT_DAMPING_THRESHOLD
    lam = cap.DEFAULT_MAX_DAMPING
    q = np.array([0.3, -0.7, 1.1, 0.4, 0.0, -0.5])
    for q5 in (0.0, 1e-3, 0.03, 0.08):  # s_min: 0, 3e-4, 0.01, 0.027
        q[4] = q5
        J = jacobian(ELFIN5, q)
        s_min = np.linalg.svd(J, compute_uv=False)[-1]
        lambda2 = lam**2 * (1.0 - (s_min / eps) ** 2) if s_min < eps else 0.0
        dC = cap.capability_joint_gradient(J, q, ELFIN5_LOWER,
                                                ELFIN5_UPPER, K_J)
        expected = np.linalg.solve(J @ J.T + lambda2 * np.eye(6), J @ dC)
        g = cap.capability_gradient(J, q, ELFIN5_LOWER, ELFIN5_UPPER, K_J)
        assert np.all(np.isfinite(g))
        np.testing.assert_allclose(g, expected, rtol=1e-8,
                                   atol=1e-10 * np.linalg.norm(expected))
        if q5 == 0.0:
            continue  # J_a^-T does not exist there
        # Without damping: the pseudo-inverse solution.
        undamped = cap.capability_gradient(J, q, ELFIN5_LOWER,
                                                ELFIN5_UPPER, K_J,
                                                damping=0.0)
        np.testing.assert_allclose(undamped, np.linalg.pinv(J.T) @ dC,
                                   rtol=1e-6, atol=1e-9)


def test_capability_gradient_is_continuous_across_the_damping_threshold():
    rng = np.random.default_rng(18)
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    q = np.zeros(6)
    lower, upper = -np.ones(6), np.ones(6)

    def gradient(s_min):
        J = U @ np.diag([2.0, 1.5, 1.0, 0.7, 0.4, s_min]) @ V.T
        return cap.capability_gradient(J, q, lower, upper, K_J,
                                            damping=0.05, damping_threshold=0.1)

    below, above = gradient(0.1 - 1e-9), gradient(0.1 + 1e-9)
    np.testing.assert_allclose(below, above, rtol=1e-6)


def test_jacobian_derivative_follows_the_cross_product_rules():
    rng = np.random.default_rng(5)
    J = rng.normal(size=(6, 7))
    Jv, Jw = J[:3].T, J[3:].T
    D = cap.jacobian_derivative(J)
    for i in range(7):
        for j in range(7):
            dv = (np.cross(Jw[i], Jv[j]) if i <= j
                  else np.cross(Jw[j], Jv[i]))
            dw = np.cross(Jw[i], Jw[j]) if i <= j else np.zeros(3)
            np.testing.assert_allclose(D[i][:, j], np.r_[dv, dw], rtol=0,
                                       atol=1e-15)


# ----------------------------------------------------------------------------
# The reference bodies for AutoDiffXd
# ----------------------------------------------------------------------------

def test_transition_for_autodiff():
    for v in (0.005, 0.012, 0.03, 0.045, 0.08):
        x = InitializeAutoDiff(np.array([v]))[0, 0]
        alpha = cap.transition_of(x, UPPER, LOWER)
        slope = cap.transition_derivative_of(x, UPPER, LOWER)
        assert alpha.value() == pytest.approx(cap.transition(v, UPPER,
                                                             LOWER))
        assert alpha.derivatives()[0] == pytest.approx(
            cap.transition_derivative(v, UPPER, LOWER), abs=1e-12)
        assert slope.value() == pytest.approx(
            cap.transition_derivative(v, UPPER, LOWER), abs=1e-12)


def test_capability_terms_for_autodiff():
    """The values are the float ones; the derivative w.r.t. q with J_a
    held is m dP_jnt/dq (exact), and w.r.t. every input it matches central
    differences."""
    rng = np.random.default_rng(20)
    q = random_nonsingular_q(rng, ELFIN5, ELFIN5_LOWER, ELFIN5_UPPER)
    J = jacobian(ELFIN5, q)
    args = (ELFIN5_LOWER, ELFIN5_UPPER, K_J, cap.DEFAULT_MAX_DAMPING,
            cap.DEFAULT_DAMPING_THRESHOLD)

    def terms(x):
        C_m, g = cap.capability_terms(x[:36].reshape(6, 6), x[36:],
                                                *args)
        return np.concatenate([[C_m], g])

    x0 = np.concatenate([J.ravel(), q])
    result = terms(InitializeAutoDiff(x0).ravel())
    np.testing.assert_array_equal(ExtractValue(result).ravel(), terms(x0))
    derivatives = ExtractGradient(result)
    np.testing.assert_allclose(
        derivatives[0, 36:],
        cap.manipulability(J) * cap.joint_limit_penalty_gradient(
            q, ELFIN5_LOWER, ELFIN5_UPPER, K_J), rtol=1e-12)
    numeric = np.stack([(terms(x0 + 1e-6 * e) - terms(x0 - 1e-6 * e)) / 2e-6
                        for e in np.eye(x0.size)], axis=1)
    np.testing.assert_allclose(derivatives, numeric, rtol=1e-6,
                               atol=1e-7 * np.abs(numeric).max())


# ----------------------------------------------------------------------------
# Bad input
# ----------------------------------------------------------------------------

J_OK = np.random.default_rng(19).normal(size=(6, 6))
Q_OK = np.zeros(6)


@pytest.mark.parametrize(("call", "name"), [
    (lambda: cap.manipulability(np.full((6, 6), np.nan)), "J_a"),
    (lambda: cap.manipulability(np.ones((7, 6))), "J_a"),
    (lambda: cap.manipulability(np.ones(6)), "J_a"),
    (lambda: cap.manipulability_joint_gradient(np.ones((5, 6))), "J_a"),
    (lambda: cap.jacobian_derivative(np.ones((6, 6, 1))), "J_a"),
    (lambda: cap.joint_limit_penalty([0.0, np.nan], [-1, -1], [1, 1], 1.0),
     "q"),
    (lambda: cap.joint_limit_penalty([0.0, np.inf], [-1, -1], [1, 1], 1.0),
     "q"),
    (lambda: cap.joint_limit_penalty([0.0, 0.0], [-1, np.nan], [1, 1], 1.0),
     "lower"),
    (lambda: cap.joint_limit_penalty([0.0, 0.0], [-1, -1], [1, 1, 1], 1.0),
     "upper"),
    (lambda: cap.joint_limit_penalty([0.0, 0.0], [-1, 1], [1, 1], 1.0),
     "lower"),
    (lambda: cap.joint_limit_penalty([0.0, 0.0], [-1, 2], [1, 1], 1.0),
     "upper"),
    (lambda: cap.joint_limit_penalty([0.0, 0.0], [-1, -1], [1, 1], 0.0),
     "k_j"),
    (lambda: cap.joint_limit_penalty_gradient([0.0], [-1], [1], -2.0),
     "k_j"),
    (lambda: cap.capability(J_OK, np.zeros(5), -np.ones(6), np.ones(6)),
     "q"),
    (lambda: cap.capability_joint_gradient(J_OK, Q_OK, -np.ones(6),
                                                np.ones(6), np.nan), "k_j"),
    (lambda: cap.capability_gradient(J_OK, Q_OK, -np.ones(6), np.ones(6),
                                          damping=-0.1), "damping"),
    (lambda: cap.capability_gradient(J_OK, Q_OK, -np.ones(6), np.ones(6),
                                          damping_threshold=0.0),
     "damping_threshold"),
    (lambda: cap.transition(0.5, 0.1, 0.2), "upper"),
    (lambda: cap.transition(0.5, 0.2, 0.2), "lower"),
    (lambda: cap.transition_derivative(0.5, 0.1, 0.2), "upper"),
    (lambda: cap.transition(np.nan, 0.2, 0.1), "value"),
    (lambda: cap.transition([0.1, np.inf], 0.2, 0.1), "value"),
    (lambda: cap.transition(0.1, np.nan, 0.1), "upper"),
])
def test_bad_input_raises_value_error_naming_the_argument(call, name):
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        call()
