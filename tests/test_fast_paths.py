"""The unchecked per-tick paths against the checked functions and against
independent formulations (the formulas as written), on random inputs: no
result may differ beyond rounding (1e-12 relative)."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE, relative_difference

from drake_wbc.math import capability, capability_gradients
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import ArmCapability


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def random_configurations(arm, count, seed):
    rng = np.random.default_rng(seed)
    middle, half = 0.5 * (arm.lower + arm.upper), 0.45 * (arm.upper - arm.lower)
    return [rng.uniform(middle - half, middle + half) for _ in range(count)]


# --- capability --------------------------------------------------------------

def manipulability_gradient_by_einsum(J):
    """dm/dq = sum_k (m / s_k) u_k^T (dJ/dq_i) v_k with the (n, 6, n)
    derivative of jacobian_derivative (the formula as written)."""
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    weights = np.array([np.prod(np.delete(s, k)) for k in range(s.size)])
    return np.einsum("k,rk,irc,kc->i", weights, U,
                     capability_gradients.jacobian_derivative(J), Vt)


def test_manipulability_gradient_matches_the_einsum_form():
    rng = np.random.default_rng(4)
    for n in (6, 7, 9):
        for _ in range(30):
            J = rng.normal(size=(6, n))
            assert relative_difference(
                capability_gradients.manipulability_joint_gradient(J),
                manipulability_gradient_by_einsum(J)) < RELATIVE


def test_jacobian_derivative_matches_np_cross_form():
    rng = np.random.default_rng(5)
    J = rng.normal(size=(6, 7))
    Jv, Jw = J[:3].T, J[3:].T
    D = capability_gradients.jacobian_derivative(J)
    for i in range(7):
        for j in range(7):
            dv = (np.cross(Jw[i], Jv[j]) if i <= j
                  else np.cross(Jw[j], Jv[i]))
            dw = np.cross(Jw[i], Jw[j]) if i <= j else np.zeros(3)
            np.testing.assert_array_equal(D[i][:, j], np.r_[dv, dw])


def test_products_of_others_is_exact_with_zeros():
    rng = np.random.default_rng(6)
    for size in (1, 2, 6, 7):
        v = rng.normal(size=size)
        v[rng.integers(size)] = 0.0
        expected = [np.prod(np.delete(v, k)) for k in range(size)]
        assert relative_difference(capability._products_of_others(v),
                                   expected) < RELATIVE
        assert np.count_nonzero(capability._products_of_others(v)) <= 1


def test_fused_capability_terms_match_the_public_functions(arm):
    rng = np.random.default_rng(7)
    for q in random_configurations(arm, 40, 8):
        J = arm.evaluate(q).J_a
        k_j, lam, eps = rng.uniform(5e3, 3e4), 0.02, rng.uniform(0.01, 0.2)
        C_m, g = capability_gradients.capability_terms_unchecked(
            J, q, arm.lower, arm.upper, k_j, lam, eps)
        assert abs(C_m - capability.capability(
            J, q, arm.lower, arm.upper, k_j)) <= RELATIVE * C_m
        assert relative_difference(g, capability_gradients.capability_gradient(
            J, q, arm.lower, arm.upper, k_j, lam, eps)) < RELATIVE
    for value in np.linspace(0.03, 0.045, 61):
        assert abs(capability.transition_unchecked(value, 0.04, 0.035)
                   - capability.transition(value, 0.04, 0.035)) < 1e-15


# --- the arm's kinematics ----------------------------------------------------

def test_remembered_kinematics_equal_fresh_ones(arm):
    fresh = ArmKinematics(arm.plant, arm.model)
    fresh.MEMO_SIZE = 1
    configurations = random_configurations(arm, 7, 9)
    for q in configurations * 3:  # more than MEMO_SIZE, and repeated
        a = arm.evaluate(q)
        fresh._memo.clear()
        b = fresh.evaluate(q)
        np.testing.assert_array_equal(a.J_a, b.J_a)
        np.testing.assert_array_equal(a.p_ee_in_base, b.p_ee_in_base)
        a.J_a[:] = np.nan  # the caller's copy: the remembered one stays
        frame = arm.model.ft_measurement_frame
        np.testing.assert_allclose(
            arm.frame_pose(q, frame).GetAsMatrix4(),
            frame.CalcPose(_context_at(arm, q), arm.model.arm_base_frame)
            .GetAsMatrix4(), rtol=0, atol=1e-15)


def _context_at(arm, q_a):
    context = arm.plant.CreateDefaultContext()
    q = arm.plant.GetPositions(context)
    q[arm._q_indices] = q_a
    arm.plant.SetPositions(context, q)
    return context


def test_p_ee_from_the_pose_matches_the_plant(arm):
    for q in random_configurations(arm, 10, 10):
        context = _context_at(arm, q)
        expected = arm.plant.CalcPointsPositions(
            context, arm.model.tcp_frame, np.zeros(3),
            arm.model.base_frame).ravel()
        assert np.max(np.abs(arm.evaluate(q).p_ee_in_base - expected)) < 1e-15


# --- the stages --------------------------------------------------------------

def test_arm_capability_stage_matches_the_public_functions(arm):
    stage = ArmCapability(None, arm)
    p = stage.params
    for q in random_configurations(arm, 10, 11):
        values = arm.evaluate(q)
        args = (values.J_a, q, arm.lower, arm.upper, p.joint_limit_gain)
        C_m = capability.capability(*args)
        expected = np.concatenate([
            values.p_ee_in_base, [C_m],
            capability_gradients.capability_gradient(
                *args, damping=p.gradient_damping,
                damping_threshold=p.gradient_damping_threshold),
            [capability.transition(C_m, p.band.upper, p.band.lower)]])
        assert relative_difference(stage.evaluate(q), expected) < RELATIVE




@pytest.mark.parametrize("acceleration", [None, 12.56])
def test_joint_velocity_for_twist_unchecked_matches_checked(acceleration):
    """Random twists, configurations near and beyond the joint limits and
    a singular Jacobian: the same command, bit for bit."""
    from drake_wbc.math import arm_control

    rng = np.random.default_rng(21)
    kinematics = ArmKinematics()
    lower, upper = kinematics.lower, kinematics.upper
    limits = kinematics.velocity_limits
    for trial in range(60):
        q = rng.uniform(lower - 0.02, upper + 0.02)
        J = kinematics.evaluate(q).J_a
        if trial % 10 == 0:
            J = J.copy()
            J[:, 4] = J[:, 3]  # rank deficient
        V = rng.normal(0.0, 0.5, 6)
        previous = rng.normal(0.0, 0.5, 6)
        checked = arm_control.joint_velocity_for_twist(
            J, V, q, lower, upper, limits, 0.01,
            acceleration_limit=acceleration, previous_q_dot=previous)
        fast = arm_control.joint_velocity_for_twist_unchecked(
            J, V, q, lower, upper, limits, 0.01,
            arm_control.DEFAULT_DAMPING,
            arm_control.DEFAULT_DAMPING_THRESHOLD,
            arm_control.DEFAULT_JOINT_LIMIT_MARGIN,
            None if acceleration is None else np.full(6, acceleration),
            None if acceleration is None else previous)
        np.testing.assert_array_equal(fast.q_dot, checked.q_dot)
        np.testing.assert_array_equal(fast.limited_joints,
                                      checked.limited_joints)
        assert (fast.scale, fast.acceleration_scale, fast.damping) == (
            checked.scale, checked.acceleration_scale, checked.damping)
