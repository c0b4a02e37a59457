"""The float fast paths of the arm's stages against the formulas as
written: the arm's Cartesian velocity controller (TwistSolver), through
its function and its Drake system, with limits active, degenerate inputs
and values that are not finite."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE, relative_difference
from pydrake.autodiffutils import AutoDiffXd, ExtractValue

from drake_wbc.math import arm_control, twist_solver
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import ArmCartesianVelocityController

H = 0.01


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


# --- the arm's Cartesian velocity controller -------------------------------

def bounds_as_written(q, lower, upper, h, margin, acceleration_limit):
    """joint_position_velocity_bounds vectorised, as its docstring and
    _braking_rate's state it."""
    distances = np.maximum(np.stack([upper - margin - q,
                                     q - lower - margin]), 0.0)
    rates = distances / h
    if acceleration_limit is not None:
        step = acceleration_limit * h
        D = distances / (step * h)
        r = 0.5 * (np.sqrt(1.0 + 8.0 * D) - 1.0)
        m = np.maximum(np.ceil(r) - 1.0, 0.0)
        f = np.clip(D / (m + 1.0) - 0.5 * m, 0.0, 1.0)
        rates = np.minimum(rates, (m + f) * step)
    return -rates[1], rates[0]


def twist_as_written(J, V, q, lower, upper, velocity_limit, h, lambda_max,
                     eps, margin, acceleration_limit, previous):
    """joint_velocity_for_twist's four stages as its docstrings state them,
    vectorised: damped least squares by the SVD, the position bounds
    (braking at the acceleration limit), uniform velocity scaling, uniform
    scaling of the change, the bounds again."""
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    s_min = float(s[-1])
    lam = 0.0 if s_min >= eps else lambda_max * (1.0 - (s_min / eps) ** 2)
    den = s**2 + lam**2
    gains = np.where(den > 0.0, s / np.where(den > 0.0, den, 1.0), 0.0)
    q_dot = Vt.T @ (gains * (U.T @ V))

    low, high = bounds_as_written(q, lower, upper, h, margin,
                                  acceleration_limit)

    def uniform(vector, limits):
        big = np.abs(vector) > limits
        return (float(np.min(limits[big] / np.abs(vector[big])))
                if big.any() else 1.0)

    bounded = np.clip(q_dot, low, high)
    limited = bounded != q_dot
    scale = uniform(bounded, velocity_limit)
    q_dot = scale * bounded
    acceleration_scale = 1.0
    if acceleration_limit is not None:
        change = q_dot - previous
        acceleration_scale = uniform(change, acceleration_limit * h)
        q_dot = previous + acceleration_scale * change
        bounded = np.clip(q_dot, low, high)
        limited |= bounded != q_dot
        q_dot = bounded
    return q_dot, scale, acceleration_scale, limited, lam, s_min


def twist_cases(arm, count, seed):
    """(J, V, q, previous): configurations inside, near and beyond the
    joint limits, near the wrist singularity and rank-deficient J, slow
    and fast twists, previous rates from rest to beyond the limits."""
    rng = np.random.default_rng(seed)
    for trial in range(count):
        q = rng.uniform(arm.lower - 0.02, arm.upper + 0.02)
        if trial % 4 == 1:  # next to an edge of the band
            i = rng.integers(6)
            edge = (arm.lower[i] if rng.uniform() < 0.5 else arm.upper[i])
            q[i] = edge + rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 0.3)
        if trial % 3 == 2:
            q[4] = rng.uniform(-0.1, 0.1)  # near the wrist singularity
        J = arm.evaluate(q).J_a
        if trial % 10 == 0:
            J = J.copy()
            J[:, 4] = J[:, 3]  # rank deficient
        V = rng.normal(0.0, rng.choice([1e-3, 0.05, 0.3, 3.0]), 6)
        previous = rng.normal(0.0, rng.choice([0.0, 0.3, 3.0]), 6)
        yield J, V, q, previous


