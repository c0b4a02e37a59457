"""What a cobot's position servo takes from a stream of joint position
commands, and how it stops.

A real arm's servo interface samples the position commands at its command
period h and checks each against the joint's own limits: the command
within the joint position limits, its step from the one before within the
joint speed limit, and the change of that step's rate within the
acceleration limit (the first command's step is from the position the arm
holds, at rest). A command beyond any of them is a fault: the arm brakes
to rest within its acceleration limits and stays stopped
(`arm_command_violation`, `brake_arm`). The simulated station runs these
(drake_wbc.station.arm_supervisor), and the robot side's own limiter
brakes with the same step (drake_wbc.hardware.safety.stop_arm).

Plain float functions (a fault is an event, not a signal to
differentiate).
"""

import math
from typing import NamedTuple

import numpy as np

from drake_wbc.math.command_limits import ROUNDING

LIMIT_KINDS = ("position", "speed", "acceleration")
"""The limits a position command is checked against, in the order they
are checked (ArmLimitViolation.kind)."""


class ArmLimitViolation(NamedTuple):
    """One joint's command beyond one of its limits.

    Attributes:
        joint: the joint's index in the arm (0 the first).
        kind: which limit, one of LIMIT_KINDS.
        value: the command's position (rad), the magnitude of its rate
            (rad/s) or the magnitude of the change of its rate (rad/s^2);
            NaN for a command that is not a number.
        limit: the limit it is beyond: the position limit on the side it
            left (rad), or the speed (rad/s) or acceleration (rad/s^2)
            limit.
    """

    joint: int
    kind: str
    value: float
    limit: float


def arm_command_violation(command, last, velocity, period, lower, upper,
                          speed, acceleration):
    """The first limit that the position command `command` breaks, or None.

    Checked in the order of LIMIT_KINDS, each over the joints in order,
    with rounding allowed (ROUNDING relative): the command within
    [lower, upper]; its rate (command - last) / period within +-speed;
    the change of that rate from `velocity` within +-acceleration period.
    A command that is not a number (NaN) is beyond its position limits;
    an infinite one too, also on a continuous joint (limits -inf and
    inf, which bound nothing else).

    Args:
        command: (n,) the command received, rad.
        last: (n,) the last command taken (at the start: the position the
            arm holds), rad.
        velocity: (n,) the rate of `last` (at the start: 0), rad/s.
        period: h, the command period, s.
        lower, upper: (n,) the joint position limits, rad (-inf and inf:
            a continuous joint).
        speed: (n,) the joint speed limits, rad/s.
        acceleration: (n,) the joint acceleration limits, rad/s^2.

    Returns:
        ArmLimitViolation, or None when the command is within every limit.
    """
    command = np.asarray(command, dtype=float)
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    # Infinite, beyond the position limits even of a continuous joint
    # (-inf and inf), which it would pass as a speed.
    within = (np.isfinite(command)
              & (command >= lower - ROUNDING * np.abs(lower))
              & (command <= upper + ROUNDING * np.abs(upper)))
    if not within.all():
        i = int(np.flatnonzero(~within)[0])
        side = lower[i] if command[i] <= lower[i] else upper[i]
        return ArmLimitViolation(i, "position", float(command[i]),
                                 float(side))
    # Within the position limits, so finite: no rate below overflows.
    rate = (command - last) / period
    speed = np.asarray(speed, dtype=float)
    fast = ~(np.abs(rate) <= speed * (1.0 + ROUNDING))
    if fast.any():
        i = int(np.flatnonzero(fast)[0])
        return ArmLimitViolation(i, "speed", float(abs(rate[i])),
                                 float(speed[i]))
    # As the robot side's limiter compares them (hardware.safety.
    # follow_arm_command): the change of rate against a h.
    change = np.abs(rate - velocity)
    acceleration = np.asarray(acceleration, dtype=float)
    sudden = ~(change <= acceleration * period * (1.0 + ROUNDING))
    if sudden.any():
        i = int(np.flatnonzero(sudden)[0])
        return ArmLimitViolation(i, "acceleration",
                                 float(change[i] / period),
                                 float(acceleration[i]))
    return None


def brake_arm(last, velocity, period, acceleration, lower, upper):
    """The next position command of an arm that stops: each joint slows
    down from `velocity` at its acceleration limit and holds where it
    comes to rest (within the position limits).

    Args:
        last: (n,) the last command, rad.
        velocity: (n,) its rate, rad/s.
        period: h, s between commands.
        acceleration: (n,) the joint acceleration limits, rad/s^2.
        lower, upper: (n,) the joint position limits, rad.

    Returns:
        (command (n,), its rate (n,)).
    """
    slower = np.sign(velocity) * np.maximum(
        np.abs(velocity) - acceleration * period, 0.0)
    command = np.clip(last + slower * period, lower, upper)
    return command, (command - last) / period


def brake_speed(distance, acceleration, period):
    """The largest speed v at which a joint may move this period and still
    come to rest within `distance`, slowing by at most `acceleration` *
    `period` each period of `period` s (elementwise, all >= 0). Braking
    hardest from v = m a h + f (m whole, 0 <= f < a h), it moves v, v - a h,
    ..., f for one period each:

        h ((m + 1) f + a h m (m + 1) / 2) = distance,

    so m = floor((sqrt(1 + 8 d / (a h^2)) - 1) / 2) and f follows. From v
    the next period's brake_speed is at least v - a h, so a joint that
    keeps to it never has to brake harder than it may, and never passes
    the point. An infinite distance (towards the limit of a continuous
    joint, which has none) allows any speed: inf."""
    step = acceleration * period
    with np.errstate(invalid="ignore"):  # inf - inf where distance = inf
        m = np.floor(0.5 * (np.sqrt(1.0 + 8.0 * distance / (step * period))
                            - 1.0))
        f = (distance / period - 0.5 * step * m * (m + 1.0)) / (m + 1.0)
    return np.where(np.isinf(distance), math.inf,
                    m * step + np.clip(f, 0.0, step))


def catch_up_arm(last, velocity, target, period, speed, acceleration):
    """The next position command of an arm whose command goes to `target`
    (where the arm is) and comes to rest on it: each joint moves towards
    it at most at its speed limit and at the `brake_speed` of the
    distance left (so that it can still stop on it), its rate changing
    by at most its acceleration limit a period: no step the servo would
    refuse, from wherever the command was going (one coming faster than
    it can stop on the target passes it, braking, and comes back).

    Args:
        last: (n,) the last command, rad.
        velocity: (n,) its rate, rad/s.
        target: (n,) where the command goes, rad (within the position
            limits: the caller's).
        period: h, s between commands.
        speed, acceleration: (n,) the joint speed (rad/s) and
            acceleration (rad/s^2) limits.

    Returns:
        (command (n,), its rate (n,)).
    """
    ahead = target - last
    closing = np.sign(ahead) * brake_speed(np.abs(ahead), acceleration,
                                           period)
    change = acceleration * period
    wanted = np.clip(np.clip(closing, velocity - change, velocity + change),
                     -speed, speed)
    command = last + wanted * period
    return command, wanted


def catching_up(last, velocity, target, within):
    """Which joints of a command that goes to `target` are on their way
    there: moving towards it, and farther than `within` from it (a
    command braking away from it, or at rest, is not).

    Args:
        last: (n,) the last command, rad.
        velocity: (n,) its rate, rad/s.
        target: (n,) where it goes, rad.
        within: rad >= 0.

    Returns:
        (n,) bool.
    """
    ahead = target - last
    return ((velocity != 0.0) & (np.sign(velocity) == np.sign(ahead))
            & (np.abs(ahead) > within))
