"""The float fast paths of the arm's stages against the formulas as
written: the arm's Cartesian velocity controller (TwistSolver), the motion
distribution for R_ba = I (distribute_aligned) and the robust compensation
in plain floats, each through its function and its Drake system, with
limits active, degenerate inputs and values that are not finite."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE, relative_difference
from pydrake.autodiffutils import AutoDiffXd, ExtractValue

from drake_wbc.bench import distribution_race as race
from drake_wbc.math import (
    aligned_distribution,
    arm_control,
    capability,
    compensation,
    distribution,
    kinematics,
    pseudoinverse,
    twist_solver,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import (
    ArmCartesianVelocityController,
    MotionDistributor,
    MotionDistributorParameters,
    RobustCompensator,
)

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


# --- motion distribution ----------------------------------------------------

def distribution_cases(count, seed):
    """(V_ee, p_ee, sigma_xy, sigma_phi, null arm velocity or None), with
    sigmas at 0 and 1 and reaches up to 15 m (where the certificate fails
    and the general path runs)."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        p = rng.uniform(-1.5, 1.5, 3) * (10.0 if i % 25 == 0 else 1.0)
        sigma_xy, sigma_phi = rng.choice([0.0, 1.0, *rng.uniform(size=3)],
                                         2)
        null = rng.normal(size=6) if i % 2 else None
        yield rng.normal(size=6), p, float(sigma_xy), float(sigma_phi), null


def test_distribute_aligned_matches_the_general_path():
    fallback = 0
    for V, p, s_xy, s_phi, null in distribution_cases(1500, seed=9):
        J = kinematics.whole_body_jacobian(None, p, np.eye(3))
        V_n = None if null is None else np.r_[null, 0.0, 0.0, 0.0]
        for damping in (pseudoinverse.DEFAULT_DAMPING, None):
            expected = distribution.distribute_unchecked(
                J, V, pseudoinverse.weights_of(s_xy, s_phi), V_n, damping)
            fast = aligned_distribution.distribute_aligned(
                V, p, s_xy, s_phi, null, damping)
            assert relative_difference(fast, expected) < RELATIVE
            # Sequences work as well as arrays.
            np.testing.assert_array_equal(
                aligned_distribution.distribute_aligned(
                    list(V), list(p), s_xy, s_phi,
                    None if null is None else list(null), damping), fast)
        M = (J * pseudoinverse.weights_of(s_xy, s_phi)) @ J.T
        fallback += pseudoinverse.certified_solve(
            J, J * pseudoinverse.weights_of(s_xy, s_phi), np.ones(6),
            1e-4) is None
        assert np.linalg.eigvalsh(M)[0] > 0.0
    assert fallback > 0  # the general path was taken somewhere


@pytest.mark.filterwarnings("ignore:invalid value encountered")
def test_distribute_aligned_keeps_the_task_and_the_general_failures():
    rng = np.random.default_rng(10)
    for _ in range(50):
        V, p = rng.normal(size=6), rng.uniform(-1, 1, 3)
        V_wb = aligned_distribution.distribute_aligned(
            V, p, *rng.uniform(size=2), rng.normal(size=6))
        J = kinematics.whole_body_jacobian(None, p)
        np.testing.assert_allclose(J @ V_wb, V, atol=1e-13)
    # Values that are not finite: what the general path gives.
    J = kinematics.whole_body_jacobian(None, [0.4, 0.2, 0.5])
    bad_V = np.r_[np.nan, np.zeros(5)]
    expected = distribution.distribute_unchecked(
        J, bad_V, pseudoinverse.weights_of(0.5, 0.5), None,
        pseudoinverse.DEFAULT_DAMPING)
    assert np.isnan(expected).any()
    np.testing.assert_array_equal(
        aligned_distribution.distribute_aligned(bad_V, [0.4, 0.2, 0.5], 0.5,
                                                0.5),
        expected)
    with pytest.raises(np.linalg.LinAlgError):
        aligned_distribution.distribute_aligned(np.zeros(6), [np.inf, 0.2, 0.5],
                                                0.5, 0.5)


def fix(system, context, values):
    for name, value in values.items():
        system.GetInputPort(name).FixValue(context, value)


def outputs(system, context, names):
    return np.concatenate([
        np.asarray(ExtractValue(system.GetOutputPort(n).Eval(context)),
                   dtype=float).ravel() for n in names])


def test_distributor_float_path_matches_its_general_path(arm):
    """The float system (plain floats) against its AutoDiffXd copy (the
    general formulas), with and without the null_space_gain port."""
    params = MotionDistributorParameters(null_space_gain=0.1)
    system = MotionDistributor(params, arm)
    general = system.ToAutoDiffXd()
    names = ("arm_velocity", "base_velocity")
    rng = np.random.default_rng(11)
    for i, (V, p, s_xy, s_phi, _) in enumerate(
            distribution_cases(60, seed=11)):
        values = {"end_effector_velocity": V, "sigma_xy": [s_xy],
                  "sigma_phi": [s_phi], "end_effector_position": p,
                  "capability": [rng.uniform(0.03, 0.045)],
                  "capability_gradient": rng.normal(size=6)}
        if i % 3 == 0:
            values["null_space_gain"] = [rng.uniform(0.0, 0.3)]
        context, ad_context = (system.CreateDefaultContext(),
                               general.CreateDefaultContext())
        fix(system, context, values)
        fix(general, ad_context, values)
        assert relative_difference(
            outputs(system, context, names),
            outputs(general, ad_context, names)) < 1e-11
        k_n = values.get("null_space_gain", [0.1])[0] * (
            capability.transition(values["capability"][0], 0.04, 0.035))
        expected = distribution.distribute(
            kinematics.whole_body_jacobian(None, p), V, s_xy, s_phi,
            distribution.capability_null_velocity(
                values["capability_gradient"], k_n))
        assert relative_difference(outputs(system, context, names),
                                   expected) < RELATIVE


