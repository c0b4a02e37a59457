"""Tests of drake_wbc.math.compensation against closed forms (Sec. IV-A)."""

import numpy as np
import pytest
from reference_kinematics import random_rotation

from drake_wbc.math.compensation import (
    base_deviation,
    gradient_projector,
    robust_compensation,
)
from drake_wbc.math.distribution import distribute
from drake_wbc.math.kinematics import base_jacobian, whole_body_jacobian

N_CASES = 200


def required_compensation(dV_b, p, R):
    """delta_V_a^req written out: the arm twist in T_a that cancels the end
    effector's motion v = dv_b + dw_b x p, w = dw_b caused by the base
    deviation (T_b)."""
    dv = np.array([dV_b[0], dV_b[1], 0.0])
    dw = np.array([0.0, 0.0, dV_b[2]])
    return -np.concatenate([R.T @ (dv + np.cross(dw, p)), R.T @ dw])


def random_case(rng):
    p = rng.uniform(-1.5, 1.5, size=3)
    R = random_rotation(rng)
    return rng.normal(size=3), base_jacobian(p), R, rng.normal(size=6), p


def test_projector_matches_row_vector_formula():
    """P = g^T (g g^T)^-1 g with g a 1x6 row, as the paper writes it."""
    rng = np.random.default_rng(30)
    for _ in range(N_CASES):
        g = rng.normal(size=(1, 6)) * 10.0 ** rng.uniform(-6, 6)
        expected = g.T @ np.linalg.inv(g @ g.T) @ g
        np.testing.assert_allclose(
            gradient_projector(g[0]), expected, rtol=1e-12, atol=1e-14
        )


def test_projector_is_symmetric_idempotent_rank_one():
    rng = np.random.default_rng(31)
    for _ in range(N_CASES):
        g = rng.normal(size=6)
        P = gradient_projector(g)
        np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-15)
        np.testing.assert_allclose(P @ P, P, rtol=0, atol=1e-14)
        np.testing.assert_allclose(P @ g, g, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.trace(P), 1.0, atol=1e-14)
        orthogonal = rng.normal(size=6)
        orthogonal -= (orthogonal @ g) / (g @ g) * g
        np.testing.assert_allclose(P @ orthogonal, 0.0, atol=1e-14)


def test_zero_gradient_gives_zero_projector():
    np.testing.assert_array_equal(gradient_projector(np.zeros(6)), 0.0)
    np.testing.assert_array_equal(
        gradient_projector(np.full(6, 1e-14)), np.zeros((6, 6))
    )
    # A zero tolerance keeps any nonzero gradient.
    P = gradient_projector(np.full(6, 1e-14), tolerance=0.0)
    np.testing.assert_allclose(P, np.full((6, 6), 1.0 / 6.0), atol=1e-15)


def test_zero_gradient_leaves_full_compensation():
    rng = np.random.default_rng(32)
    dV_b, J_b, R, _, p = random_case(rng)
    dV_a_cmp, dV_ee = robust_compensation(dV_b, J_b, R, np.zeros(6), 1.0)
    np.testing.assert_allclose(
        dV_a_cmp, required_compensation(dV_b, p, R), atol=1e-12
    )
    np.testing.assert_array_equal(dV_ee, 0.0)


def test_alpha_zero_gives_the_required_compensation():
    rng = np.random.default_rng(33)
    for _ in range(N_CASES):
        dV_b, J_b, R, grad, p = random_case(rng)
        dV_a_cmp, dV_ee = robust_compensation(dV_b, J_b, R, grad, 0.0)
        np.testing.assert_allclose(
            dV_a_cmp, required_compensation(dV_b, p, R), rtol=0, atol=1e-12
        )
        np.testing.assert_array_equal(dV_ee, 0.0)


def test_alpha_zero_cancels_the_base_deviation_at_the_end_effector():
    """Whole-body identity from eq. (fk): R6 dV_a^cmp + J_b dV_b = 0."""
    rng = np.random.default_rng(34)
    for _ in range(N_CASES):
        dV_b, J_b, R, grad, _ = random_case(rng)
        dV_a_cmp, _ = robust_compensation(dV_b, J_b, R, grad, 0.0)
        arm = np.concatenate([R @ dV_a_cmp[:3], R @ dV_a_cmp[3:]])
        np.testing.assert_allclose(arm + J_b @ dV_b, 0.0, atol=1e-12)


def test_alpha_one_removes_the_gradient_component():
    rng = np.random.default_rng(35)
    for _ in range(N_CASES):
        dV_b, J_b, R, grad, p = random_case(rng)
        dV_a_cmp, _ = robust_compensation(dV_b, J_b, R, grad, 1.0)
        dV_a_req = required_compensation(dV_b, p, R)
        scale = np.linalg.norm(grad) * np.linalg.norm(dV_a_req)
        assert abs(grad @ dV_a_cmp) <= 1e-12 * scale
        # The rest of the compensation is untouched: what was removed is
        # parallel to the gradient.
        removed = dV_a_req - dV_a_cmp
        np.testing.assert_allclose(
            removed, (removed @ grad) / (grad @ grad) * grad, atol=1e-12
        )


