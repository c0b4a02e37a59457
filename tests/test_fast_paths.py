"""The unchecked per-tick paths against the checked functions and against
independent formulations (the formulas as written), on random inputs: no
result may differ beyond rounding (1e-12 relative)."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE, relative_difference
from pydrake.common.value import AbstractValue

from drake_wbc.math import (
    capability,
    capability_gradients,
    compensation,
    distribution,
    kinematics,
    pseudoinverse,
    repulsion,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import (
    ArmCapability,
    MotionDistributor,
    MotionDistributorParameters,
    RobustCompensator,
)
from drake_wbc.stages.cdmp_stages import BaseCdmp
from drake_wbc.stages.wrench import external_wrench


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def random_configurations(arm, count, seed):
    rng = np.random.default_rng(seed)
    middle, half = 0.5 * (arm.lower + arm.upper), 0.45 * (arm.upper - arm.lower)
    return [rng.uniform(middle - half, middle + half) for _ in range(count)]


# --- distribution ----------------------------------------------------------

def distribute_as_written(J, V_ee, sigma_xy, sigma_phi, V_n, damping):
    """Eqs. (wbsln)/(wbccm) as written: J^+ from the eigenvalues of
    J Q J^T with the damping rule of pseudoinverse's docstring, then
    J^+ V_ee + (I - J^+ J) V_n."""
    Q = np.diag([sigma_xy, sigma_xy, 1, 1, 1, sigma_phi, 1 - sigma_xy,
                 1 - sigma_xy, 1 - sigma_phi])
    M = J @ Q @ J.T
    M = 0.5 * (M + M.T)
    if damping is not None:
        e = np.linalg.eigvalsh(M)
        s_min, s_max = max(e[0], 0.0), e[-1]
        eps = damping.threshold * s_max
        if s_min < eps:
            M += np.eye(6) * damping.max_squared * s_max * (
                1 - (s_min / eps) ** 2)
    J_pinv = Q @ J.T @ np.linalg.inv(M)
    return J_pinv @ V_ee + (np.eye(9) - J_pinv @ J) @ V_n


def random_jacobians(rng, count):
    """Controller J_wb = [R_ba, J_b], random ones, and ones made nearly
    singular so that the damping acts (kind 2)."""
    for i in range(count):
        kind = i % 3
        if kind == 0:
            yield kind, kinematics.whole_body_jacobian(
                None, rng.uniform(-1.0, 1.0, 3), np.eye(3))
        elif kind == 1:
            yield kind, rng.normal(size=(6, 9))
        else:
            J = rng.normal(size=(6, 9))
            J[5] = J[4] + rng.choice([0.0, 1e-6, 1e-3, 3e-2]) * J[5]
            yield kind, J


def test_distribute_matches_the_formula_as_written():
    rng = np.random.default_rng(0)
    damping = pseudoinverse.DEFAULT_DAMPING
    worst = {}
    for kind, J in random_jacobians(rng, 600):
        sigma_xy, sigma_phi = rng.choice([0.0, 1.0, *rng.uniform(size=3)], 2)
        V_ee, V_n = rng.normal(size=6), rng.normal(size=9)
        expected = distribute_as_written(J, V_ee, sigma_xy, sigma_phi, V_n,
                                         damping)
        checked = distribution.distribute(J, V_ee, sigma_xy, sigma_phi, V_n)
        fast = distribution.distribute_unchecked(
            J, V_ee, pseudoinverse.weights_of(sigma_xy, sigma_phi), V_n,
            damping)
        np.testing.assert_array_equal(fast, checked)
        worst[kind] = max(worst.get(kind, 0.0),
                          relative_difference(fast, expected))
    # Kind 2 (damped, condition numbers up to 1e4) loses digits in the
    # inverse of the formula as written itself.
    assert worst[0] < RELATIVE and worst[1] < RELATIVE
    assert worst[2] < 1e-9


def test_certificate_only_skips_the_damping_when_it_is_inactive():
    rng = np.random.default_rng(1)
    threshold = pseudoinverse.DEFAULT_DAMPING.threshold
    skipped = 0
    for _, J in random_jacobians(rng, 900):
        JQ = J * pseudoinverse.weights_of(*rng.uniform(size=2))
        x = pseudoinverse.certified_solve(J, JQ, np.ones(6), threshold)
        e = np.linalg.eigvalsh(JQ @ J.T)
        if x is not None:
            skipped += 1
            assert e[0] >= threshold * e[-1]
            assert relative_difference(x, np.linalg.solve(JQ @ J.T,
                                                          np.ones(6))) < 1e-10
    assert skipped > 500  # the controller's and the random ones


def test_weighted_pseudoinverse_unchanged_and_null_velocity_optional():
    rng = np.random.default_rng(2)
    for _, J in random_jacobians(rng, 60):
        sigma = rng.uniform(size=2)
        Q = pseudoinverse.weighting_matrix(*sigma)
        V_ee = rng.normal(size=6)
        J_pinv = pseudoinverse.weighted_pseudoinverse(J, Q)
        assert relative_difference(
            distribution.distribute(J, V_ee, *sigma), J_pinv @ V_ee) < 1e-12
        assert relative_difference(
            J_pinv, distribute_as_written(
                J, np.eye(6), *sigma, np.zeros((9, 6)),
                pseudoinverse.DEFAULT_DAMPING)) < 1e-9


def test_distribute_still_checks_its_arguments():
    J = kinematics.whole_body_jacobian(None, [0.5, 0.1, 0.6])
    with pytest.raises(ValueError, match="V_ee"):
        distribution.distribute(J, [0.0, np.nan, 0, 0, 0, 0], 0.5, 0.5)
    with pytest.raises(ValueError, match="sigma_phi"):
        distribution.distribute(J, np.zeros(6), 0.5, 1.5)
    with pytest.raises(ValueError, match="null_velocity"):
        distribution.distribute(J, np.zeros(6), 0.5, 0.5, np.zeros(8))
    with pytest.raises(ValueError, match="J_wb"):
        distribution.distribute(np.full((6, 9), np.inf), np.zeros(6), 0, 0)


# --- kinematics --------------------------------------------------------------

def test_whole_body_jacobian_unchecked_matches_checked():
    rng = np.random.default_rng(3)
    for _ in range(50):
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        R *= np.sign(np.linalg.det(R))
        J_a, p = rng.normal(size=(6, 6)), rng.normal(size=3)
        for arm_jacobian in (None, J_a):
            np.testing.assert_array_equal(
                kinematics.whole_body_jacobian_unchecked(arm_jacobian, p, R),
                kinematics.whole_body_jacobian(arm_jacobian, p, R))
        expected = np.hstack([np.kron(np.eye(2), R),
                              kinematics.base_jacobian(p)])
        np.testing.assert_array_equal(
            kinematics.whole_body_jacobian(None, p, R), expected)


def test_remembered_rotation_is_checked_again_when_it_changes():
    R = np.eye(3)
    kinematics.whole_body_jacobian(None, np.zeros(3), R)
    kinematics.whole_body_jacobian(None, np.zeros(3), R)  # remembered
    R[0, 0] = 2.0  # the same array, changed in place
    with pytest.raises(ValueError, match="R_ba"):
        kinematics.whole_body_jacobian(None, np.zeros(3), R)


def test_as_float_array_fast_path_and_errors():
    x = np.arange(3.0)
    assert kinematics.as_float_array("x", x, (3,)) is x
    np.testing.assert_array_equal(
        kinematics.as_float_array("x", [1, 2, 3], (3,)), [1.0, 2.0, 3.0])
    huge = np.full(3, 1e308)  # finite, though its sum would overflow
    assert kinematics.as_float_array("x", huge, (3,)) is huge
    for bad in (np.array([0.0, np.nan, 1.0]), np.zeros(4), "abc"):
        with pytest.raises(ValueError, match="x"):
            kinematics.as_float_array("x", bad, (3,))


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


def test_distributor_and_compensator_match_the_checked_math(arm):
    rng = np.random.default_rng(12)
    distributor = MotionDistributor(
        MotionDistributorParameters(null_space_gain=0.1), arm)
    compensator = RobustCompensator(None, arm)
    d_context = distributor.CreateDefaultContext()
    c_context = compensator.CreateDefaultContext()
    R_ba = np.array(arm.R_ba)
    for _ in range(20):
        V_ee, p, g = rng.normal(size=6), rng.uniform(-1, 1, 3), rng.normal(
            size=6)
        sigma, C_m = rng.uniform(size=2), rng.uniform(0.03, 0.045)
        for name, value in (("end_effector_velocity", V_ee),
                            ("sigma_xy", sigma[:1]), ("sigma_phi", sigma[1:]),
                            ("end_effector_position", p),
                            ("capability", [C_m]),
                            ("capability_gradient", g)):
            distributor.GetInputPort(name).FixValue(d_context, value)
        k_n = 0.1 * capability.transition(C_m, 0.04, 0.035)
        expected = distribution.distribute(
            kinematics.whole_body_jacobian(None, p, R_ba), V_ee, *sigma,
            distribution.capability_null_velocity(g, k_n))
        actual = np.concatenate([
            distributor.GetOutputPort("arm_velocity").Eval(d_context),
            distributor.GetOutputPort("base_velocity").Eval(d_context)])
        assert relative_difference(actual, expected) < RELATIVE

        V_a, V_b, V_b_flt = (rng.normal(size=6), rng.normal(size=3),
                             rng.normal(size=3))
        alpha = rng.uniform()
        for name, value in (("arm_velocity", V_a), ("base_velocity", V_b),
                            ("filtered_base_velocity", V_b_flt),
                            ("end_effector_position", p),
                            ("capability_gradient", g), ("alpha", [alpha])):
            compensator.GetInputPort(name).FixValue(c_context, value)
        cmp, deviation = compensation.robust_compensation(
            V_b_flt - V_b, kinematics.base_jacobian(p), R_ba, g, alpha)
        assert relative_difference(
            compensator.GetOutputPort("arm_reference_velocity").Eval(
                c_context), V_a + cmp) < RELATIVE
        assert relative_difference(
            compensator.GetOutputPort("end_effector_deviation").Eval(
                c_context), deviation) < RELATIVE


def test_base_cdmp_force_is_cached_on_the_points():
    stage = BaseCdmp()
    context = stage.CreateDefaultContext()
    stage.GetInputPort("base_velocity").FixValue(context, np.zeros(3))
    port = stage.GetInputPort("obstacle_points")
    rng = np.random.default_rng(13)
    for _ in range(3):
        points = rng.uniform(-0.9, 0.9, (50, 2))
        port.FixValue(context, AbstractValue.Make(points))
        expected = repulsion.repulsive_force(points, stage.params.repulsion)
        force = stage.repulsive_force(context)
        np.testing.assert_array_equal(force, [*expected, 0.0])
        force[:] = np.nan  # a copy: the cached value stays
        np.testing.assert_array_equal(stage.repulsive_force(context)[:2],
                                      expected)


def test_external_wrench_matches_np_cross(arm):
    rng = np.random.default_rng(14)
    for q in random_configurations(arm, 5, 15):
        X_AM = arm.frame_pose(q, arm.model.ft_measurement_frame)
        X_AT = arm.frame_pose(q, arm.model.tcp_frame)
        reading, p_com, mass = rng.normal(size=6), rng.normal(size=3), 1.3
        R = X_AM.rotation().matrix()
        weight = R.T @ [0.0, 0.0, -mass * 9.81]
        f = R @ (reading[:3] - weight)
        tau = R @ (reading[3:] - np.cross(p_com, weight)) + np.cross(
            X_AM.translation() - X_AT.translation(), f)
        np.testing.assert_array_equal(
            external_wrench(reading, X_AM, X_AT, mass, p_com), np.r_[f, tau])


def test_repulsive_force_float_path_matches_the_general_one():
    """Points inside, on, near and far from the footprint, and a crowd
    that hits the bound: the float path against the general one (written
    for AutoDiffXd, here on floats)."""
    rng = np.random.default_rng(23)
    for max_force in (80.0, 1e12):
        params = repulsion.RepulsiveFieldParameters(k_obs=0.02,
                                                    max_force=max_force)
        for count in (1, 5, 300):
            points = rng.uniform(-1.5, 1.5, (count, 2))
            points[:: 7] = rng.uniform(-0.45, 0.45, points[:: 7].shape)
            fast = repulsion.repulsive_force(points, params)
            general = repulsion._repulsive_force_any(points, params)
            assert relative_difference(fast, general) < RELATIVE
    nan = np.array([[0.5, 0.0], [np.nan, 0.1]])
    assert np.all(np.isnan(repulsion.repulsive_force(
        nan, repulsion.RepulsiveFieldParameters())))
