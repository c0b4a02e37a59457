"""Tests of drake_wbc.math.capability's values (manipulability, joint-limit
penalty, C_m, transition) and its argument checks, against closed forms and
independent formulations.

Real arm Jacobians come from the independent serial-chain kinematics of
reference_kinematics: the Elfin5 table and random chains, to show nothing
is Elfin-specific.
"""

import numpy as np
import pytest
from reference_kinematics import (
    ELFIN5,
    ELFIN5_LOWER,
    ELFIN5_UPPER,
    chains_under_test,
    jacobian,
    jacobian_by_differences,
    penalty_by_loop,
    random_nonsingular_q,
)

from drake_wbc.math import capability as cap
from drake_wbc.math import capability_gradients as cap_grad

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
# Bad input
# ----------------------------------------------------------------------------

J_OK = np.random.default_rng(19).normal(size=(6, 6))
Q_OK = np.zeros(6)


@pytest.mark.parametrize(("call", "name"), [
    (lambda: cap.manipulability(np.full((6, 6), np.nan)), "J_a"),
    (lambda: cap.manipulability(np.ones((7, 6))), "J_a"),
    (lambda: cap.manipulability(np.ones(6)), "J_a"),
    (lambda: cap_grad.manipulability_joint_gradient(np.ones((5, 6))), "J_a"),
    (lambda: cap_grad.jacobian_derivative(np.ones((6, 6, 1))), "J_a"),
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
    (lambda: cap_grad.joint_limit_penalty_gradient([0.0], [-1], [1], -2.0),
     "k_j"),
    (lambda: cap.capability(J_OK, np.zeros(5), -np.ones(6), np.ones(6)),
     "q"),
    (lambda: cap_grad.capability_joint_gradient(J_OK, Q_OK, -np.ones(6),
                                                np.ones(6), np.nan), "k_j"),
    (lambda: cap_grad.capability_gradient(J_OK, Q_OK, -np.ones(6), np.ones(6),
                                          damping=-0.1), "damping"),
    (lambda: cap_grad.capability_gradient(J_OK, Q_OK, -np.ones(6), np.ones(6),
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
