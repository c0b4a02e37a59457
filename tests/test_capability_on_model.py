"""The capability of movement on the robot model: the analytic gradients
against finite differences through Drake's kinematics of the Elfin5, and
the default k_j against the paper's limitation band."""

import numpy as np
import pytest

from drake_wbc.math import capability
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics

BAND = (0.035, 0.04)  # the paper's C_m^l, C_m^u


@pytest.fixture(scope="module")
def kinematics():
    return ArmKinematics()


def _random_configurations(kinematics, count, seed):
    rng = np.random.default_rng(seed)
    configurations = []
    while len(configurations) < count:
        q = rng.uniform(0.9 * kinematics.lower, 0.9 * kinematics.upper)
        # Keep away from singularities, where the gradient is not smooth.
        s = np.linalg.svd(kinematics.evaluate(q).J_a, compute_uv=False)
        if s[-1] > 0.05:
            configurations.append(q)
    return configurations


def test_manipulability_gradient_matches_drake(kinematics):
    step = 1e-6
    for q in _random_configurations(kinematics, 10, seed=5):
        analytic = capability.manipulability_joint_gradient(
            kinematics.evaluate(q).J_a
        )
        numeric = np.zeros(6)
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = step
            numeric[i] = (
                capability.manipulability(kinematics.evaluate(q + dq).J_a)
                - capability.manipulability(kinematics.evaluate(q - dq).J_a)
            ) / (2 * step)
        np.testing.assert_allclose(analytic, numeric, rtol=1e-5, atol=1e-9)


def test_cartesian_gradient_is_rate_of_change_along_twists(kinematics):
    """g . V equals dC_m/dt when the arm moves with twist V (Drake's
    Jacobian maps V to joint rates; C_m evaluated on the model)."""
    lower, upper = kinematics.lower, kinematics.upper
    rng = np.random.default_rng(6)
    step = 1e-6

    def C_m(q):
        return capability.capability(kinematics.evaluate(q).J_a, q, lower,
                                     upper)

    for q in _random_configurations(kinematics, 10, seed=7):
        J_a = kinematics.evaluate(q).J_a
        g = capability.capability_gradient(J_a, q, lower, upper)
        V = rng.normal(size=6)
        q_dot = np.linalg.solve(J_a, V)
        rate = (C_m(q + step * q_dot) - C_m(q - step * q_dot)) / (2 * step)
        assert g @ V == pytest.approx(rate, rel=1e-5, abs=1e-10)


def test_default_k_j_places_the_band_between_home_and_constraints(
    kinematics,
):
    lower, upper = kinematics.lower, kinematics.upper

    def C_m(q):
        return capability.capability(kinematics.evaluate(q).J_a, q, lower,
                                     upper)

    # Home is well above the band.
    assert C_m(HOME_ARM_POSITIONS) > 1.5 * BAND[1]
    # A joint 5% of its range from a limit (the others at home) is below it.
    q = HOME_ARM_POSITIONS.copy()
    q[0] = upper[0] - 0.05 * (upper[0] - lower[0])
    assert C_m(q) < BAND[0]
    # So is the elbow opened towards the stretched singularity,
    q = HOME_ARM_POSITIONS.copy()
    q[2] = 0.45
    assert C_m(q) < BAND[0]
    # while 20% from a limit is still above it.
    q = HOME_ARM_POSITIONS.copy()
    q[0] = upper[0] - 0.20 * (upper[0] - lower[0])
    assert C_m(q) > BAND[1]


@pytest.mark.parametrize(("joint", "slope"), [(4, 0.31), (2, 0.16)],
                         ids=["wrist", "elbow"])
def test_smallest_singular_value_near_the_singularities(kinematics, joint,
                                                        slope):
    """s_min of J_a about `slope` d within d rad of the wrist (q_5 = 0)
    and elbow (q_3 = 0) singularities, from home: the slopes from which
    the docstrings of the damping thresholds (capability's and
    arm_control's DEFAULT_DAMPING_THRESHOLD) tell where each damps."""
    for d in (0.01, 0.05, 0.1):
        q = np.array(HOME_ARM_POSITIONS, dtype=float)
        q[joint] = d
        s_min = np.linalg.svd(kinematics.evaluate(q).J_a,
                              compute_uv=False)[-1]
        assert s_min / d == pytest.approx(slope, rel=0.03)