def test_deviation_formulas_of_eq_deviation():
    rng = np.random.default_rng(36)
    for _ in range(N_CASES):
        dV_b, J_b, R, grad, p = random_case(rng)
        alpha = rng.uniform(0.0, 1.0)
        dV_a_cmp, dV_ee = robust_compensation(dV_b, J_b, R, grad, alpha)
        dV_a_req = required_compensation(dV_b, p, R)
        g = grad / np.linalg.norm(grad)
        R6 = np.kron(np.eye(2), R)
        # delta_V_ee is in T_b: the paper's T_a value turned by R_ba.
        np.testing.assert_allclose(
            dV_ee, -alpha * R6 @ g * (g @ dV_a_req), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            dV_ee, R6 @ (dV_a_cmp - dV_a_req), rtol=0, atol=1e-12
        )
        # What the end effector does of the compensated command, eq.
        # (fk) in T_b: R_ba dV_a^cmp + J_b dV_b, is the deviation.
        arm = np.concatenate([R @ dV_a_cmp[:3], R @ dV_a_cmp[3:]])
        np.testing.assert_allclose(arm + J_b @ dV_b, dV_ee, rtol=0,
                                   atol=1e-12)


def test_default_mounting_is_identity():
    rng = np.random.default_rng(37)
    dV_b, J_b, _, grad, _ = random_case(rng)
    for a, b in zip(
        robust_compensation(dV_b, J_b, None, grad, 0.4),
        robust_compensation(dV_b, J_b, np.eye(3), grad, 0.4),
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)


def test_base_deviation():
    np.testing.assert_array_equal(
        base_deviation([0.3, -0.1, 0.2], [0.5, 0.1, -0.2]), [-0.2, -0.2, 0.4]
    )


def test_filtered_base_with_full_compensation_keeps_the_reference():
    """Distribution, then any filtering of V_b, then compensation with
    alpha = 0: the commands actually sent, [V_a + dV_a^cmp; V_b^flt], still
    give the reference end-effector twist (eqs. (fk), (wbccm),
    (compensation))."""
    rng = np.random.default_rng(38)
    for _ in range(50):
        R, p = random_rotation(rng), rng.uniform(-1.5, 1.5, size=3)
        J_wb = whole_body_jacobian(None, p, R)
        V_ee = rng.normal(size=6)
        V_wb = distribute(J_wb, V_ee, *rng.uniform(0.0, 1.0, size=2))
        V_a, V_b = V_wb[:6], V_wb[6:]
        V_b_flt = V_b + rng.normal(size=3)
        dV_a_cmp, _ = robust_compensation(
            base_deviation(V_b_flt, V_b), base_jacobian(p), R,
            rng.normal(size=6), 0.0,
        )
        sent = np.concatenate([V_a + dV_a_cmp, V_b_flt])
        np.testing.assert_allclose(J_wb @ sent, V_ee, rtol=0, atol=1e-9)


GOOD = {
    "delta_V_b": np.array([0.1, -0.2, 0.3]),
    "J_b": base_jacobian([0.5, 0.2, 1.0]),
    "R_ba": np.eye(3),
    "grad_C_m": np.ones(6),
    "alpha": 0.5,
}


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("alpha", -0.1),
        ("alpha", 1.1),
        ("alpha", np.nan),
        ("R_ba", 2.0 * np.eye(3)),
        ("R_ba", np.diag([1.0, -1.0, 1.0])),
        ("R_ba", np.eye(2)),
        ("delta_V_b", [0.0, np.nan, 0.0]),
        ("delta_V_b", np.zeros(6)),
        ("J_b", np.zeros((6, 2))),
        ("J_b", np.full((6, 3), np.inf)),
        ("grad_C_m", np.zeros(3)),
        ("grad_C_m", [np.nan] * 6),
    ],
)
def test_robust_compensation_rejects_bad_input(name, value):
    with pytest.raises(ValueError, match=name):
        robust_compensation(**{**GOOD, name: value})


def test_gradient_projector_rejects_bad_input():
    with pytest.raises(ValueError, match="grad"):
        gradient_projector(np.ones(5))
    with pytest.raises(ValueError, match="grad"):
        gradient_projector([np.inf, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="tolerance"):
        gradient_projector(np.ones(6), tolerance=-1.0)


def test_base_deviation_rejects_bad_input():
    with pytest.raises(ValueError, match="V_b_filtered"):
        base_deviation([np.nan, 0.0, 0.0], np.zeros(3))
    with pytest.raises(ValueError, match="V_b"):
        base_deviation(np.zeros(3), np.zeros(2))