@pytest.mark.parametrize("name, value", [("sigma_xy", np.nan),
                                         ("sigma_phi", 1.5),
                                         ("null_space_gain", -0.1)])
def test_distributor_float_path_still_rejects_bad_values(arm, name, value):
    system = MotionDistributor(None, arm)
    context = system.CreateDefaultContext()
    fix(system, context, {"end_effector_velocity": np.zeros(6),
                          "sigma_xy": [0.5], "sigma_phi": [0.5],
                          "end_effector_position": [0.4, 0.1, 0.5],
                          "capability": [0.05],
                          "capability_gradient": np.ones(6), name: [value]})
    with pytest.raises(ValueError, match=name):
        system.GetOutputPort("arm_velocity").Eval(context)


def test_race_closed_form_is_the_controllers_distribution(arm):
    solve = race.closed_form(arm)
    for problem in race.make_problems(10, seed=12, arm=arm):
        p_ee = arm.evaluate(problem.arm_position).p_ee_in_base
        expected = distribution.distribute(
            kinematics.whole_body_jacobian(None, p_ee, arm.R_ba),
            problem.end_effector_velocity, problem.sigma_xy,
            problem.sigma_phi, distribution.capability_null_velocity(
                problem.capability_gradient, problem.null_space_gain))
        assert relative_difference(solve(problem), expected) < RELATIVE


# --- robust compensation ----------------------------------------------------

def random_rotation(rng):
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    return R * np.sign(np.linalg.det(R))


def test_compensate_unchecked_matches_robust_compensation():
    rng = np.random.default_rng(13)
    for i in range(500):
        R = np.eye(3) if i % 2 else random_rotation(rng)
        V_a, dV_b, p = rng.normal(size=6), rng.normal(size=3), rng.normal(
            size=3)
        g = rng.normal(size=6) * rng.choice([0.0, 1e-13, 1e-11, 1.0, 1e3])
        alpha = float(rng.choice([0.0, 1.0, rng.uniform()]))
        cmp, deviation = compensation.robust_compensation(
            dV_b, kinematics.base_jacobian(p), R, g, alpha)
        result = compensation.compensate_unchecked(
            V_a.tolist(), dV_b.tolist(), p.tolist(),
            tuple(map(tuple, R.T.tolist())), g.tolist(), alpha)
        assert relative_difference(result[:6], V_a + cmp) < RELATIVE
        scale = max(np.max(np.abs(cmp)), 1e-300)
        assert np.max(np.abs(np.array(result[6:]) - deviation)) \
            <= RELATIVE * scale
    nan = compensation.compensate_unchecked(
        [0.0] * 6, [np.nan, 0.0, 0.0], [0.1, 0.2, 0.3],
        ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0)), [1.0] * 6, 0.5)
    assert np.isnan(nan).any()


def test_compensator_float_path_matches_its_general_path(arm):
    system = RobustCompensator(None, arm)
    general = system.ToAutoDiffXd()
    names = ("arm_reference_velocity", "end_effector_deviation")
    rng = np.random.default_rng(14)
    for i in range(60):
        values = {"arm_velocity": rng.normal(size=6),
                  "base_velocity": rng.normal(size=3),
                  "filtered_base_velocity": rng.normal(size=3),
                  "end_effector_position": rng.uniform(-1, 1, 3),
                  "capability_gradient": rng.normal(size=6)
                  * (0.0 if i % 10 == 0 else 1.0),
                  "alpha": [float(rng.choice([0.0, 1.0, rng.uniform()]))]}
        if i % 3 == 0:
            values["compensation_switch"] = [rng.uniform()]
        context, ad_context = (system.CreateDefaultContext(),
                               general.CreateDefaultContext())
        fix(system, context, values)
        fix(general, ad_context, values)
        fast, slow = (outputs(system, context, names),
                      outputs(general, ad_context, names))
        assert np.max(np.abs(fast - slow)) <= RELATIVE * max(
            np.max(np.abs(slow)), 1.0)


@pytest.mark.parametrize("name, value", [("alpha", np.nan), ("alpha", 1.5),
                                         ("compensation_switch", -0.5)])
def test_compensator_float_path_still_rejects_bad_values(arm, name, value):
    system = RobustCompensator(None, arm)
    context = system.CreateDefaultContext()
    values = {"arm_velocity": np.zeros(6), "base_velocity": np.zeros(3),
              "filtered_base_velocity": np.zeros(3),
              "end_effector_position": np.zeros(3),
              "capability_gradient": np.ones(6), "alpha": [0.5]}
    values[name] = [value]
    fix(system, context, values)
    with pytest.raises(ValueError, match=name):
        system.GetOutputPort("arm_reference_velocity").Eval(context)
