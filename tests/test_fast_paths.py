"""The unchecked per-tick paths against the checked functions and against
independent formulations (the formulas as written), on random inputs: no
result may differ beyond rounding (1e-12 relative)."""

import numpy as np
import pytest

from drake_wbc.robot.model import ArmKinematics


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def random_configurations(arm, count, seed):
    rng = np.random.default_rng(seed)
    middle, half = 0.5 * (arm.lower + arm.upper), 0.45 * (arm.upper - arm.lower)
    return [rng.uniform(middle - half, middle + half) for _ in range(count)]




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
