"""The simulated arm refuses what the real arm refuses: a position command
beyond a joint's position, speed or acceleration limit faults it, and it
brakes to rest within its acceleration limits and stays stopped
(drake_wbc.station.arm_supervisor, drake_wbc.math.arm_servo); a stream
within the limits, up to rounding, passes. The closed forms: from a rate
of k a h the stop's rates are (k - 1) a h, ..., a h, 0, and it comes to
rest a h^2 k (k - 1) / 2 further on."""

import numpy as np
import pytest

from drake_wbc.math.arm_servo import arm_command_violation, brake_arm
from drake_wbc.robot.model import ArmKinematics

H = 0.01  # the arm's command period, s
ARM = ArmKinematics()
SPEED, ACCELERATION = ARM.velocity_limits, ARM.acceleration_limits
LOWER, UPPER = ARM.lower, ARM.upper
HOME = np.array(ARM.home)


def violation(command, last=HOME, velocity=None):
    velocity = np.zeros(6) if velocity is None else velocity
    return arm_command_violation(command, last, velocity, H, LOWER, UPPER,
                                 SPEED, ACCELERATION)


def along(joint, value):
    e = np.zeros(6)
    e[joint] = value
    return e


@pytest.mark.parametrize("joint", range(6))
def test_a_command_at_each_limit_up_to_rounding_is_within_it(joint):
    a, v = ACCELERATION[joint], SPEED[joint]
    for scale, within in ((1.0 + 0.5e-9, True), (1.0 + 2e-9, False)):
        # Position: on the upper limit, the last command at rest on it.
        at = HOME.copy()
        at[joint] = UPPER[joint]
        beyond = violation(at + along(joint, (scale - 1.0) * UPPER[joint]),
                           last=at)
        assert (beyond is None) == within
        if not within:
            assert beyond == (joint, "position", pytest.approx(
                UPPER[joint] * scale, rel=1e-15), UPPER[joint])
        # Speed: at the speed limit from it (no change of rate).
        found = violation(HOME + along(joint, v * H * scale),
                          velocity=along(joint, v))
        assert (found is None) == within
        if not within:
            assert found.kind == "speed" and found.joint == joint
            assert found.value == pytest.approx(v * scale, rel=1e-12)
            assert found.limit == v
        # Acceleration: a h^2 from rest.
        found = violation(HOME + along(joint, a * H * H * scale))
        assert (found is None) == within
        if not within:
            assert found.kind == "acceleration" and found.joint == joint
            assert found.value == pytest.approx(a * scale, rel=1e-9)
            assert found.limit == a


def test_the_first_limit_broken_is_reported_in_order():
    """Position before speed before acceleration, the first joint first;
    a command that is not a number is beyond its position limits."""
    jump = HOME + along(4, 1.0) + along(2, 0.5)
    assert violation(jump)[:2] == (2, "speed")
    found = violation(jump + along(5, 10.0))
    assert found[:2] == (5, "position") and found.limit == UPPER[5]
    found = violation(HOME + along(3, np.nan) + along(1, -5.0))
    assert found[:2] == (1, "position") and found.limit == LOWER[1]
    found = violation(HOME + along(3, np.nan))
    assert found[:2] == (3, "position") and np.isnan(found.value)
    assert violation(HOME) is None


def test_the_stop_slows_at_the_acceleration_limit_and_holds():
    a, k = ACCELERATION, 7
    q, v = HOME.copy(), k * a * H
    rates = []
    for _ in range(k + 3):
        q, v = brake_arm(q, v, H, a, LOWER, UPPER)
        rates.append(v)
    expected = [max(k - 1 - j, 0) * a * H for j in range(k + 3)]
    np.testing.assert_allclose(rates, expected, atol=1e-12)
    np.testing.assert_allclose(q - HOME, a * H * H * k * (k - 1) / 2,
                               rtol=1e-12)
