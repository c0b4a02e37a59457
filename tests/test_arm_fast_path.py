"""The float fast paths of the arm's stages against the formulas as
written: the motion distribution for R_ba = I (distribute_aligned) and
the robust compensation in plain floats, each through its function and
its Drake system, with degenerate inputs and values that are not
finite."""

import numpy as np
import pytest
from fast_path_checks import RELATIVE, relative_difference
from pydrake.autodiffutils import ExtractValue

from drake_wbc.bench import distribution_race as race
from drake_wbc.math import (
    aligned_distribution,
    capability,
    compensation,
    distribution,
    kinematics,
    pseudoinverse,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import (
    MotionDistributor,
    MotionDistributorParameters,
    RobustCompensator,
)


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


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
