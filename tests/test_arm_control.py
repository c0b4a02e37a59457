"""The arm's Cartesian velocity controller: the math against closed forms
and brute force, the Drake system through its ports, its scalar conversion
and its linearisation."""

import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractValue, InitializeAutoDiff
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    FirstOrderTaylorApproximation,
    Linearize,
    LogVectorOutput,
)
from shipped_names import ARM_JOINTS, ROBOT_ACCELERATION_LIMIT

from drake_wbc.math.arm_control import (
    DEFAULT_DAMPING,
    DEFAULT_DAMPING_THRESHOLD,
    DEFAULT_JOINT_LIMIT_MARGIN,
    ArmControllerParameters,
    damped_least_squares,
    joint_position_velocity_bounds,
    joint_velocity_for_twist,
    singularity_damping,
)
from drake_wbc.math.capability import jacobian_derivative
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    ArmKinematics,
    arm_kinematics,
)
from drake_wbc.stages import ArmCartesianVelocityController

H = 0.01
VELOCITY_LIMIT = 1.57
ACCELERATION_LIMIT = 12.56


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def jacobian(arm, q):
    return arm.evaluate(q).J_a


def regular_configuration(arm, rng):
    """A configuration near home with s_min of J_a well above the damping
    threshold and every joint far from its limits."""
    while True:
        q = HOME_ARM_POSITIONS + rng.uniform(-0.3, 0.3, 6)
        s = np.linalg.svd(jacobian(arm, q), compute_uv=False)
        if s[-1] > 2 * DEFAULT_DAMPING_THRESHOLD:
            return q


def unlimited(J_a, V_a, q, **kwargs):
    """joint_velocity_for_twist with limits too far away to act."""
    kwargs.setdefault("margin", 0.0)
    return joint_velocity_for_twist(J_a, V_a, q, q - 1e3, q + 1e3, 1e9, H,
                                    **kwargs)


def parallel(a, b):
    return abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b))


# --- the math ---------------------------------------------------------


@pytest.mark.parametrize("seed", range(5))
def test_regular_point_without_damping_is_the_inverse(arm, seed):
    rng = np.random.default_rng(seed)
    q = regular_configuration(arm, rng)
    J = jacobian(arm, q)
    V = rng.normal(size=6) * 0.05
    exact = np.linalg.solve(J, V)
    for damping in (0.0, DEFAULT_DAMPING):  # the rule gives lambda = 0 here
        result = joint_velocity_for_twist(J, V, q, arm.lower, arm.upper,
                                          VELOCITY_LIMIT, H, damping=damping)
        np.testing.assert_allclose(result.q_dot, exact, rtol=1e-10,
                                   atol=1e-14)
        assert not result.damped and not result.limited
        assert result.scale == 1.0 and result.acceleration_scale == 1.0


@pytest.mark.parametrize("columns", [6, 7])
def test_damped_solution_is_the_dls_closed_form(columns):
    rng = np.random.default_rng(10 + columns)
    J = rng.normal(size=(6, columns))
    V = rng.normal(size=6)
    for lam in (0.0, 0.05, 0.3):
        closed = J.T @ np.linalg.solve(J @ J.T + lam**2 * np.eye(6), V)
        np.testing.assert_allclose(damped_least_squares(J, V, lam), closed,
                                   rtol=1e-10)
    # The rule: with eps above every singular value, damping always acts.
    eps, lambda_max = 10.0, 0.4
    s_min = np.linalg.svd(J, compute_uv=False).min()
    lam = lambda_max * (1 - (s_min / eps) ** 2)
    closed = J.T @ np.linalg.solve(J @ J.T + lam**2 * np.eye(6), V)
    result = unlimited(J, V, np.zeros(columns), damping=lambda_max,
                       damping_threshold=eps)
    assert result.damped and result.damping == pytest.approx(lam)
    np.testing.assert_allclose(result.q_dot, closed, rtol=1e-10)


def test_singularity_damping_rule_is_smooth_and_bounded():
    eps, lambda_max = DEFAULT_DAMPING_THRESHOLD, DEFAULT_DAMPING
    assert singularity_damping(0.0) == lambda_max
    assert singularity_damping(eps) == 0.0
    assert singularity_damping(2 * eps) == 0.0
    s = np.linspace(0.0, 2 * eps, 4001)
    lam = np.array([singularity_damping(x) for x in s])
    np.testing.assert_allclose(
        lam**2, np.where(s < eps, lambda_max**2 * (1 - (s / eps) ** 2) ** 2,
                         0.0), atol=1e-15)
    # lambda^2, all the solve uses, is C1: its slope tends to 0 at eps
    # from below as it is 0 above (lambda itself has a kink there).
    for delta in (1e-3 * eps, 1e-6 * eps):
        left = (0.0 - singularity_damping(eps - delta) ** 2) / delta
        assert abs(left) < 10 * delta * lambda_max**2 / eps**2
    assert (singularity_damping(0.5 * eps) ** 2 - lambda_max**2 * 0.75**2
            ) == pytest.approx(0.0, abs=1e-18)
    # The gain of a direction with singular value s never exceeds 1.07/eps.
    gain = s / (s**2 + lam**2)
    assert gain.max() < 1.07 / eps
    assert gain.max() > 1.06 / eps


@pytest.mark.parametrize("joint", [4, 2])  # q5 -> 0 (wrist), q3 -> 0 (elbow)
def test_near_a_singularity_the_rates_stay_bounded(arm, joint):
    rng = np.random.default_rng(20 + joint)
    V = rng.normal(size=6)
    V *= 0.05 / np.linalg.norm(V)
    bound = 1.07 / DEFAULT_DAMPING_THRESHOLD * np.linalg.norm(V)
    for distance in (1e-2, 1e-4, 1e-8, 0.0):
        q = HOME_ARM_POSITIONS.copy()
        q[joint] = distance
        J = jacobian(arm, q)
        result = unlimited(J, V, q)
        assert np.all(np.isfinite(result.q_dot))
        assert result.damped
        assert np.linalg.norm(result.q_dot) <= bound
        if distance > 0:  # without damping the same twist explodes
            undamped = unlimited(J, V, q, damping=0.0).q_dot
            assert np.linalg.norm(undamped) > 2 * bound
    # With the real limits the result obeys them too.
    limited = joint_velocity_for_twist(J, V * 20, q, arm.lower, arm.upper,
                                       VELOCITY_LIMIT, H)
    assert np.abs(limited.q_dot).max() <= VELOCITY_LIMIT * (1 + 1e-12)