@pytest.mark.parametrize("acceleration", [None, 12.56, 1.0])
@pytest.mark.parametrize("margin", [0.0, 0.05, 0.3])
def test_twist_solver_matches_the_stages_as_written(arm, acceleration,
                                                    margin):
    """The LU solve at regular points differs from the SVD by rounding;
    every flag and scale is the same."""
    limits = arm.velocity_limits
    a = None if acceleration is None else np.full(6, acceleration)
    damped = limited = 0
    for J, V, q, previous in twist_cases(arm, 150, seed=int(margin * 100)):
        expected = twist_as_written(
            J, V, q, arm.lower, arm.upper, limits, H,
            arm_control.DEFAULT_DAMPING,
            arm_control.DEFAULT_DAMPING_THRESHOLD, margin, a, previous)
        command = arm_control.joint_velocity_for_twist(
            J, V, q, arm.lower, arm.upper, limits, H, margin=margin,
            acceleration_limit=acceleration, previous_q_dot=previous)
        assert relative_difference(command.q_dot, expected[0]) < RELATIVE
        np.testing.assert_array_equal(command.limited_joints, expected[3])
        assert command.damping == pytest.approx(expected[4], rel=1e-12,
                                                abs=1e-15)
        assert command.smallest_singular_value == pytest.approx(
            expected[5], rel=1e-12, abs=1e-15)
        for fast, slow in zip(command[1:3], expected[1:3], strict=True):
            assert fast == pytest.approx(slow, rel=1e-12)
        damped += command.damped
        limited += command.limited
    assert damped > 10 and limited > 30  # both kinds were exercised


@pytest.mark.parametrize("acceleration", [None, 12.56])
def test_twist_solver_limits_are_bit_for_bit(arm, acceleration):
    """With damping everywhere (eps above every s_min) both take the same
    SVD, so the limits, applied joint by joint in floats and skipped where
    they cannot cut, give exactly the vectorised result."""
    a = None if acceleration is None else np.full(6, acceleration)
    eps = 10.0
    for J, V, q, previous in twist_cases(arm, 300, seed=3):
        expected = twist_as_written(J, V, q, arm.lower, arm.upper,
                                    arm.velocity_limits, H, 0.05, eps,
                                    0.05, a, previous)
        solver = twist_solver.TwistSolver(arm.lower, arm.upper,
                                          arm.velocity_limits, H, 0.05, eps,
                                          0.05, a)
        command = solver.solve(J, V, q, None if a is None else previous)
        np.testing.assert_array_equal(command.q_dot, expected[0])
        np.testing.assert_array_equal(command.limited_joints, expected[3])
        assert command[1:3] == expected[1:3]


@pytest.mark.parametrize("acceleration", [None, 12.56, 0.5])
def test_position_bounds_skip_only_where_they_cannot_cut(arm, acceleration):
    """Rates just below and above the velocity limit, at distances just
    inside and outside the distance beyond which the bound is skipped: the
    clipped rates equal the clip to the bounds as written, and
    joint_position_velocity_bounds gives those bounds bit for bit."""
    rng = np.random.default_rng(4)
    limits = arm.velocity_limits
    a = None if acceleration is None else np.full(6, acceleration)
    solver = twist_solver.TwistSolver(arm.lower, arm.upper, limits, H, 0.05,
                                      0.05, 0.05, a)
    clear = np.array(solver._clear)
    for _ in range(300):
        distance = clear * rng.choice([0.0, 0.5, 1.0 - 1e-9, 1.0, 1.0 + 1e-9,
                                       2.0], 6)
        towards_upper = rng.uniform(size=6) < 0.5
        q = np.where(towards_upper, arm.upper - 0.05 - distance,
                     arm.lower + 0.05 + distance)
        speed = limits * rng.choice([0.3, 1.0 - 1e-12, 1.0, 1.0 + 1e-12,
                                     3.0], 6)
        q_dot = np.where(towards_upper, speed, -speed)
        low, high = bounds_as_written(q, arm.lower, arm.upper, H, 0.05, a)
        np.testing.assert_array_equal(
            np.stack(arm_control.joint_position_velocity_bounds(
                q, arm.lower, arm.upper, H, 0.05, acceleration)),
            np.stack([low, high]))
        limited = [False] * 6
        bounded = solver._bounded(q_dot.tolist(), q.tolist(), limited, {})
        expected = np.clip(q_dot, low, high)
        np.testing.assert_array_equal(bounded, expected)
        np.testing.assert_array_equal(limited, expected != q_dot)
    # The bound at the skip distance is indeed at least the limit.
    for i in range(6):
        q = 0.5 * (arm.lower + arm.upper)
        q[i] = arm.upper[i] - 0.05 - clear[i]
        _, high = bounds_as_written(q, arm.lower, arm.upper, H, 0.05, a)
        q[i] = arm.lower[i] + 0.05 + clear[i]
        low, _ = bounds_as_written(q, arm.lower, arm.upper, H, 0.05, a)
        assert high[i] >= limits[i] and -low[i] >= limits[i]


