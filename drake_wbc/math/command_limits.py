"""Command limits that keep the direction.

The base command is scaled as a whole to the robot's velocity limits, and
its change from one tick to the next as a whole to the acceleration
limits, rather than clipped axis by axis, so that a saturated command
stays parallel to the one the controller meant (the arm's joint rates are
scaled the same way by drake_wbc.math.arm_control.joint_velocity_command).
The limits themselves are drake_wbc.math.safety.SafetyParameters'.

One body each, for any scalar type (float, and AutoDiffXd for the stages'
linearisation): a command has three entries, so the math runs entry by
entry in Python scalars, which for floats is about ten times faster than
numpy at this size. `limit_base_velocity`, which the base command
limiter runs every tick, has besides a float kernel
(drake_wbc.math.kernels), `limit_base_velocity_float`: the same
operations in the same order compiled to machine code
(drake_wbc.math.compiled), so the same values, bit for bit.
"""

from typing import NamedTuple

import numpy as np

from drake_wbc.math.compiled import compiled, float_array
from drake_wbc.math.kernels import fast_kernel

ROUNDING = 1e-9
"""Relative: a command within a limit up to rounding is within it (the
robot's own checks, drake_wbc.hardware.safety and
drake_wbc.math.arm_servo; a command within passes unchanged, bit for
bit)."""


def uniform_scale(vector, limits):
    """The largest factor s in [0, 1] with |s vector_i| <= limits_i for
    every i: scaling by it keeps the vector's direction.

    Args:
        vector: (n,) finite, any scalar type.
        limits: (n,) > 0.

    Returns:
        s (1.0 when the vector is within its limits).
    """
    scale = 1.0
    for value, limit in zip(_entries(vector), _entries(limits), strict=True):
        magnitude = abs(value)
        if magnitude > limit and limit < scale * magnitude:
            scale = limit / magnitude
    return scale


def _entries(values):
    """The entries of a vector as a list (of Python scalars for a float
    array)."""
    return values.tolist() if type(values) is np.ndarray else values


class LimitedCommand(NamedTuple):
    """The result of `limit_base_velocity`.

    Attributes:
        command: (3,) the command sent.
        velocity_scale: the factor in [0, 1] applied to the desired
            command, by the velocity limits and the given `scale` (1 when
            neither acted).
        acceleration_scale: the factor in [0, 1] applied to the change from
            the previous command (1 when within the acceleration limits).
    """

    command: np.ndarray
    velocity_scale: float
    acceleration_scale: float

    @property
    def limited(self):
        """True when a limit changed the desired command."""
        return self.velocity_scale < 1.0 or self.acceleration_scale < 1.0


def limit_base_velocity(desired, previous, velocity_limits,
                        acceleration_limits, time_step, scale=1.0):
    """The base command within the velocity and acceleration limits.

        v   = s_v s desired,            s_v = uniform_scale(s desired, v_max),
        out = previous + s_a (v - previous),
                                        s_a = uniform_scale(v - previous,
                                                            a_max h).

    The velocity limit scales the whole command, so it stays parallel to
    the desired one; the acceleration limit scales the whole change, so
    the command moves along the straight line from the previous command
    towards v and reaches it as fast as the limits allow. With `previous`
    within the velocity limits, `out` is too (the box of limits is convex).
    A desired command within both limits is returned unchanged (the same
    values, bit for bit). Any scalar type.

    Args:
        desired: (3,) [vx, vy, wz] in T_b, finite.
        previous: (3,) the command of the previous tick.
        velocity_limits, acceleration_limits: (3,) > 0.
        time_step: h > 0, s.
        scale: a further factor s in [0, 1] on the desired command (e.g.
            drake_wbc.math.separation.separation_scale); 1 by default.

    Returns:
        LimitedCommand.
    """
    desired = _entries(desired)
    if scale < 1.0:
        desired = [scale * v for v in desired]
    previous = _entries(previous)
    velocity_scale = uniform_scale(desired, velocity_limits)
    target = (desired if velocity_scale == 1.0
              else [velocity_scale * v for v in desired])
    change = [t - p for t, p in zip(target, previous, strict=True)]
    acceleration_scale = uniform_scale(
        change, [a * time_step for a in _entries(acceleration_limits)])
    if acceleration_scale < 1.0:
        command = [p + acceleration_scale * c
                   for p, c in zip(previous, change, strict=True)]
    else:
        command = target
    command = np.array(command)
    if command.dtype.kind in "biu":  # whole numbers given
        command = command.astype(float)
    return LimitedCommand(command, scale * velocity_scale,
                          acceleration_scale)


def _limit_inputs(rng):
    """Random arguments of limit_base_velocity: desired commands within
    and beyond the limits, previous commands near and far from them
    (steps within and beyond the acceleration limits), zero commands,
    separation scales of 1, 0 and between, whole numbers."""
    limits = rng.uniform(0.1, 2.0, 3)
    accelerations = rng.uniform(0.1, 3.0, 3)
    desired = rng.normal(size=3) * rng.choice([0.0, 0.01, 0.5, 5.0])
    previous = rng.choice([desired, np.zeros(3),
                           rng.uniform(-1.0, 1.0, 3) * limits])
    if rng.random() < 0.2:
        previous = desired + rng.normal(size=3) * 1e-4
    scale = float(rng.choice([1.0, 0.0, rng.uniform(0.0, 1.0)]))
    time_step = float(rng.choice([0.01, 0.001, rng.uniform(1e-3, 0.1)]))
    if rng.random() < 0.05:
        desired = rng.integers(-2, 3, 3)
    return (desired, previous, tuple(limits.tolist()),
            tuple(accelerations.tolist()), time_step, scale)


@fast_kernel(limit_base_velocity, sample=_limit_inputs)
def limit_base_velocity_float(desired, previous, velocity_limits,
                              acceleration_limits, time_step, scale=1.0):
    """`limit_base_velocity` of float commands, compiled
    (`_limit_loop`): the base command limiter's tick."""
    command, velocity_scale, acceleration_scale = _limit_loop(
        float_array(desired), float_array(previous),
        float_array(velocity_limits), float_array(acceleration_limits),
        float(time_step), float(scale))
    return LimitedCommand(command, velocity_scale, acceleration_scale)


@compiled
def _uniform_scale_loop(vector, limits):
    """`uniform_scale` of float arrays, the same steps."""
    scale = 1.0
    for i in range(vector.shape[0]):
        magnitude = abs(vector[i])
        if magnitude > limits[i] and limits[i] < scale * magnitude:
            scale = limits[i] / magnitude
    return scale


@compiled
def _limit_loop(desired, previous, velocity_limits, acceleration_limits,
                time_step, scale):
    """`limit_base_velocity`'s steps on float arrays: (command, scale
    times the velocity scale, acceleration scale)."""
    if scale < 1.0:
        desired = scale * desired
    velocity_scale = _uniform_scale_loop(desired, velocity_limits)
    target = (desired if velocity_scale == 1.0
              else velocity_scale * desired)
    change = target - previous
    acceleration_scale = _uniform_scale_loop(
        change, acceleration_limits * time_step)
    if acceleration_scale < 1.0:
        command = previous + acceleration_scale * change
    else:
        command = target.copy()
    return command, scale * velocity_scale, acceleration_scale