def test_uniform_scaling_keeps_the_direction(arm):
    rng = np.random.default_rng(30)
    q = regular_configuration(arm, rng)
    J = jacobian(arm, q)
    V = np.array([0.8, -0.5, 0.3, 1.0, -0.7, 0.4])
    limits = np.array([1.57, 1.57, 1.57, 2.0, 2.5, 3.0])
    free = unlimited(J, V, q).q_dot
    assert np.sum(np.abs(free) > limits) >= 2  # several joints too fast
    result = joint_velocity_for_twist(J, V, q, q - 1e3, q + 1e3, limits, H,
                                      margin=0.0)
    assert result.scale < 1.0 and result.limited
    assert parallel(result.q_dot, free) == pytest.approx(1.0, abs=1e-14)
    np.testing.assert_allclose(result.q_dot, result.scale * free, rtol=1e-14)
    assert np.abs(result.q_dot / limits).max() == pytest.approx(1.0)
    # The end effector keeps its direction of motion: J q_dot = scale V.
    np.testing.assert_allclose(J @ result.q_dot, result.scale * V,
                               atol=1e-12)
    # Clipping each joint instead would turn the motion.
    assert parallel(np.clip(free, -limits, limits), free) < 0.999


@pytest.mark.parametrize("joint", range(6))
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_joint_at_its_limit_is_never_commanded_further(arm, joint, side):
    q = HOME_ARM_POSITIONS.copy()
    J = jacobian(arm, q)
    V = side * J[:, joint] * 0.5  # the twist of that joint turning outwards
    margin = DEFAULT_JOINT_LIMIT_MARGIN
    for beyond in (-0.003, 0.0, margin, margin + 0.01):
        # The limit placed `beyond` past the edge of the band from q.
        limit = q[joint] + side * (margin - beyond)
        lower, upper = q - 3.0, q + 3.0
        if side > 0:
            upper[joint] = limit
        else:
            lower[joint] = limit
        result = joint_velocity_for_twist(J, V, q, lower, upper,
                                          VELOCITY_LIMIT, H)
        step = q[joint] + H * result.q_dot[joint]
        if beyond > 0:  # beyond the band's edge: no further out
            assert side * result.q_dot[joint] <= 0.0
        elif beyond == 0:  # at the edge, to the rounding of the limits
            assert side * result.q_dot[joint] <= 1e-12
        else:  # approaching: stops exactly at the edge
            edge = limit - side * margin
            assert side * (step - edge) <= 1e-15
            assert step == pytest.approx(edge, abs=1e-15)
        assert result.limited_joints[joint] and result.limited


def braking_rate_by_summation(distance, h, a):
    """The largest v whose full-deceleration stop v, v - a h, ..., covers
    at most `distance` (each rate held for h), by bisection."""

    def stopping_distance(v):
        total = 0.0
        while v > 0:
            total += v * h
            v -= a * h
        return total

    lo, hi = 0.0, 100.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stopping_distance(mid) <= distance else (lo, mid)
    return lo


@pytest.mark.parametrize("distance", [0.0, 4e-4, 1.256e-3, 3e-3, 0.0123,
                                      0.1, 0.35])
def test_braking_bound_by_brute_force(distance):
    upper = 1.0
    q = np.array([upper - distance])
    low, high = joint_position_velocity_bounds(
        q, [-1.0], [upper], H, margin=0.0,
        acceleration_limit=ACCELERATION_LIMIT)
    expected = braking_rate_by_summation(distance, H, ACCELERATION_LIMIT)
    assert high[0] == pytest.approx(expected, abs=1e-9)
    assert low[0] <= 0.0
    # Without an acceleration limit only the next step counts.
    assert joint_position_velocity_bounds(q, [-1.0], [upper], H, 0.0)[1][
        0] == pytest.approx(distance / H)


def test_acceleration_limit_scales_the_change(arm):
    rng = np.random.default_rng(40)
    q = regular_configuration(arm, rng)
    J = jacobian(arm, q)
    V = np.array([0.05, 0.02, -0.03, 0.1, 0.0, 0.05])
    previous = rng.normal(size=6) * 0.1
    free = unlimited(J, V, q).q_dot
    result = joint_velocity_for_twist(
        J, V, q, arm.lower, arm.upper, VELOCITY_LIMIT, H,
        acceleration_limit=ACCELERATION_LIMIT, previous_q_dot=previous)
    change = result.q_dot - previous
    assert result.acceleration_scale < 1.0 and result.limited
    assert np.abs(change).max() == pytest.approx(ACCELERATION_LIMIT * H)
    assert parallel(change, free - previous) == pytest.approx(1.0, abs=1e-12)
    # Starting from the desired rate nothing changes.
    again = joint_velocity_for_twist(
        J, V, q, arm.lower, arm.upper, VELOCITY_LIMIT, H,
        acceleration_limit=ACCELERATION_LIMIT, previous_q_dot=free)
    np.testing.assert_allclose(again.q_dot, free, rtol=1e-12)
    assert again.acceleration_scale == 1.0 and not again.limited


@pytest.mark.parametrize("seed", [None, 0, 1, 2])
def test_stepping_into_limits_keeps_every_limit(arm, seed):
    """Integrating the command against a strong twist (None: the tool
    pushed straight down at 0.3 m/s, which ends with the shoulder at its
    lower limit; else random): positions stay in the band and rates change
    by at most a h every step, also while braking at a joint limit or
    passing near a singularity."""
    if seed is None:
        V = np.array([0.0, 0.0, -0.3, 0.0, 0.0, 0.0])
    else:
        rng = np.random.default_rng(50 + seed)
        V = np.concatenate([rng.normal(size=3) * 0.3, rng.normal(size=3)])
    q, q_dot = HOME_ARM_POSITIONS.copy(), np.zeros(6)
    margin = DEFAULT_JOINT_LIMIT_MARGIN
    braked = 0
    for _ in range(400):
        result = joint_velocity_for_twist(
            jacobian(arm, q), V, q, arm.lower, arm.upper, VELOCITY_LIMIT, H,
            acceleration_limit=ACCELERATION_LIMIT, previous_q_dot=q_dot)
        assert np.abs(result.q_dot - q_dot).max() <= (
            ACCELERATION_LIMIT * H * (1 + 1e-9))
        assert np.abs(result.q_dot).max() <= VELOCITY_LIMIT * (1 + 1e-12)
        braked += bool(result.limited_joints.any())
        q_dot = result.q_dot
        q = q + H * q_dot
        assert np.all(q <= arm.upper - margin + 1e-12)
        assert np.all(q >= arm.lower + margin - 1e-12)
    if seed is None:  # the shoulder really ran into its limit
        assert braked > 0
        assert q[1] == pytest.approx(arm.lower[1] + margin, abs=1e-12)