def test_twist_solver_other_joint_counts(arm):
    """A (6, 7) Jacobian (no LU path) and a (6, 5) one: the same as the
    stages as written."""
    rng = np.random.default_rng(5)
    for n in (5, 7):
        lower, upper = -np.full(n, 2.0), np.full(n, 2.5)
        for _ in range(20):
            J, V = rng.normal(size=(6, n)), rng.normal(0.0, 0.3, 6)
            q, previous = rng.uniform(-2.1, 2.6, n), rng.normal(size=n)
            expected = twist_as_written(J, V, q, lower, upper,
                                        np.full(n, 1.5), H, 0.05, 0.05,
                                        0.05, np.full(n, 10.0), previous)
            command = arm_control.joint_velocity_for_twist(
                J, V, q, lower, upper, 1.5, H, acceleration_limit=10.0,
                previous_q_dot=previous)
            np.testing.assert_array_equal(command.q_dot, expected[0])


def controller_update(system, context, q, previous, V, hold=None):
    context.SetDiscreteState(np.concatenate([q, previous, [0.0]]))
    system.GetInputPort("arm_velocity").FixValue(context, V)
    if hold is not None:
        system.GetInputPort("hold").FixValue(context, [hold])
    return system.EvalUniquePeriodicDiscreteUpdate(context).get_vector(
    ).CopyToVector()


def test_controller_update_matches_the_stages_as_written(arm):
    system = ArmCartesianVelocityController(None, arm)
    context = system.CreateDefaultContext()
    a = np.full(6, arm_control.ELFIN5_ACCELERATION_LIMIT)
    for J, V, q, previous in twist_cases(arm, 120, seed=6):
        q = np.clip(q, arm.lower, arm.upper)
        J = arm.evaluate(q).J_a  # the controller's own J_a
        q_dot, scale, acc_scale, limited, _, _ = twist_as_written(
            J, V, q, arm.lower, arm.upper, arm.velocity_limits, H,
            arm_control.DEFAULT_DAMPING,
            arm_control.DEFAULT_DAMPING_THRESHOLD,
            arm_control.DEFAULT_JOINT_LIMIT_MARGIN, a, previous)
        state = controller_update(system, context, q, previous, V)
        assert relative_difference(state[6:12], q_dot) < RELATIVE
        expected_q = np.clip(q + H * q_dot, arm.lower, arm.upper)
        assert relative_difference(state[:6], expected_q) < RELATIVE
        assert np.all(state[:6] >= arm.lower)
        assert np.all(state[:6] <= arm.upper)
        assert state[12] == float(scale < 1.0 or acc_scale < 1.0
                                  or limited.any())
        np.testing.assert_array_equal(
            state, system.float_update(np.concatenate([q, previous, [0.0],
                                                       V])))


def test_controller_holds_on_hold_and_on_a_twist_that_is_not_finite(arm):
    system = ArmCartesianVelocityController(None, arm)
    context = system.CreateDefaultContext()
    q = 0.5 * (arm.lower + arm.upper) + 0.1
    previous = np.full(6, 0.2)
    for V, hold, flag in (([np.nan, 0, 0, 0, 0, 0], None, 1.0),
                          ([0, 0, np.inf, 0, 0, 0], 0.0, 1.0),
                          ([0.1, 0, 0, 0, 0, 0], 1.0, 0.0)):
        state = controller_update(system, context, q, previous,
                                  np.array(V, dtype=float), hold)
        np.testing.assert_array_equal(state, np.r_[q, np.zeros(6), flag])


def test_controller_autodiff_update_has_the_float_value(arm):
    system = ArmCartesianVelocityController(None, arm)
    converted = system.ToAutoDiffXd()
    for _, V, q, previous in twist_cases(arm, 4, seed=8):
        q = np.clip(q, arm.lower, arm.upper)
        expected = controller_update(system, system.CreateDefaultContext(),
                                     q, previous, V)
        context = converted.CreateDefaultContext()
        context.SetDiscreteState(np.concatenate([q, previous, [0.0]]))
        converted.GetInputPort("arm_velocity").FixValue(
            context, np.array([AutoDiffXd(v) for v in V], dtype=object))
        value = ExtractValue(converted.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector()).ravel()
        np.testing.assert_array_equal(value, expected)
