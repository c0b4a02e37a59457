"""Tests of drake_wbc.math.kinematics against independent rigid-body
formulas."""

import numpy as np
import pytest
from reference_kinematics import random_rotation

from drake_wbc.math.kinematics import (
    base_jacobian,
    twist_rotation,
    whole_body_jacobian,
    world_to_base_twist,
)

N_CASES = 200


def rot_z(angle):
    """Rotation by `angle` about z, written out."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def end_effector_twist_from_base(V_b, p):
    """[v; w] of a point p rigidly attached to the base moving with V_b:
    v = v_b + w_b x p, w = w_b (all in T_b)."""
    v_b = np.array([V_b[0], V_b[1], 0.0])
    w_b = np.array([0.0, 0.0, V_b[2]])
    return np.concatenate([v_b + np.cross(w_b, p), w_b])


def test_base_jacobian_matches_rigid_body_velocity():
    rng = np.random.default_rng(1)
    for _ in range(N_CASES):
        p = rng.uniform(-2.0, 2.0, size=3)
        V_b = rng.normal(size=3)
        expected = end_effector_twist_from_base(V_b, p)
        np.testing.assert_allclose(
            base_jacobian(p) @ V_b, expected, rtol=0, atol=1e-12
        )


def test_base_jacobian_layout_and_unused_height():
    J_b = base_jacobian([0.7, -0.2, 0.4])
    expected = np.array([
        [1.0, 0.0, 0.2],
        [0.0, 1.0, 0.7],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
    ])
    np.testing.assert_array_equal(J_b, expected)
    np.testing.assert_array_equal(base_jacobian([0.7, -0.2, -3.0]), J_b)


def test_twist_rotation_rotates_both_parts():
    rng = np.random.default_rng(2)
    for _ in range(20):
        R = random_rotation(rng)
        V = rng.normal(size=6)
        expected = np.concatenate([R @ V[:3], R @ V[3:]])
        np.testing.assert_allclose(
            twist_rotation(R) @ V, expected, rtol=0, atol=1e-12
        )


def test_whole_body_jacobian_cartesian_arm_input():
    """Bottom line of eq. (fk): V_ee = R_ba V_a + J_b V_b, written out."""
    rng = np.random.default_rng(3)
    for _ in range(N_CASES):
        R = random_rotation(rng)
        p = rng.uniform(-2.0, 2.0, size=3)
        V_a, V_b = rng.normal(size=6), rng.normal(size=3)
        expected = end_effector_twist_from_base(V_b, p)
        expected[:3] += R @ V_a[:3]
        expected[3:] += R @ V_a[3:]
        J_wb = whole_body_jacobian(None, p, R)
        assert J_wb.shape == (6, 9)
        np.testing.assert_allclose(
            J_wb @ np.concatenate([V_a, V_b]), expected, rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            whole_body_jacobian(np.eye(6), p, R), J_wb, rtol=0, atol=0
        )


def test_whole_body_jacobian_default_mounting_is_identity():
    p = np.array([0.5, 0.3, 1.0])
    np.testing.assert_array_equal(
        whole_body_jacobian(None, p),
        whole_body_jacobian(None, p, np.eye(3)),
    )
    np.testing.assert_array_equal(
        whole_body_jacobian(None, p)[:, :6], np.eye(6)
    )


def test_whole_body_jacobian_with_joint_jacobian():
    """Top line of eq. (fk): the arm columns are R_ba J_a."""
    rng = np.random.default_rng(4)
    for _ in range(50):
        R = random_rotation(rng)
        J_a = rng.normal(size=(6, 6))
        p = rng.uniform(-2.0, 2.0, size=3)
        dq_a, V_b = rng.normal(size=6), rng.normal(size=3)
        arm_twist = J_a @ dq_a
        expected = end_effector_twist_from_base(V_b, p)
        expected[:3] += R @ arm_twist[:3]
        expected[3:] += R @ arm_twist[3:]
        J_wb = whole_body_jacobian(J_a, p, R)
        np.testing.assert_allclose(
            J_wb @ np.concatenate([dq_a, V_b]), expected, rtol=0, atol=1e-12
        )


def test_base_columns_match_finite_difference_of_world_motion():
    """The base moves with world-frame rates dq_b = [dx, dy, dphi] while the
    arm holds still; the end effector's world position is p_w = [x_b, y_b,
    0] + Rz(phi) ^b p_ee. Its finite-difference velocity, rotated into T_b
    with eq. (3), equals J_b V_b with V_b = ^bR_w dq_b (eq. (fk), top line).
    """
    rng = np.random.default_rng(5)
    dt = 1e-6
    for _ in range(20):
        x_b, y_b, phi = rng.uniform(-3.0, 3.0, size=3)
        dq_b = rng.normal(size=3)
        p_b = rng.uniform(-1.5, 1.5, size=3)

        def world_position(t, x_b=x_b, y_b=y_b, phi=phi, dq_b=dq_b, p_b=p_b):
            base = np.array([x_b + dq_b[0] * t, y_b + dq_b[1] * t, 0.0])
            return base + rot_z(phi + dq_b[2] * t) @ p_b

        v_world = (world_position(dt) - world_position(-dt)) / (2 * dt)
        w_world = np.array([0.0, 0.0, dq_b[2]])
        V_ee = world_to_base_twist(np.concatenate([v_world, w_world]), phi)
        V_b = rot_z(-phi) @ dq_b
        np.testing.assert_allclose(
            base_jacobian(p_b) @ V_b, V_ee, rtol=0, atol=1e-7
        )


def test_world_to_base_twist_matches_explicit_rotation():
    rng = np.random.default_rng(6)
    for _ in range(N_CASES):
        phi = rng.uniform(-2 * np.pi, 2 * np.pi)
        V_ref = rng.normal(size=6)
        R_wb = rot_z(phi)  # orientation of T_b in T_w
        V_ee = world_to_base_twist(V_ref, phi)
        np.testing.assert_allclose(R_wb @ V_ee[:3], V_ref[:3], atol=1e-12)
        np.testing.assert_allclose(R_wb @ V_ee[3:], V_ref[3:], atol=1e-12)


def test_world_to_base_twist_quarter_turn():
    """Base turned by +90 deg: its x axis is the world's y axis, so a world
    x velocity is a -y velocity in T_b, a world y velocity is +x."""
    V_ee = world_to_base_twist([1.0, 2.0, 3.0, 0.5, -0.25, 4.0], np.pi / 2)
    np.testing.assert_allclose(
        V_ee, [2.0, -1.0, 3.0, -0.25, -0.5, 4.0], rtol=0, atol=1e-15
    )


@pytest.mark.parametrize(
    "bad", [[np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [1.0, 2.0], np.zeros(4)]
)
def test_base_jacobian_rejects_bad_position(bad):
    with pytest.raises(ValueError, match="p_ee_in_base"):
        base_jacobian(bad)


NOT_ROTATIONS = [
    2.0 * np.eye(3),
    np.diag([1.0, 1.0, -1.0]),  # a reflection: orthogonal but det = -1
    np.ones((3, 3)),
    np.eye(4),
    np.full((3, 3), np.nan),
]


@pytest.mark.parametrize("bad", NOT_ROTATIONS)
def test_whole_body_jacobian_rejects_non_rotation(bad):
    with pytest.raises(ValueError, match="R_ba"):
        whole_body_jacobian(None, [0.5, 0.0, 1.0], bad)


@pytest.mark.parametrize("bad", NOT_ROTATIONS)
def test_twist_rotation_rejects_non_rotation(bad):
    with pytest.raises(ValueError, match=r"^R (=|has shape)"):
        twist_rotation(bad)


@pytest.mark.parametrize(
    "bad", [np.eye(5), np.ones((6, 7)), np.full((6, 6), np.nan)]
)
def test_whole_body_jacobian_rejects_bad_arm_jacobian(bad):
    with pytest.raises(ValueError, match="J_a"):
        whole_body_jacobian(bad, [0.5, 0.0, 1.0])


def test_whole_body_jacobian_rejects_bad_position():
    with pytest.raises(ValueError, match="p_ee_in_base"):
        whole_body_jacobian(None, [0.5, np.nan, 1.0])


def test_world_to_base_twist_rejects_bad_input():
    with pytest.raises(ValueError, match="V_ee_ref_world"):
        world_to_base_twist(np.zeros(5), 0.0)
    with pytest.raises(ValueError, match="V_ee_ref_world"):
        world_to_base_twist([0, 0, np.nan, 0, 0, 0], 0.0)
    with pytest.raises(ValueError, match="base_yaw"):
        world_to_base_twist(np.zeros(6), np.nan)
    with pytest.raises(ValueError, match="base_yaw"):
        world_to_base_twist(np.zeros(6), [0.1, 0.2])