# --- against the four stages as written ------------------------------


def bounds_as_written(q, lower, upper, h, margin, acceleration_limit):
    """joint_position_velocity_bounds vectorised, as its docstring and
    braking_rate's state it."""
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


def relative_difference(a, b):
    """max |a - b| over max |b| (b the formula as written)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


ROUNDING = 1e-12
"""The relative difference allowed between two formulations."""


@pytest.mark.parametrize("acceleration", [None, 12.56, 1.0])
@pytest.mark.parametrize("margin", [0.0, 0.05, 0.3])
def test_the_command_is_the_four_stages_as_written(arm, acceleration,
                                                   margin):
    """The damped solve by the normal equations against the SVD's gains:
    the same command to rounding, every flag and scale the same."""
    limits = arm.velocity_limits
    a = None if acceleration is None else np.full(6, acceleration)
    damped = limited = 0
    for J, V, q, previous in twist_cases(arm, 150, seed=int(margin * 100)):
        expected = twist_as_written(
            J, V, q, arm.lower, arm.upper, limits, H, DEFAULT_DAMPING,
            DEFAULT_DAMPING_THRESHOLD, margin, a, previous)
        command = joint_velocity_for_twist(
            J, V, q, arm.lower, arm.upper, limits, H, margin=margin,
            acceleration_limit=acceleration, previous_q_dot=previous)
        assert relative_difference(command.q_dot, expected[0]) < ROUNDING
        np.testing.assert_array_equal(command.limited_joints, expected[3])
        assert command.damping == pytest.approx(expected[4], rel=1e-12,
                                                abs=1e-15)
        assert command.smallest_singular_value == pytest.approx(
            expected[5], rel=1e-12, abs=1e-15)
        for value, written in zip(command[1:3], expected[1:3], strict=True):
            assert value == pytest.approx(written, rel=1e-12)
        damped += command.damped
        limited += command.limited
    assert damped > 10 and limited > 30  # both kinds were exercised


def test_other_joint_counts_as_written():
    """A (6, 7) Jacobian and a (6, 5) one (a redundant and a deficient
    arm): the same as the stages as written."""
    rng = np.random.default_rng(5)
    for n in (5, 7):
        lower, upper = -np.full(n, 2.0), np.full(n, 2.5)
        for _ in range(20):
            J, V = rng.normal(size=(6, n)), rng.normal(0.0, 0.3, 6)
            q, previous = rng.uniform(-2.1, 2.6, n), rng.normal(size=n)
            expected = twist_as_written(J, V, q, lower, upper,
                                        np.full(n, 1.5), H, 0.05, 0.05,
                                        0.05, np.full(n, 10.0), previous)
            command = joint_velocity_for_twist(
                J, V, q, lower, upper, 1.5, H, acceleration_limit=10.0,
                previous_q_dot=previous)
            assert relative_difference(command.q_dot, expected[0]) < (
                ROUNDING)


@pytest.mark.parametrize("acceleration", [None, 12.56, 0.5])
def test_the_bounds_are_as_written(arm, acceleration):
    rng = np.random.default_rng(4)
    a = None if acceleration is None else np.full(6, acceleration)
    for _ in range(300):
        q = rng.uniform(arm.lower - 0.1, arm.upper + 0.1)
        np.testing.assert_allclose(
            np.stack(joint_position_velocity_bounds(
                q, arm.lower, arm.upper, H, 0.05, acceleration)),
            np.stack(bounds_as_written(q, arm.lower, arm.upper, H, 0.05,
                                       a)), rtol=1e-14, atol=1e-14)


def controller_update(system, context, q, previous, V, hold=None):
    context.SetDiscreteState(np.concatenate([q, previous, [0.0]]))
    system.GetInputPort("arm_velocity").FixValue(context, V)
    if hold is not None:
        system.GetInputPort("hold").FixValue(context, [hold])
    return system.EvalUniquePeriodicDiscreteUpdate(context).get_vector(
    ).CopyToVector()


SEVEN_JOINTS = (Path(__file__).resolve().parent.parent / "models"
                / "lbr_omni.robot.yaml")


def test_a_hold_stops_a_redundant_arms_self_motion():
    """On a seven-joint arm away from the middles of its joints, the
    self-motion moves the command with no twist asked; a hold (a safe
    stop) brakes it to rest and it stays there: the joint centring must
    not go on moving a stopped robot (it did, at 0.02 rad/s)."""
    arm = arm_kinematics(load_robot_description(SEVEN_JOINTS))
    start = np.asarray(arm.home) + 0.3
    commands = {}
    for hold in (0.0, 1.0):
        system = ArmCartesianVelocityController(None, arm)
        context = system.CreateDefaultContext()
        system.GetInputPort("arm_velocity").FixValue(context, np.zeros(6))
        system.GetInputPort("hold").FixValue(context, [hold])
        system.set_arm_position(context, start)
        Simulator(system, context).AdvanceTo(2.0)
        commands[hold] = (
            system.GetOutputPort("arm_position_command").Eval(context),
            system.GetOutputPort("arm_velocity_command").Eval(context))
    moving, _ = commands[0.0]
    held, rate = commands[1.0]
    assert np.abs(moving - start).max() > 0.01
    np.testing.assert_array_equal(held, start)
    np.testing.assert_array_equal(rate, 0.0)


def test_controller_update_is_the_stages_as_written(arm):
    system = ArmCartesianVelocityController(None, arm)
    context = system.CreateDefaultContext()
    a = np.full(6, ROBOT_ACCELERATION_LIMIT)
    for J, V, q, previous in twist_cases(arm, 120, seed=6):
        q = np.clip(q, arm.lower, arm.upper)
        J = arm.evaluate(q).J_a  # the controller's own J_a
        q_dot, scale, acc_scale, limited, _, _ = twist_as_written(
            J, V, q, arm.lower, arm.upper, arm.velocity_limits, H,
            DEFAULT_DAMPING, DEFAULT_DAMPING_THRESHOLD,
            DEFAULT_JOINT_LIMIT_MARGIN, a, previous)
        state = controller_update(system, context, q, previous, V)
        assert relative_difference(state[6:12], q_dot) < ROUNDING
        expected_q = np.clip(q + H * q_dot, arm.lower, arm.upper)
        assert relative_difference(state[:6], expected_q) < ROUNDING
        assert np.all(state[:6] >= arm.lower)
        assert np.all(state[:6] <= arm.upper)
        assert state[12] == float(scale < 1.0 or acc_scale < 1.0
                                  or limited.any())


def test_controller_brakes_on_hold_and_on_a_twist_that_is_not_finite(arm):
    """A hold (or a twist that is not finite) brakes the command to rest
    within the acceleration limit, along its direction, then holds it;
    without an acceleration limit it stops at once."""
    system = ArmCartesianVelocityController(None, arm)
    context = system.CreateDefaultContext()
    q0 = 0.5 * (arm.lower + arm.upper) + 0.1
    previous = np.array([1.5, -1.2, 0.8, 0.3, -0.1, 0.0])
    step = ROBOT_ACCELERATION_LIMIT * H
    for V, hold, flag in (([np.nan, 0, 0, 0, 0, 0], None, 1.0),
                          ([0, 0, np.inf, 0, 0, 0], 0.0, 1.0),
                          ([0.1, 0, 0, 0, 0, 0], 1.0, None)):
        q, rate = q0, previous
        for _ in range(20):
            state = controller_update(system, context, q, rate,
                                      np.array(V, dtype=float), hold)
            change = state[6:12] - rate
            assert np.abs(change).max() <= step * (1 + 1e-12)
            np.testing.assert_allclose(  # along the last direction
                state[6:12], rate * (1.0 - min(1.0, step / np.abs(
                    rate).max())) if rate.any() else 0.0, atol=1e-15)
            np.testing.assert_allclose(state[:6], q + H * state[6:12],
                                       rtol=1e-15)
            # Limited while the acceleration limit cuts the braking.
            assert state[12] == (flag if flag is not None else float(
                np.abs(rate).max() > step))
            q, rate = state[:6], state[6:12]
        np.testing.assert_array_equal(rate, 0.0)  # at rest, 0.12 s later
        # Braking as a whole took v_max / a (+ a tick): joint i ran
        # |v_i| (v_max / (2 a) + h) at most.
        stop_time = np.abs(previous).max() / ROBOT_ACCELERATION_LIMIT
        assert np.all(np.abs(q - q0) <= np.abs(previous) * (
            0.5 * stop_time + H) + 1e-12)
    at_once = ArmCartesianVelocityController(
        ArmControllerParameters(use_acceleration_limit=False), arm)
    state = controller_update(at_once, at_once.CreateDefaultContext(), q0,
                              previous, np.full(6, 0.1), 1.0)
    np.testing.assert_array_equal(state, np.r_[q0, np.zeros(6), 0.0])


def resumed_update(system, context, q, previous, V, measured, resume,
                   hold=0.0):
    system.GetInputPort("arm_position").FixValue(context, measured)
    system.GetInputPort("resume").FixValue(context, [resume])
    return controller_update(system, context, q, previous, V, hold)


def test_a_resume_restarts_from_where_the_arm_is(arm):
    """At the update that ends a safe stop (`resume`), an arm measured
    farther than the tolerance from q_cmd restarts the command from the
    measurement, at rest: the update is the one from there with no
    previous rate, its step within the acceleration limit. Within the
    tolerance, or without resume, or beyond a joint's limits (by more than
    an encoder at the limit reads), the measurement changes nothing, bit
    for bit; with hold (a protective stop that outlasts the safe stop)
    the command restarts there and stays; the AutoDiff system takes the
    same branch."""
    system = ArmCartesianVelocityController(None, arm)
    assert system.resume_tolerance == 0.1
    q = 0.5 * (arm.lower + arm.upper) + 0.1
    previous = np.array([0.05, -0.04, 0.03, 0.0, 0.0, 0.0])
    V = np.array([0.1, 0.0, 0.05, 0.0, 0.2, 0.0])
    away = q + np.array([0.0, 0.15, 0.0, -0.3, 0.0, 0.0])

    def update(*args, **kwargs):
        return resumed_update(system, system.CreateDefaultContext(), *args,
                              **kwargs)

    plain = controller_update(system, system.CreateDefaultContext(), q,
                              previous, V)
    near = q + np.array([0.0, 0.0999, 0.0, -0.0999, 0.0, 0.0])
    np.testing.assert_array_equal(update(q, previous, V, near, 1.0), plain)
    np.testing.assert_array_equal(update(q, previous, V, away, 0.0), plain)
    np.testing.assert_array_equal(update(q, previous, V, away, 1.0, 1.0),
                                  np.r_[away, np.zeros(6), 0.0])
    state = update(q, previous, V, away, 1.0)
    from_there = controller_update(system, system.CreateDefaultContext(),
                                   away, np.zeros(6), V)
    np.testing.assert_array_equal(state, from_there)
    assert np.abs(state[6:12]).max() > 0.0
    assert np.abs(state[6:12]).max() <= ROBOT_ACCELERATION_LIMIT * H * (
        1 + 1e-12)
    # A measurement beyond a joint's limit by at most one period's step at
    # the acceleration limit from rest (an encoder at its limit) restarts
    # on the limit; one farther beyond (within the input guard's
    # MEASURED_POSITION_MARGIN, so no fault) is no position to restart
    # from, as none to start from: held on the limit, the command jumped
    # 0.05 rad away from the arm. It resumes from where it was.
    slack = arm.acceleration_limits[0] * H * H
    beyond = away.copy()
    beyond[0] = arm.upper[0] + 0.9 * slack
    state = update(q, previous, np.zeros(6), beyond, 1.0)
    assert state[0] == arm.upper[0]
    beyond[0] = arm.upper[0] + 0.05
    np.testing.assert_array_equal(
        update(q, previous, np.zeros(6), beyond, 1.0),
        controller_update(system, system.CreateDefaultContext(), q,
                          previous, np.zeros(6)))
    autodiff = system.ToAutoDiffXd()
    context = autodiff.CreateDefaultContext()
    context.SetDiscreteState(np.concatenate([q, previous, [0.0]]))
    autodiff.GetInputPort("arm_velocity").FixValue(context, V)
    autodiff.GetInputPort("arm_position").FixValue(
        context, InitializeAutoDiff(away).ravel())
    autodiff.GetInputPort("resume").FixValue(context, [1.0])
    update_ad = autodiff.EvalUniquePeriodicDiscreteUpdate(
        context).get_vector().CopyToVector()
    np.testing.assert_allclose(ExtractValue(update_ad).ravel(), from_there,
                               rtol=1e-12, atol=1e-15)
    # d q_cmd / d q_meas: the identity plus h d q_dot / d q.
    derivatives = np.array([u.derivatives() for u in update_ad[:6]])
    assert np.abs(derivatives - np.eye(6)).max() < 0.1


@pytest.mark.parametrize("V", [[1e308, 1e308, 0, 0, 0, 1e308],
                               [1.7e308, 0, 0, 0, 0, 0],
                               [1e308, -1e308, 1e308, -1e308, 1e308, 1e308]])
def test_a_finite_twist_whose_rates_overflow_brakes(arm, V):
    """A twist finite but so large that its joint rates overflow (a
    reference of 1e308 m/s, which the input guard passes as finite)
    brakes as one that is not finite (or is scaled into the limits where
    it does not overflow): never a NaN in q_cmd, never a step beyond the
    acceleration limit."""
    system = ArmCartesianVelocityController(None, arm)
    context = system.CreateDefaultContext()
    previous = np.array([1.5, -1.2, 0.8, 0.3, -0.1, 0.0])
    for q0 in (HOME_ARM_POSITIONS, 0.5 * (arm.lower + arm.upper) + 0.1):
        state = controller_update(system, context, q0, previous,
                                  np.array(V, dtype=float), 0.0)
        assert np.isfinite(state).all()
        change = state[6:12] - previous
        assert np.abs(change).max() <= ROBOT_ACCELERATION_LIMIT * H * (
            1 + 1e-12)
        assert state[12] == 1.0


@pytest.mark.parametrize("acceleration_limit", [None, 3.0])
def test_a_start_outside_the_limits_is_refused_not_jumped_to(
        arm, acceleration_limit):
    """Joint limits tightened to exclude the arm's measured position: the
    command would start on the limit, a jump for the servo (0.95 rad, or
    0.05 rad: 5 rad/s in one period); set_arm_position
    (Controller.initialize) refuses it, naming the joint. A reading past
    a limit by at most one period's step at the acceleration limit from
    rest (a h^2: an encoder at its limit) starts on the limit: the rule of
    the hardware's guard (start_within_limits), with the controller's
    acceleration limit (the arm's own if not given)."""
    lower = np.array(arm.lower, dtype=float)
    lower[1] = 0.5
    params = ArmControllerParameters(lower=lower.tolist(),
                                     upper=list(arm.upper),
                                     acceleration_limit=acceleration_limit)
    system = ArmCartesianVelocityController(params, arm)
    context = system.CreateDefaultContext()
    slack = (arm.acceleration_limits[1] if acceleration_limit is None
             else acceleration_limit) * H * H
    q = np.array(HOME_ARM_POSITIONS, dtype=float)
    for beyond in (0.95, 0.05, 1.01 * slack):
        q[1] = 0.5 - beyond
        value = re.escape(repr(float(q[1])))
        with pytest.raises(ValueError, match=(
                rf"q\[1\] = {value} is not allowed: must be within the "
                r"joint's limits \[0.5, 2.35\] rad .*would jump there\); "
                r"move the arm within them or widen arm_controller")):
            system.set_arm_position(context, q)
    q[1] = 0.5 - 0.99 * slack
    system.set_arm_position(context, q)
    q[1] = 0.5
    np.testing.assert_array_equal(system.GetOutputPort(
        "arm_position_command").Eval(context), q)


# --- the system -------------------------------------------------------


def simulate(params, twist, duration, q0=None, time_step=0.01):
    builder = DiagramBuilder()
    system = builder.AddSystem(ArmCartesianVelocityController(
        params, time_step=time_step))
    source = builder.AddSystem(ConstantVectorSource(twist))
    builder.Connect(source.get_output_port(),
                    system.GetInputPort("arm_velocity"))
    logs = {
        name: LogVectorOutput(system.GetOutputPort(name), builder,
                              publish_period=time_step)
        for name in ("arm_position_command", "arm_velocity_command",
                     "limited")
    }
    diagram = builder.Build()
    simulator = Simulator(diagram)
    if q0 is not None:
        system.set_arm_position(
            system.GetMyMutableContextFromRoot(simulator.get_mutable_context()),
            q0)
    simulator.AdvanceTo(duration)
    context = simulator.get_context()
    data = {name: log.FindLog(context).data() for name, log in logs.items()}
    q_cmd = system.GetOutputPort("arm_position_command").Eval(
        system.GetMyContextFromRoot(context))
    return q_cmd, data


def end_effector_error(arm, params, speed, time_step=0.01):
    """Error of the commanded end effector after 1 s of [speed, 0, 0]."""
    q_cmd, _ = simulate(params, [speed, 0, 0, 0, 0, 0], 1.0,
                        time_step=time_step)
    start, end = arm.evaluate(HOME_ARM_POSITIONS).X_AE, arm.evaluate(q_cmd).X_AE
    displacement = end.translation() - start.translation()
    turn = (start.rotation().inverse() @ end.rotation()).ToAngleAxis().angle()
    return displacement - [speed, 0.0, 0.0], turn


@pytest.mark.parametrize("use_acceleration_limit", [False, True])
def test_constant_twist_moves_the_end_effector(arm, use_acceleration_limit):
    """0.05 m/s along x of T_a for 1 s (100 updates, at t = 0 to 0.99):
    0.05 m along x. Tolerance 1e-3 m: the explicit (Euler) integration of
    q_dot = J_a(q)^-1 V_a drifts by O(h), 5e-5 m here (the tool point moves
    on arcs within each step), and with the acceleration limit the start
    from rest costs at most one step's travel, 0.05 m/s * h = 5e-4 m."""
    params = ArmControllerParameters(
        use_acceleration_limit=use_acceleration_limit)
    error, turn = end_effector_error(arm, params, 0.05)
    assert np.abs(error).max() < 1e-3
    assert turn < 1e-6
    if not use_acceleration_limit:
        assert np.abs(error).max() < 1e-4


def test_integration_error_is_first_order_in_the_time_step(arm):
    errors = [
        np.linalg.norm(end_effector_error(
            arm, ArmControllerParameters(use_acceleration_limit=False),
            0.05, time_step=h)[0])
        for h in (0.01, 0.005)
    ]
    assert errors[0] / errors[1] == pytest.approx(2.0, rel=0.1)


def test_spinning_the_wrist_stops_at_the_limit(arm):
    """A twist that turns joint 6 alone, at 1 rad/s, for 5 s: the command
    stops at upper - margin, braking within the acceleration limit, and
    never passes it."""
    params = ArmControllerParameters()
    J = jacobian(arm, HOME_ARM_POSITIONS)
    q_cmd, data = simulate(params, J[:, 5], 5.0)
    edge = arm.upper[5] - params.margin
    assert data["arm_position_command"][5].max() <= edge + 1e-12
    assert q_cmd[5] == pytest.approx(edge, abs=1e-12)
    np.testing.assert_allclose(q_cmd[:5], HOME_ARM_POSITIONS[:5], atol=1e-9)
    rates = data["arm_velocity_command"]
    assert np.abs(np.diff(rates, axis=1)).max() <= (
        ROBOT_ACCELERATION_LIMIT * 0.01 * (1 + 1e-9))
    assert data["limited"][0, -1] == 1.0  # still pushed, still limited
    assert data["limited"][0, 50] == 0.0  # cruising at 1 rad/s


@pytest.mark.parametrize("seed", range(2))
def test_pushing_through_limits_never_leaves_them(arm, seed):
    rng = np.random.default_rng(60 + seed)
    twist = np.concatenate([rng.normal(size=3) * 0.3, rng.normal(size=3)])
    params = ArmControllerParameters()
    _, data = simulate(params, twist, 4.0)
    q = data["arm_position_command"]
    assert np.all(q <= arm.upper[:, None] - params.margin + 1e-12)
    assert np.all(q >= arm.lower[:, None] + params.margin - 1e-12)
    assert np.abs(data["arm_velocity_command"]).max() <= 1.57 * (1 + 1e-12)
    assert data["limited"].max() == 1.0


def test_ports_state_and_no_direct_feedthrough():
    system = ArmCartesianVelocityController()
    inputs = [system.get_input_port(i).get_name()
              for i in range(system.num_input_ports())]
    assert inputs == ["arm_velocity", "hold", "arm_position", "resume"]
    names = [system.get_output_port(i).get_name()
             for i in range(system.num_output_ports())]
    assert names == ["arm_position_command", "arm_velocity_command",
                     "limited"]
    assert not system.HasDirectFeedthrough(0, 0)
    assert not system.HasAnyDirectFeedthrough()
    context = system.CreateDefaultContext()
    np.testing.assert_array_equal(
        system.get_output_port(0).Eval(context), HOME_ARM_POSITIONS)
    q0 = HOME_ARM_POSITIONS + 0.1
    system.set_arm_position(context, q0)
    np.testing.assert_array_equal(system.get_output_port(0).Eval(context), q0)
    np.testing.assert_array_equal(system.get_output_port(1).Eval(context),
                                  np.zeros(6))
    # At rest with a zero twist the command holds.
    system.get_input_port(0).FixValue(context, np.zeros(6))
    update = system.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_allclose(update.get_vector().CopyToVector()[:6], q0,
                               atol=1e-15)


def test_model_limits_are_the_defaults(arm):
    system = ArmCartesianVelocityController()
    np.testing.assert_array_equal(system.lower, arm.lower)
    np.testing.assert_array_equal(system.upper, arm.upper)
    np.testing.assert_array_equal(system.velocity_limits, np.full(6, 1.57))
    np.testing.assert_array_equal(arm.acceleration_limits,
                                  np.full(6, ROBOT_ACCELERATION_LIMIT))
    plant = arm._plant
    for name in ARM_JOINTS:
        joint = plant.GetJointByName(name)
        assert joint.acceleration_upper_limits()[0] == (
            ROBOT_ACCELERATION_LIMIT)


def test_autodiff_update_has_the_double_value_and_derivatives(arm):
    system = ArmCartesianVelocityController()
    ad = system.ToAutoDiffXd()
    assert ad.params == system.params
    rng = np.random.default_rng(70)
    q = regular_configuration(arm, rng)
    V = rng.normal(size=6) * 0.01
    context = system.CreateDefaultContext()
    system.set_arm_position(context, q)
    system.get_input_port(0).FixValue(context, V)
    expected = system.EvalUniquePeriodicDiscreteUpdate(
        context).get_vector().CopyToVector()
    ad_context = ad.CreateDefaultContext()
    ad.set_arm_position(ad_context, q)
    ad.get_input_port(0).FixValue(ad_context,
                                 InitializeAutoDiff(V).ravel())
    update = ad.EvalUniquePeriodicDiscreteUpdate(
        ad_context).get_vector().CopyToVector()
    np.testing.assert_allclose(ExtractValue(update).ravel(), expected)
    J_inv = np.linalg.inv(jacobian(arm, q))
    derivative = np.array([u.derivatives() for u in update[:6]])
    np.testing.assert_allclose(derivative, H * J_inv, rtol=1e-6, atol=1e-9)


def update_by_central_differences(system, x, u, step=1e-6):
    """d x_next / d (x, u) of the double system, by central differences."""
    context = system.CreateDefaultContext()
    port = system.get_input_port(0)

    def update(z):
        context.SetDiscreteState(z[:x.size])
        port.FixValue(context, z[x.size:])
        return system.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector()

    z = np.concatenate([x, u])
    columns = []
    for i in range(z.size):
        dz = np.zeros_like(z)
        dz[i] = step
        columns.append((update(z + dz) - update(z - dz)) / (2 * step))
    jac = np.stack(columns, axis=1)
    return jac[:, :x.size], jac[:, x.size:]


def expected_linearisation(arm, q, V):
    """A and B in closed form where no limit acts and J_a is regular:
    q_dot = J^-1 V, d q_dot / d q_i = -J^-1 (dJ/dq_i) J^-1 V, with dJ/dq_i
    from the analytic jacobian_derivative; q_dot does not depend on the
    previous rate."""
    J = jacobian(arm, q)
    J_inv = np.linalg.inv(J)
    q_dot = J_inv @ V
    dq_dot = np.stack([-J_inv @ dJ @ q_dot for dJ in jacobian_derivative(J)],
                      axis=1)
    A = np.zeros((13, 13))
    A[:6, :6] = np.eye(6) + H * dq_dot
    A[6:12, :6] = dq_dot
    B = np.zeros((13, 6))
    B[:6] = H * J_inv
    B[6:12] = J_inv
    return A, B, q_dot


def test_linearize_at_rest_gives_the_inverse_jacobian(arm):
    rng = np.random.default_rng(80)
    q = regular_configuration(arm, rng)
    system = ArmCartesianVelocityController()
    context = system.CreateDefaultContext()
    system.set_arm_position(context, q)
    system.get_input_port(0).FixValue(context, np.zeros(6))
    linear = Linearize(system, context)  # an equilibrium: V_a = 0
    assert linear.time_period() == H
    A, B, _ = expected_linearisation(arm, q, np.zeros(6))
    np.testing.assert_allclose(linear.A(), A, atol=1e-8)
    np.testing.assert_allclose(linear.B(), B, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(linear.C()[:6], np.eye(6, 13))
    np.testing.assert_array_equal(linear.D(), np.zeros((6, 6)))


@pytest.mark.parametrize("seed", range(2))
def test_taylor_approximation_at_a_moving_regular_point(arm, seed):
    """Away from singularities and limits, moving at the commanded rate:
    Drake's first-order approximation of the AutoDiff system against
    central differences of the double update and the closed form."""
    rng = np.random.default_rng(90 + seed)
    q = regular_configuration(arm, rng)
    V = np.concatenate([rng.normal(size=3) * 0.03, rng.normal(size=3) * 0.1])
    A, B, q_dot = expected_linearisation(arm, q, V)
    x = np.concatenate([q, q_dot, [0.0]])  # already at the desired rate
    system = ArmCartesianVelocityController()
    context = system.CreateDefaultContext()
    context.SetDiscreteState(x)
    system.get_input_port(0).FixValue(context, V)
    update = system.EvalUniquePeriodicDiscreteUpdate(context)
    assert update.get_vector().GetAtIndex(12) == 0.0  # nothing limited
    affine = FirstOrderTaylorApproximation(system, context)
    A_fd, B_fd = update_by_central_differences(system, x, V)
    for A_other, B_other in ((A_fd, B_fd), (A, B)):
        np.testing.assert_allclose(affine.A(), A_other, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(affine.B(), B_other, rtol=1e-6, atol=1e-8)
    assert np.abs(A[:6, :6] - np.eye(6)).max() > 1e-4  # A depends on V_a


# --- arguments --------------------------------------------------------


@pytest.mark.parametrize("kwargs, name", [
    (dict(damping=-0.1), "damping"),
    (dict(damping_threshold=0.0), "damping_threshold"),
    (dict(margin=-0.01), "margin"),
    (dict(margin=float("nan")), "margin"),
    (dict(acceleration_limit=0.0), "acceleration_limit"),
    (dict(use_acceleration_limit=1), "use_acceleration_limit"),
    (dict(lower=[-1.0] * 6), "upper"),
    (dict(lower=[1.0] * 6, upper=[-1.0] * 6), "lower"),
    (dict(lower=[-1.0] * 6, upper=[1.0] * 6, margin=1.0), "margin"),
    (dict(velocity_limits=[1.0] * 5 + [-1.0]), "velocity_limits"),
])
def test_bad_parameters_are_rejected(kwargs, name):
    with pytest.raises(ValueError, match=name):
        ArmControllerParameters(**kwargs)


def test_bad_system_arguments_are_rejected():
    with pytest.raises(ValueError, match="params"):
        ArmCartesianVelocityController(params=0.01)
    with pytest.raises(ValueError, match="margin"):
        ArmCartesianVelocityController(ArmControllerParameters(margin=2.4))
    for time_step in (0.0, -0.01):
        with pytest.raises(ValueError, match=f"time_step = {time_step}"):
            ArmCartesianVelocityController(time_step=time_step)
    for tolerance in (0.0, float("inf")):
        with pytest.raises(ValueError, match=(
                f"resume_tolerance = {tolerance} is not allowed")):
            ArmCartesianVelocityController(resume_tolerance=tolerance)
    system = ArmCartesianVelocityController()
    with pytest.raises(ValueError, match="q"):
        system.set_arm_position(system.CreateDefaultContext(), np.zeros(5))


@pytest.mark.parametrize("kwargs, name", [
    (dict(time_step=0.0), "time_step"),
    (dict(damping=-1.0), "damping"),
    (dict(damping_threshold=-1.0), "damping_threshold"),
    (dict(margin=-0.1), "margin"),
    (dict(velocity_limit=0.0), "velocity_limit"),
    (dict(acceleration_limit=-1.0), "acceleration_limit"),
    (dict(previous_q_dot=np.zeros(5), acceleration_limit=1.0),
     "previous_q_dot"),
    (dict(J_a=np.eye(5)), "J_a"),
    (dict(V_a=np.zeros(5)), "V_a"),
    (dict(q=np.full(6, np.nan)), "q"),
])
def test_bad_math_arguments_are_rejected(kwargs, name):
    arguments = dict(J_a=np.eye(6), V_a=np.zeros(6), q=np.zeros(6),
                     lower=-np.ones(6), upper=np.ones(6), velocity_limit=1.0,
                     time_step=0.01)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=name):
        joint_velocity_for_twist(**arguments)


@pytest.mark.parametrize("seed", range(5))
def test_a_redundant_arm_centres_its_joints_in_its_self_motion(seed):
    """Seven joints, away from every limit: with or without the joint
    centring, J q_dot = V_a exactly (to rounding); the centring part lies
    in J's null space, brings the joints towards their middles (z . N z
    >= 0 for z the centring rates), and six joints are not touched."""
    from drake_wbc.math.arm_control import (
        centring_velocity,
        joint_velocity_command,
        twist_limits,
    )
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(6, 7))
    V = rng.normal(0.0, 0.02, 6)
    lower, upper = -np.full(7, 3.0), np.full(7, 3.0)
    q = rng.uniform(-1.0, 1.0, 7)
    commands = {}
    for gain in (0.0, 0.5):
        limits = twist_limits(lower, upper, 10.0, H, margin=0.05,
                              self_motion_gain=gain)
        commands[gain] = joint_velocity_command(J, V, q, None, limits)
        assert not commands[gain].limited
        np.testing.assert_allclose(J @ commands[gain].q_dot, V, atol=1e-12)
    centring = commands[0.5].q_dot - commands[0.0].q_dot
    np.testing.assert_allclose(J @ centring, 0.0, atol=1e-12)
    z = centring_velocity(q, lower, upper, 0.5)
    assert z @ centring >= 0.0 and np.linalg.norm(centring) > 1e-3
    # Integrated with no task (J held), the joints settle where they are
    # as near the middles as the end effector allows: the component of q
    # along J's null space decays at k_c / r (0.5 / 3 1/s), the rest stays.
    null = np.linalg.svd(J)[2][-1]
    q_t = q.copy()
    limits = twist_limits(lower, upper, 10.0, H, self_motion_gain=0.5)
    for _ in range(3000):
        q_t = q_t + H * joint_velocity_command(J, np.zeros(6), q_t, None,
                                               limits).q_dot
    assert abs(null @ q_t) < 0.01 * abs(null @ q)
    np.testing.assert_allclose(J @ q_t, J @ q, atol=1e-9)
    # Six joints: nothing to centre in.
    J6, q6 = J[:, :6], q[:6]
    plain = joint_velocity_command(J6, V, q6, None, twist_limits(
        lower[:6], upper[:6], 10.0, H))
    centred = joint_velocity_command(J6, V, q6, None, twist_limits(
        lower[:6], upper[:6], 10.0, H, self_motion_gain=0.5))
    np.testing.assert_array_equal(plain.q_dot, centred.q_dot)


def _held_stage(arm, start, measured):
    """The arm stage held (a safe stop) at `start`, its arm measured at
    `measured`: (stage, context, simulator, the measured arm's port)."""
    system = ArmCartesianVelocityController(None, arm)
    context = system.CreateDefaultContext()
    system.set_arm_position(context, start)
    system.GetInputPort("arm_velocity").FixValue(context, np.zeros(6))
    system.GetInputPort("hold").FixValue(context, [1.0])
    system.GetInputPort("resume").FixValue(context, [0.0])
    port = system.GetInputPort("arm_position")
    port.FixValue(context, measured)
    return system, context, Simulator(system, context), port


def _command(context, n):
    return context.get_discrete_state_vector().CopyToVector()[:n].copy()


@pytest.mark.parametrize("clear_after", [20, 25, 30, 40])
def test_a_held_command_catching_up_near_a_limit_resumes_within_limits(
        arm, clear_after):
    """The arm moved to 5 mrad from a joint's upper limit during a stop,
    the command 0.3 rad away: the held command goes to the edge of the
    band the running command keeps to (the margin inside the limit), so
    that when the stop clears on the way there (once within the
    tolerance) the running command goes on within the acceleration
    limit. It went to the limit itself, outside the band, where the
    running command allows no outward rate: it stopped dead in one
    tick, 79 rad/s^2."""
    n = arm.num_joints
    start = np.array(arm.home, dtype=float)
    start[0] = arm.upper[0] - 0.3
    measured = start.copy()
    measured[0] = arm.upper[0] - 0.005
    system, context, simulator, _ = _held_stage(arm, start, measured)
    commands = [start]
    for i in range(60):
        simulator.AdvanceTo((i + 1) * H)
        commands.append(_command(context, n))
        if i == clear_after:
            system.GetInputPort("hold").FixValue(context, [0.0])
            system.GetInputPort("resume").FixValue(context, [1.0])
        elif i == clear_after + 1:
            system.GetInputPort("resume").FixValue(context, [0.0])
    rates = np.diff(np.array(commands), axis=0) / H
    assert np.abs(rates).max() <= arm.velocity_limits.max() * (1 + 1e-9)
    assert np.abs(np.diff(rates, axis=0)).max() / H <= (
        ROBOT_ACCELERATION_LIMIT * (1 + 1e-6))
    assert commands[-1][0] <= arm.upper[0] - DEFAULT_JOINT_LIMIT_MARGIN + (
        1e-12)


@pytest.mark.parametrize("sag", [0.002, 0.005, 0.02])
def test_a_held_command_does_not_chase_an_arm_that_sags_below_it(arm, sag):
    """A joint pushed 0.15 rad off its held command and let go, its servo
    (lagging, about 25 Hz) settling `sag` below the command, as a
    position servo under gravity does: the command goes to the arm and
    stays, a minute later where it came to rest. It went on following
    the arm that the servo carried along below it, down to the joint
    limit (2 mrad of sag, in 30 s)."""
    n = arm.num_joints
    home = np.array(arm.home, dtype=float)
    offset = np.zeros(n)
    offset[1] = -sag
    measured = home + offset
    measured[1] -= 0.15
    _, context, simulator, port = _held_stage(arm, home, measured)
    rested = None
    for i in range(6000):
        simulator.AdvanceTo((i + 1) * H)
        q = _command(context, n)
        if i >= 10:  # let go: the servo follows the command, `sag` below
            measured = measured + 0.55 * (q + offset - measured)
            port.FixValue(context, measured)
        if i == 200:
            rested = q
    np.testing.assert_allclose(q, rested, atol=1e-9)
    assert abs(q[1] - home[1]) < 0.16
