"""Tests of drake_wbc.math.capability_gradients against finite
differences of the independent serial-chain kinematics of
reference_kinematics (the Elfin5 table and random chains).
"""

import numpy as np
import pytest
from reference_kinematics import (
    ELFIN5,
    ELFIN5_LOWER,
    ELFIN5_UPPER,
    central_differences,
    chains_under_test,
    jacobian,
    one_sided_difference,
    penalty_by_loop,
    random_nonsingular_q,
)

from drake_wbc.math import capability as cap
from drake_wbc.math import capability_gradients as cap_grad

K_J = cap.DEFAULT_JOINT_LIMIT_GAIN
CHAINS = chains_under_test()
CHAIN_IDS = [name for name, *_ in CHAINS]


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
        np.testing.assert_allclose(cap_grad.jacobian_derivative(
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
        analytic = cap_grad.manipulability_joint_gradient(jacobian(chain, q))
        np.testing.assert_allclose(
            analytic, numeric, rtol=1e-6,
            atol=1e-6 * np.max(np.abs(numeric)))


def test_manipulability_gradient_at_and_near_singularities():
    # Stretched straight up: several zero singular values, m vanishes to
    # higher order, its gradient is 0.
    home = cap_grad.manipulability_joint_gradient(jacobian(ELFIN5, np.zeros(6)))
    assert np.all(np.abs(home) < 1e-12)
    # Wrist singularity (q_5 = 0): one zero singular value, m ~ |g . d| along
    # any direction d, and the gradient is the limit of the gradients on
    # either side, up to sign.
    q = np.array([0.3, -0.7, 1.1, 0.4, 0.0, -0.5])
    g = cap_grad.manipulability_joint_gradient(jacobian(ELFIN5, q))
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
        g_near = cap_grad.manipulability_joint_gradient(jacobian(ELFIN5, near))
        assert min(np.linalg.norm(g_near - g),
                   np.linalg.norm(g_near + g)) < 1e-6 * np.linalg.norm(g)


def test_penalty_gradient_matches_finite_differences_inside():
    rng = np.random.default_rng(13)
    for _ in range(20):
        q = rng.uniform(ELFIN5_LOWER, ELFIN5_UPPER)
        numeric = central_differences(
            lambda x: penalty_by_loop(x, ELFIN5_LOWER, ELFIN5_UPPER, K_J), q)
        np.testing.assert_allclose(
            cap_grad.joint_limit_penalty_gradient(q, ELFIN5_LOWER, ELFIN5_UPPER,
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
            (penalty, cap_grad.joint_limit_penalty_gradient(
                q, ELFIN5_LOWER, ELFIN5_UPPER, K_J)),
            (capability, cap_grad.capability_joint_gradient(
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
    at_limit = cap_grad.joint_limit_penalty_gradient(q, ELFIN5_LOWER,
                                                     ELFIN5_UPPER, K_J)
    q[1] += 1e-3
    beyond = cap_grad.joint_limit_penalty_gradient(q, ELFIN5_LOWER,
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
            cap_grad.capability_joint_gradient(jacobian(chain, q), q, lower,
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
            g = cap_grad.capability_gradient(J, q, lower, upper, K_J)
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
                    J.T, cap_grad.capability_joint_gradient(J, q, lower, upper,
                                                            K_J)),
                rtol=1e-9, atol=1e-12 * np.linalg.norm(g))


def test_capability_gradient_of_a_redundant_chain_is_least_squares():
    _, chain, lower, upper = CHAINS[-1]
    rng = np.random.default_rng(17)
    q = random_nonsingular_q(rng, chain, lower, upper)
    J = jacobian(chain, q)
    assert J.shape == (6, 7)
    dC = cap_grad.capability_joint_gradient(J, q, lower, upper, K_J)
    expected = np.linalg.lstsq(J.T, dC, rcond=None)[0]
    np.testing.assert_allclose(
        cap_grad.capability_gradient(J, q, lower, upper, K_J), expected,
        rtol=1e-9, atol=1e-12 * np.linalg.norm(expected))


def test_capability_gradient_damping_near_a_singularity():
    eps = cap_grad.DEFAULT_DAMPING_THRESHOLD
    lam = cap_grad.DEFAULT_MAX_DAMPING
    q = np.array([0.3, -0.7, 1.1, 0.4, 0.0, -0.5])
    for q5 in (0.0, 1e-3, 0.03, 0.08):  # s_min: 0, 3e-4, 0.01, 0.027
        q[4] = q5
        J = jacobian(ELFIN5, q)
        s_min = np.linalg.svd(J, compute_uv=False)[-1]
        lambda2 = lam**2 * (1.0 - (s_min / eps) ** 2) if s_min < eps else 0.0
        dC = cap_grad.capability_joint_gradient(J, q, ELFIN5_LOWER,
                                                ELFIN5_UPPER, K_J)
        expected = np.linalg.solve(J @ J.T + lambda2 * np.eye(6), J @ dC)
        g = cap_grad.capability_gradient(J, q, ELFIN5_LOWER, ELFIN5_UPPER, K_J)
        assert np.all(np.isfinite(g))
        np.testing.assert_allclose(g, expected, rtol=1e-8,
                                   atol=1e-10 * np.linalg.norm(expected))
        if q5 == 0.0:
            continue  # J_a^-T does not exist there
        # Without damping: the pseudo-inverse solution.
        undamped = cap_grad.capability_gradient(J, q, ELFIN5_LOWER,
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
        return cap_grad.capability_gradient(J, q, lower, upper, K_J,
                                            damping=0.05, damping_threshold=0.1)

    below, above = gradient(0.1 - 1e-9), gradient(0.1 + 1e-9)
    np.testing.assert_allclose(below, above, rtol=1e-6)
