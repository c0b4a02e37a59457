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
differentiate), but `braking_rate`, the braking bound of the arm
controller's reference body too (drake_wbc.math.arm_control), of any
scalar type.
"""

import math
from typing import NamedTuple

import numpy as np

from drake_wbc.math.command_limits import ROUNDING
from drake_wbc.math.scalar_support import value_of

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


def braking_rate(distance, step, step_h):
    """The largest rate towards an edge `distance` away (>= 0) from which
    a joint can still stop at the edge, its rate changing by at most
    step = a h a period (step_h = step h); any scalar type.

    Braking from rate v = (m + f) a h (m an integer, 0 < f <= 1) at the
    full deceleration runs through v, v - a h, ..., f a h, then 0, and
    covers S(v) = a h^2 (m + 1)(f + m / 2). This inverts S: with
    D = distance / (a h^2), m(m + 1)/2 < D <= (m + 1)(m + 2)/2 and
    f = D / (m + 1) - m / 2. Since S(v - a h) = S(v) - v h, the bound one
    period later is exactly a h lower: braking along it never needs more
    than the acceleration limit, and S(v) >= v h keeps q + v h inside.
    (m, a whole number, has no derivative.)
    """
    D = distance / step_h
    r = 0.5 * (math.sqrt(1.0 + 8.0 * float(value_of(D))) - 1.0)
    m = max(float(math.ceil(r)) - 1.0, 0.0)
    f = min(max(D / (m + 1.0) - 0.5 * m, 0.0), 1.0)
    return (m + f) * step



def brake_speed(distance, acceleration, period):
    """`braking_rate` elementwise in floats: the largest speed at which
    each joint may move this period and still come to rest within
    `distance` (>= 0), slowing by at most `acceleration` * `period` each
    period of `period` s. From it the next period's brake_speed is at
    least v - a h, so a joint that keeps to it never has to brake harder
    than it may, and never passes the point. An infinite distance
    (towards the limit of a continuous joint, which has none) allows any
    speed: inf; a NaN distance gives NaN.

    Args:
        distance: (n,) rad (or m).
        acceleration: (n,) or a scalar, > 0, per s^2.
        period: h, s.

    Returns:
        (n,) float array.
    """
    distance, acceleration = np.broadcast_arrays(
        np.asarray(distance, dtype=float),
        np.asarray(acceleration, dtype=float))
    return np.array([
        d if math.isnan(d) else math.inf if math.isinf(d)
        else braking_rate(d, a * period, a * period * period)
        for d, a in zip(distance.ravel().tolist(),
                        acceleration.ravel().tolist(), strict=True)],
        dtype=float).reshape(distance.shape)


def catch_up_arm(last, velocity, target, period, speed, acceleration,
                 target_velocity=0.0, bounds=None):
    """The next position command of an arm whose command goes to `target`
    (where the arm is, or a target moving at `target_velocity`) and
    comes to rest on it: each joint moves towards it, relative to it, at
    the `brake_speed` of the distance left (so that it can still stop on
    it), at most at its speed limit (and within `bounds`), its rate
    changing by at most its acceleration limit a period: no step the
    servo would refuse, from wherever the command was going (one coming
    faster than it can stop on the target passes it, braking, and comes
    back). The robot side's limiter follows a moving target by it too
    (drake_wbc.hardware.safety.follow_arm_command).

    Args:
        last: (n,) the last command, rad.
        velocity: (n,) its rate, rad/s.
        target: (n,) where the command goes, rad (within the position
            limits: the caller's).
        period: h, s between commands.
        speed, acceleration: (n,) the joint speed (rad/s) and
            acceleration (rad/s^2) limits.
        target_velocity: (n,) or 0, the rate at which the target moves
            this period, rad/s.
        bounds: None, or (down, up): (n,) the largest rates towards the
            lower and the upper position limits, rad/s.

    Returns:
        (command (n,), its rate (n,)).
    """
    # How far the target was ahead before it moved this period, and the
    # speed relative to it that stops on it.
    ahead = target - last - target_velocity * period
    closing = np.sign(ahead) * brake_speed(np.abs(ahead), acceleration,
                                           period)
    change = acceleration * period
    wanted = np.clip(np.clip(target_velocity + closing, velocity - change,
                             velocity + change), -speed, speed)
    if bounds is not None:
        wanted = np.clip(wanted, -bounds[0], bounds[1])
    return last + wanted * period, wanted


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
